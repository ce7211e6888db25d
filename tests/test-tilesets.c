/* Tests of the tilesets module: the procedural city, forest and hybrid and
 * the built-in registry. Plain C: main returns 0 when every check holds. */
#include "tileworld/tilesets.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tests/tileset-checks.h"
#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static bool box_contains(const struct tw_box *outer, const struct tw_box *inner)
{
    for (int k = 0; k < 3; k++)
        if (inner->min[k] < outer->min[k] || inner->max[k] > outer->max[k])
            return false;
    return true;
}

/* Bit-for-bit equality of everything a generator writes. */
static bool tilesets_identical(const struct tw_tileset *a, const struct tw_tileset *b)
{
    if (a->prototype_count != b->prototype_count || a->mesh_count != b->mesh_count ||
        a->material_count != b->material_count || a->part_count != b->part_count ||
        memcmp(a->footprint, b->footprint, sizeof(a->footprint)) != 0 ||
        memcmp(&a->common_box, &b->common_box, sizeof(a->common_box)) != 0)
        return false;
    for (uint32_t k = 0; k < a->material_count; k++)
        if (memcmp(&a->materials[k], &b->materials[k], sizeof(a->materials[k])) != 0)
            return false;
    for (uint32_t k = 0; k < a->mesh_count; k++) {
        if (!mesh_data_identical(&a->meshes[k], &b->meshes[k]))
            return false;
    }
    for (uint32_t p = 0; p < a->prototype_count; p++) {
        const struct tw_prototype *x = &a->prototypes[p], *y = &b->prototypes[p];
        if (!prototype_head_identical(x, y) || x->weight != y->weight)
            return false;
        for (uint32_t k = 0; k < x->instance_count; k++) {
            const struct tw_instance *i = &x->instances[k], *j = &y->instances[k];
            if (i->mesh != j->mesh || i->material != j->material ||
                memcmp(i->transform, j->transform, sizeof(i->transform)) != 0 ||
                memcmp(&i->box, &j->box, sizeof(i->box)) != 0)
                return false;
        }
    }
    return true;
}

/* Counts the triangles of ts, placed by their instances, whose horizontal
 * extent reaches within band of a border and whose bounds lo, hi bad()
 * refuses (given limit); *where names the first one's prototype.
 * Conservative: the triangle's bounding rectangle is tested. */
static uint64_t band_violations(const struct tw_tileset *ts, float band,
                                bool (*bad)(const float lo[3], const float hi[3], float limit),
                                float limit, const char **where)
{
    const float w = ts->footprint[0], d = ts->footprint[1];
    uint64_t count = 0;
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            const struct tw_instance *in = &proto->instances[k];
            const struct tw_mesh *m = &ts->meshes[in->mesh];
            for (uint32_t t = 0; t < m->triangle_count; t++) {
                float lo[3], hi[3];
                placed_triangle_bounds(in, m, t, lo, hi);
                const bool in_band = lo[0] < band || hi[0] > w - band || lo[2] < band ||
                                     hi[2] > d - band;
                if (in_band && bad(lo, hi, limit)) {
                    if (!count)
                        *where = proto->name;
                    count++;
                }
            }
        }
    }
    return count;
}

static bool above(const float lo[3], const float hi[3], float kerb_max)
{
    (void)lo;
    return hi[1] > kerb_max;
}

/* Nothing above the kerb within street_width / 2 - 1 m of a border: a
 * triangle whose horizontal extent reaches into that band must lie below
 * the kerb's 0.2 m. */
static uint64_t street_band_violations(const struct tw_tileset *ts, float band,
                                       const char **where)
{
    return band_violations(ts, band, above, 0.2f, where);
}

/* A mesh that tw_tileset_finish() merged from instances. */
static bool merged_mesh(const struct tw_tileset *ts, uint32_t mesh)
{
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        for (uint32_t k = 0; k < ts->prototypes[p].instance_count; k++)
            if (ts->prototypes[p].instances[k].merged && ts->prototypes[p].instances[k].mesh == mesh)
                return true;
    return false;
}

/* Every triangle is flat shaded (its three normals equal the unit face
 * normal) and wound counter-clockwise seen from the side its normal points
 * to: the renderer culls back faces. A merged mesh holds its instances'
 * normals transformed as the shader transforms them (by the linear part,
 * which a non-uniform scale tilts off the face normal): its normals only
 * have to point to the front side. */
static uint64_t shading_violations(const struct tw_tileset *ts)
{
    uint64_t bad = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        const struct tw_mesh *m = &ts->meshes[k];
        const float min_dot = merged_mesh(ts, k) ? 0.0f : 0.999f;
        for (uint32_t t = 0; t < m->triangle_count; t++) {
            const uint32_t *i = m->indices + 3 * t;
            const float *a = m->positions + 3 * i[0], *b = m->positions + 3 * i[1],
                        *c = m->positions + 3 * i[2];
            const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            const float e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                          e1[0] * e2[1] - e1[1] * e2[0]};
            const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            if (!(len > 0.0f)) {
                bad++;
                continue;
            }
            for (int v = 0; v < 3; v++) {
                /* Normals of merged meshes are transformed, not renormalised
                 * (the shader normalises them, as it does an instance's). */
                const float *vn = m->normals + 3 * i[v];
                const float vlen = sqrtf(vn[0] * vn[0] + vn[1] * vn[1] + vn[2] * vn[2]);
                const float dot = (vn[0] * n[0] + vn[1] * n[1] + vn[2] * n[2]) / (len * vlen);
                if (min_dot > 0.0f ? dot < min_dot : !(dot > 0.0f)) {
                    bad++;
                    break;
                }
            }
        }
    }
    return bad;
}


static bool in_headroom(const float lo[3], const float hi[3], float headroom)
{
    return hi[1] > 0.05f && lo[1] < headroom;
}

/* The forest's walking band: a triangle whose horizontal extent reaches
 * within band of a border must lie on the ground (max y <= ground + 0.05)
 * or overhead (min y >= ground + headroom). */
static uint64_t headroom_violations(const struct tw_tileset *ts, float band, float headroom,
                                    const char **where)
{
    return band_violations(ts, band, in_headroom, headroom, where);
}

/* Checks that hold for every generated tileset: finished, boxes inside the
 * footprint and the common box, clusters within the limit and adding up,
 * flat shading, every material used, triangle counts in [10k, 100k]. */
static void check_common(const struct tw_tileset *ts, const char *what)
{
    CHECK_MSG(ts->finished, "%s: not finished", what);
    const float w = ts->footprint[0], d = ts->footprint[1], eps = 1e-4f;
    bool *material_used = calloc(ts->material_count, sizeof(bool));
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        CHECK_MSG(proto->triangle_count >= 10000 && proto->triangle_count <= 100000,
                  "%s: %llu triangles", proto->name, (unsigned long long)proto->triangle_count);
        CHECK_MSG(proto->weight > 0.0f, "%s: weight %g", proto->name, (double)proto->weight);
        CHECK_MSG(proto->box.min[0] >= -eps && proto->box.max[0] <= w + eps &&
                  proto->box.min[2] >= -eps && proto->box.max[2] <= d + eps,
                  "%s: box x [%g, %g] z [%g, %g] leaves the footprint", proto->name,
                  (double)proto->box.min[0], (double)proto->box.max[0],
                  (double)proto->box.min[2], (double)proto->box.max[2]);
        CHECK_MSG(proto->box.max[1] > 0.0f && proto->box.min[1] >= -eps, "%s: box y [%g, %g]",
                  proto->name, (double)proto->box.min[1], (double)proto->box.max[1]);
        CHECK_MSG(box_contains(&ts->common_box, &proto->box), "%s: not inside the common box",
                  proto->name);
        uint64_t cluster_triangles = 0;
        for (uint32_t k = 0; k < proto->cluster_count; k++) {
            CHECK_MSG(proto->clusters[k].triangle_count <= ts->max_cluster_triangles,
                      "%s: cluster of %u triangles", proto->name, proto->clusters[k].triangle_count);
            cluster_triangles += proto->clusters[k].triangle_count;
        }
        CHECK_MSG(cluster_triangles == proto->triangle_count, "%s: clusters hold %llu triangles",
                  proto->name, (unsigned long long)cluster_triangles);
        for (uint32_t k = 0; k < proto->instance_count; k++)
            if (material_used && proto->instances[k].material < ts->material_count)
                material_used[proto->instances[k].material] = true;
    }
    for (uint32_t k = 0; material_used && k < ts->material_count; k++)
        CHECK_MSG(material_used[k], "%s: material %u is never used", what, k);
    free(material_used);
    const uint64_t shading_bad = shading_violations(ts);
    CHECK_MSG(shading_bad == 0, "%s: %llu triangles not flat shaded or wound clockwise", what,
              (unsigned long long)shading_bad);
}

/* The ground and trail instances span the tile; everything else is an
 * object standing in it. */
static bool spans_tile(const struct tw_tileset *ts, const struct tw_instance *in)
{
    return in->box.max[0] - in->box.min[0] > 0.5f * ts->footprint[0] &&
           in->box.max[2] - in->box.min[2] > 0.5f * ts->footprint[1];
}

/* Objects that stand on the ground and reach higher than height: trees,
 * in a forest. A tree's canopy and trunk are two instances at the same
 * place, counted once. */
static uint32_t tall_objects(const struct tw_prototype *proto, float height)
{
    uint32_t n = 0;
    for (uint32_t k = 0; k < proto->instance_count; k++) {
        const struct tw_instance *in = &proto->instances[k];
        /* A merged mesh is many objects; its instances are counted. */
        if (in->merged || !(in->box.max[1] > height && in->box.min[1] < 0.5f))
            continue;
        bool seen = false;
        for (uint32_t j = 0; j < k && !seen; j++) {
            const struct tw_instance *o = &proto->instances[j];
            seen = o->box.max[1] > height && o->box.min[1] < 0.5f &&
                   o->transform[3] == in->transform[3] && o->transform[11] == in->transform[11];
        }
        n += !seen;
    }
    return n;
}

/* Distance along o + t dir to the nearest triangle of one instance, or
 * INFINITY (Moller-Trumbore on transformed vertices). */
static float ray_instance(const struct tw_tileset *ts, const struct tw_instance *in,
                          const float o[3], const float dir[3], float t_max)
{
    /* Slab test against the instance box first. */
    float t0 = 0.0f, t1 = t_max;
    for (int a = 0; a < 3; a++) {
        if (fabsf(dir[a]) < 1e-12f) {
            if (o[a] < in->box.min[a] || o[a] > in->box.max[a])
                return INFINITY;
            continue;
        }
        float ta = (in->box.min[a] - o[a]) / dir[a], tb = (in->box.max[a] - o[a]) / dir[a];
        if (ta > tb) {
            const float x = ta;
            ta = tb;
            tb = x;
        }
        t0 = fmaxf(t0, ta);
        t1 = fminf(t1, tb);
        if (t0 > t1)
            return INFINITY;
    }
    const struct tw_mesh *m = &ts->meshes[in->mesh];
    float best = INFINITY;
    for (uint32_t t = 0; t < m->triangle_count; t++) {
        float v[3][3];
        for (int k = 0; k < 3; k++)
            transform_point(in->transform, m->positions + 3 * m->indices[3 * t + k], v[k]);
        const float e1[3] = {v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]};
        const float e2[3] = {v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]};
        const float p[3] = {dir[1] * e2[2] - dir[2] * e2[1], dir[2] * e2[0] - dir[0] * e2[2],
                            dir[0] * e2[1] - dir[1] * e2[0]};
        const float det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
        if (fabsf(det) < 1e-12f)
            continue;
        const float inv = 1.0f / det;
        const float s[3] = {o[0] - v[0][0], o[1] - v[0][1], o[2] - v[0][2]};
        const float u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
        if (u < 0.0f || u > 1.0f)
            continue;
        const float q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2],
                            s[0] * e1[1] - s[1] * e1[0]};
        const float w = (dir[0] * q[0] + dir[1] * q[1] + dir[2] * q[2]) * inv;
        if (w < 0.0f || u + w > 1.0f)
            continue;
        const float t_hit = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
        if (t_hit > 1e-4f && t_hit < best)
            best = t_hit;
    }
    return best;
}

/* Casts a ray from a point in cell (0, 0) through the world of ts (hash
 * selection with seed) and returns the distance to the first object (not
 * the ground) it meets within t_max, or INFINITY. Cells are visited in
 * the order the ray enters them, so the first cell with a hit holds the
 * nearest one. */
static float ray_world(const struct tw_tileset *ts, uint64_t seed, const float o[3],
                       const float dir[3], float t_max)
{
    const struct tw_selection sel = {seed, 0, NULL, NULL};
    const float w = ts->footprint[0], d = ts->footprint[1];
    struct tw_cell last = {INT64_MIN, INT64_MIN};
    for (float t = 0.0f; t <= t_max; t += 0.25f) {
        const struct tw_cell cell = {(int64_t)floorf((o[0] + t * dir[0]) / w),
                                     (int64_t)floorf((o[2] + t * dir[2]) / d)};
        if (cell.i == last.i && cell.j == last.j)
            continue;
        last = cell;
        const struct tw_prototype *proto = &ts->prototypes[tw_tiles_select(ts, &sel, cell)];
        const float local[3] = {o[0] - (float)cell.i * w, o[1], o[2] - (float)cell.j * d};
        float best = INFINITY;
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            if (spans_tile(ts, &proto->instances[k]))
                continue;
            best = fminf(best, ray_instance(ts, &proto->instances[k], local, dir, t_max));
        }
        if (best <= t_max)
            return best;
    }
    return INFINITY;
}

/* The three generators behind one signature (set: the generator's own
 * settings struct, or NULL), for the checks they share. */
typedef int generator_fn(uint64_t seed, const void *set, const struct tw_log *log,
                         struct tw_tileset **out);

static int generate_city(uint64_t seed, const void *set, const struct tw_log *log,
                         struct tw_tileset **out)
{
    return tw_tilesets_city(seed, set, log, out);
}

static int generate_forest(uint64_t seed, const void *set, const struct tw_log *log,
                           struct tw_tileset **out)
{
    return tw_tilesets_forest(seed, set, log, out);
}

static int generate_hybrid(uint64_t seed, const void *set, const struct tw_log *log,
                           struct tw_tileset **out)
{
    return tw_tilesets_hybrid(seed, set, log, out);
}

/* What every generator promises of its seeds: makes ts[0] from seed 1 with
 * the defaults (settings NULL), timed; ts[1] from seed 1 again with the
 * default settings spelled out (defaults); ts[2] from seed 2 with
 * seed2_settings. None logs an error, ts[1] is ts[0] bit for bit, ts[2]
 * differs, and ts[0] has the default 80 m footprint and prototypes
 * prototypes. False, with nothing made, if seed 1 fails. */
static bool generate_seeds(const char *name, generator_fn *generate, const void *defaults,
                           const void *seed2_settings, uint32_t prototypes,
                           struct tw_tileset *ts[3])
{
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};
    ts[0] = ts[1] = ts[2] = NULL;
    const double t0 = now_seconds();
    int err = generate(1, NULL, &log, &ts[0]);
    const double t1 = now_seconds();
    CHECK_MSG(err == 0 && ts[0], "%s(seed 1) failed: %s", name, tw_error_to_str(err));
    if (err || !ts[0])
        return false;
    const struct tw_tileset *a = ts[0];
    printf("%s seed 1: generated in %.3f s, %u meshes, %u parts, %.1f MB geometry\n", name,
           t1 - t0, a->mesh_count, a->part_count, (double)tw_tileset_geometry_bytes(a) / 1e6);

    err = generate(1, defaults, &log, &ts[1]);
    CHECK_MSG(err == 0 && ts[1], "%s(seed 1) again failed: %s", name, tw_error_to_str(err));
    err = generate(2, seed2_settings, &log, &ts[2]);
    CHECK_MSG(err == 0 && ts[2], "%s(seed 2) failed: %s", name, tw_error_to_str(err));
    CHECK_MSG(captured.errors == 0, "%s: unexpected error message: %s", name, captured.last);
    if (ts[1])
        CHECK_MSG(tilesets_identical(a, ts[1]), "%s: the same seed gave different tilesets", name);
    if (ts[2])
        CHECK_MSG(!tilesets_identical(a, ts[2]), "%s: seeds 1 and 2 gave identical tilesets", name);

    CHECK_MSG(a->footprint[0] == 80.0f && a->footprint[1] == 80.0f, "%s footprint %g x %g", name,
              (double)a->footprint[0], (double)a->footprint[1]);
    CHECK_MSG(a->prototype_count == prototypes, "%s prototype_count = %u", name,
              a->prototype_count);
    return true;
}

static void destroy_seeds(struct tw_tileset *ts[3])
{
    for (int k = 0; k < 3; k++)
        tw_tileset_destroy(ts[k]);
}

/* generate() refuses set: TW_ERR_INVALID and no tileset. What the message
 * says is the caller's to check. */
static void check_refused(const char *what, generator_fn *generate, const void *set,
                          const struct tw_log *log)
{
    struct tw_tileset *ts = NULL;
    const int err = generate(1, set, log, &ts);
    CHECK_MSG(err == TW_ERR_INVALID && !ts, "%s: %s", what, tw_error_to_str(err));
    tw_tileset_destroy(ts);
}

/* What generate() makes from custom settings set (NULL if it fails, a
 * failed check). */
static struct tw_tileset *make_custom(const char *name, generator_fn *generate, uint64_t seed,
                                      const void *set)
{
    struct tw_tileset *ts = NULL;
    const int err = generate(seed, set, NULL, &ts);
    CHECK_MSG(err == 0 && ts, "%s, custom settings: %s", name, tw_error_to_str(err));
    return ts;
}

/* A tileset made from custom settings has the prototype count, the
 * footprint and the cluster size they ask for, and its common box stays
 * within the footprint along x. */
static void check_custom(const char *name, const struct tw_tileset *ts, uint32_t prototypes,
                         float footprint, uint32_t max_cluster_triangles)
{
    CHECK_MSG(ts->prototype_count == prototypes, "%s: prototype_count = %u", name,
              ts->prototype_count);
    CHECK_MSG(ts->footprint[0] == footprint, "%s: footprint %g", name, (double)ts->footprint[0]);
    CHECK_MSG(ts->max_cluster_triangles == max_cluster_triangles, "%s: max_cluster_triangles = %u",
              name, ts->max_cluster_triangles);
    CHECK_MSG(ts->common_box.min[0] >= -1e-4f && ts->common_box.max[0] <= footprint + 1e-4f,
              "%s: common box x [%g, %g]", name, (double)ts->common_box.min[0],
              (double)ts->common_box.max[0]);
}

static void test_city(void)
{
    struct tw_city_settings set = {0};
    tw_tilesets_city_default_settings(&set);
    CHECK_MSG(set.prototypes == 12 && set.footprint == 80.0f && set.street_width == 14.0f &&
              set.max_height == 90.0f && set.max_cluster_triangles == 2048,
              "unexpected defaults");

    struct tw_tileset *seeds[3];
    if (!generate_seeds("city", generate_city, &set, &set, 12, seeds))
        return;
    struct tw_tileset *a = seeds[0];
    CHECK_MSG(a->material_count >= 5, "only %u materials", a->material_count);
    CHECK_MSG(a->max_cluster_triangles == 2048, "max_cluster_triangles = %u",
              a->max_cluster_triangles);
    check_common(a, "city");

    float tallest = 0.0f;
    uint64_t total = 0;
    printf("  %-18s %9s %9s %9s %8s\n", "prototype", "triangles", "instances", "clusters",
           "height");
    for (uint32_t p = 0; p < a->prototype_count; p++) {
        const struct tw_prototype *proto = &a->prototypes[p];
        printf("  %-18s %9llu %9u %9u %8.1f\n", proto->name,
               (unsigned long long)proto->triangle_count, proto->instance_count,
               proto->cluster_count, (double)proto->box.max[1]);
        total += proto->triangle_count;
        CHECK_MSG(proto->instance_count >= 8 && proto->instance_count <= 100, "%s: %u instances",
                  proto->name, proto->instance_count);
        CHECK_MSG(proto->box.max[1] <= set.max_height + 1e-3f, "%s: %g m is above max_height",
                  proto->name, (double)proto->box.max[1]);
        if (proto->box.max[1] > tallest)
            tallest = proto->box.max[1];
    }
    printf("  average %.0f triangles per prototype, tallest %.1f m\n",
           (double)total / a->prototype_count, (double)tallest);
    CHECK_MSG(tallest > 40.0f, "no prototype taller than 40 m (tallest %g m)", (double)tallest);

    const char *where = "";
    const uint64_t band_bad = street_band_violations(a, 0.5f * set.street_width - 1.0f, &where);
    CHECK_MSG(band_bad == 0, "%llu triangles above the kerb in the street band (first in %s)",
              (unsigned long long)band_bad, where);

    /* The band check itself must be able to fail: a band that reaches the
     * lot line contains building walls. */
    CHECK_MSG(street_band_violations(a, 0.5f * set.street_width + 0.5f, &where) > 0,
              "band check does not see buildings at the lot line");

    destroy_seeds(seeds);
}

static void test_city_settings(void)
{
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};

    struct tw_city_settings set = {0};
    set.prototypes = 3;
    check_refused("city, 3 prototypes", generate_city, &set, &log);
    CHECK_MSG(captured.errors > 0 && strstr(captured.last, "prototypes"),
              "no message about prototypes: \"%s\"", captured.last);

    set = (struct tw_city_settings){0};
    set.street_width = 70.0f;
    check_refused("city, street_width 70", generate_city, &set, &log);

    int err = tw_tilesets_city(1, NULL, &log, NULL);
    CHECK_MSG(err == TW_ERR_INVALID, "NULL out: %s", tw_error_to_str(err));

    /* Other settings are honoured: more prototypes, a wider tile, a lower
     * skyline, a different cluster size. */
    const struct tw_city_settings custom = {.prototypes = 9, .footprint = 100.0f,
                                            .street_width = 16.0f, .max_height = 50.0f,
                                            .max_cluster_triangles = 700};
    struct tw_tileset *ts = make_custom("city", generate_city, 7, &custom);
    if (ts) {
        check_custom("city", ts, 9, 100.0f, 700);
        CHECK_MSG(ts->common_box.max[1] <= 50.0f + 1e-3f, "common box top %g m",
                  (double)ts->common_box.max[1]);
        const char *where = "";
        const uint64_t bad = street_band_violations(ts, 7.0f, &where);
        CHECK_MSG(bad == 0, "custom settings: %llu triangles in the street band (first in %s)",
                  (unsigned long long)bad, where);
        for (uint32_t p = 0; p < ts->prototype_count; p++)
            CHECK_MSG(ts->prototypes[p].triangle_count >= 10000 &&
                      ts->prototypes[p].triangle_count <= 100000, "%s: %llu triangles",
                      ts->prototypes[p].name,
                      (unsigned long long)ts->prototypes[p].triangle_count);
        tw_tileset_destroy(ts);
    }
}


static void print_prototypes(const struct tw_tileset *ts)
{
    printf("  %-26s %9s %9s %9s %8s %6s\n", "prototype", "triangles", "instances", "clusters",
           "height", "tall");
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        printf("  %-26s %9llu %9u %9u %8.1f %6u\n", proto->name,
               (unsigned long long)proto->triangle_count, proto->instance_count,
               proto->cluster_count, (double)proto->box.max[1], tall_objects(proto, 3.0f));
    }
}

static void test_forest(void)
{
    struct tw_forest_settings set = {0};
    tw_tilesets_forest_default_settings(&set);
    CHECK_MSG(set.prototypes == 10 && set.footprint == 80.0f && set.density == 1.0f &&
              set.path_clearance == 1.0f && set.max_cluster_triangles == 2048,
              "unexpected forest defaults");

    struct tw_tileset *seeds[3];
    if (!generate_seeds("forest", generate_forest, &set, NULL, 10, seeds))
        return;
    struct tw_tileset *a = seeds[0];
    print_prototypes(a);
    check_common(a, "forest");

    /* The stands differ, and each kind the design asks for is there. */
    static const char *const kinds[] = {"spruce", "mixed", "beech", "birch", "thin", "clearing",
                                        "rocky"};
    for (size_t k = 0; k < sizeof(kinds) / sizeof(kinds[0]); k++) {
        bool found = false;
        for (uint32_t p = 0; p < a->prototype_count; p++)
            found |= strstr(a->prototypes[p].name, kinds[k]) != NULL;
        CHECK_MSG(found, "forest: no %s stand", kinds[k]);
    }

    /* Many weak occluders: hundreds of instances, every standing object
     * small next to the tile, trees by the hundred in the dense stands;
     * shared meshes, far fewer than instances. */
    const float w = a->footprint[0], d = a->footprint[1];
    const double tile_volume = (double)w * d * (a->common_box.max[1] - a->common_box.min[1]);
    uint64_t instances = 0;
    for (uint32_t p = 0; p < a->prototype_count; p++) {
        const struct tw_prototype *proto = &a->prototypes[p];
        instances += proto->instance_count;
        CHECK_MSG(proto->instance_count >= 100 && proto->instance_count <= 450,
                  "%s: %u instances", proto->name, proto->instance_count);
        const uint32_t trees = tall_objects(proto, 3.0f);
        const bool dense = strstr(proto->name, "spruce") || strstr(proto->name, "mixed");
        CHECK_MSG(trees >= (dense ? 150u : 100u), "%s: only %u objects taller than 3 m",
                  proto->name, trees);
        double volume = 0.0, largest = 0.0;
        uint32_t objects = 0;
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            const struct tw_instance *in = &proto->instances[k];
            if (in->merged || spans_tile(a, in))
                continue;
            const double area = (double)(in->box.max[0] - in->box.min[0]) *
                                (in->box.max[2] - in->box.min[2]);
            const double v = area * (in->box.max[1] - in->box.min[1]);
            volume += v;
            objects++;
            if (in->box.max[1] > 3.0f && area > largest)
                largest = area;
        }
        const double mean = objects ? volume / objects : 0.0;
        CHECK_MSG(mean < 0.002 * tile_volume, "%s: mean instance box %.0f m^3 is %.2f %% of the tile",
                  proto->name, mean, 100.0 * mean / tile_volume);
        CHECK_MSG(largest < 0.025 * (double)w * d, "%s: a tree covers %.0f m^2 of the tile",
                  proto->name, largest);
    }
    CHECK_MSG(a->mesh_count * 8 < instances, "forest: %u meshes for %llu instances: not shared",
              a->mesh_count, (unsigned long long)instances);

    /* The walking band: no trunk, bush or low branch within path_clearance
     * of a border; and the check can see trees, with a wider band. */
    const char *where = "";
    uint64_t bad = headroom_violations(a, set.path_clearance, 2.5f, &where);
    CHECK_MSG(bad == 0, "forest: %llu triangles in the walking band (first in %s)",
              (unsigned long long)bad, where);
    CHECK_MSG(headroom_violations(a, 6.0f, 2.5f, &where) > 0,
              "forest: band check does not see trees 6 m from the border");

    /* Together they close up: horizontal rays at eye height and above,
     * through a world of this tileset, all but a few meet something within
     * 3 tiles, while many pass the first 10 m: no tree is a wall. */
    uint32_t rays = 0, near = 0, through = 0;
    for (uint32_t k = 0; k < 300; k++) {
        const uint64_t h = tw_tiles_hash(99, k, 7);
        const float height = 0.6f + 14.0f * (float)(h & 0xffff) / 65536.0f;
        const float angle = 6.2831853f * (float)((h >> 16) & 0xffff) / 65536.0f;
        const float z = 10.0f + 60.0f * (float)((h >> 32) & 0xffff) / 65536.0f;
        const float o[3] = {40.0f, height, z};
        const float dir[3] = {cosf(angle), 0.0f, sinf(angle)};
        const float hit = ray_world(a, 1, o, dir, 3.0f * w);
        rays++;
        near += hit < 10.0f;
        through += !(hit <= 3.0f * w);
    }
    printf("  horizontal rays at 0.6-14.6 m: %.1f %% stopped within 10 m, %.1f %% pass 3 tiles\n",
           100.0 * near / rays, 100.0 * through / rays);
    CHECK_MSG(through * 50 <= rays, "forest: %u of %u rays pass 3 tiles", through, rays);
    CHECK_MSG(near * 4 <= rays * 3, "forest: %u of %u rays stopped within 10 m: a wall, not trees",
              near, rays);

    destroy_seeds(seeds);
}

static void test_forest_settings(void)
{
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};

    struct tw_forest_settings set = {0};
    set.prototypes = 3;
    check_refused("forest, 3 prototypes", generate_forest, &set, &log);
    CHECK_MSG(captured.errors > 0 && strstr(captured.last, "prototypes") &&
              strstr(captured.last, "forest"), "no message about prototypes: \"%s\"", captured.last);
    set = (struct tw_forest_settings){0};
    set.density = 5.0f;
    check_refused("forest, density 5", generate_forest, &set, &log);
    CHECK_MSG(strstr(captured.last, "density"), "no message about density: \"%s\"", captured.last);
    set = (struct tw_forest_settings){0};
    set.footprint = NAN;
    check_refused("forest, footprint NaN", generate_forest, &set, &log);
    int err = tw_tilesets_forest(1, NULL, &log, NULL);
    CHECK_MSG(err == TW_ERR_INVALID, "forest, NULL out: %s", tw_error_to_str(err));

    /* Other settings are honoured: a wider tile, a wider trail, a thinner
     * forest, more prototypes, smaller clusters. */
    const struct tw_forest_settings custom = {.prototypes = 12, .footprint = 100.0f,
                                              .path_clearance = 2.5f, .density = 0.6f,
                                              .max_cluster_triangles = 500};
    struct tw_tileset *ts = make_custom("forest", generate_forest, 3, &custom);
    if (ts) {
        check_custom("forest", ts, 12, 100.0f, 500);
        CHECK_MSG(ts->common_box.min[2] >= -1e-4f && ts->common_box.max[2] <= 100.0f + 1e-4f,
                  "common box z [%g, %g]", (double)ts->common_box.min[2],
                  (double)ts->common_box.max[2]);
        const char *where = "";
        const uint64_t bad = headroom_violations(ts, 2.5f, 2.5f, &where);
        CHECK_MSG(bad == 0, "custom settings: %llu triangles in the walking band (first in %s)",
                  (unsigned long long)bad, where);
        tw_tileset_destroy(ts);
    }
}

static void test_hybrid(void)
{
    struct tw_hybrid_settings set = {0};
    tw_tilesets_hybrid_default_settings(&set);
    CHECK_MSG(set.prototypes == 12 && set.footprint == 80.0f && set.street_width == 14.0f &&
              set.max_height == 90.0f && set.green_share == 0.4f &&
              set.max_cluster_triangles == 2048, "unexpected hybrid defaults");

    struct tw_tileset *seeds[3];
    if (!generate_seeds("hybrid", generate_hybrid, &set, NULL, 12, seeds))
        return;
    struct tw_tileset *a = seeds[0];
    print_prototypes(a);
    check_common(a, "hybrid");

    uint32_t woods = 0, parks = 0, city = 0;
    float tallest = 0.0f;
    for (uint32_t p = 0; p < a->prototype_count; p++) {
        const struct tw_prototype *proto = &a->prototypes[p];
        tallest = fmaxf(tallest, proto->box.max[1]);
        CHECK_MSG(proto->box.max[1] <= set.max_height + 1e-3f, "%s: %g m is above max_height",
                  proto->name, (double)proto->box.max[1]);
        if (strstr(proto->name, "wood")) {
            woods++;
            CHECK_MSG(tall_objects(proto, 3.0f) >= 80, "%s: only %u trees", proto->name,
                      tall_objects(proto, 3.0f));
        } else if (strstr(proto->name, "park")) {
            parks++;
        } else {
            city++;
        }
    }
    CHECK_MSG(woods >= 2 && parks >= 1 && city >= 4, "hybrid: %u woods, %u parks, %u city blocks",
              woods, parks, city);
    CHECK_MSG(tallest > 40.0f, "hybrid: no prototype taller than 40 m (tallest %g m)",
              (double)tallest);

    /* Streets along every border, wooded blocks and parks included. */
    const char *where = "";
    const uint64_t band_bad = street_band_violations(a, 0.5f * set.street_width - 1.0f, &where);
    CHECK_MSG(band_bad == 0, "hybrid: %llu triangles above the kerb in the street band (first in %s)",
              (unsigned long long)band_bad, where);
    CHECK_MSG(street_band_violations(a, 0.5f * set.street_width + 0.5f, &where) > 0,
              "hybrid: band check does not see the blocks");

    destroy_seeds(seeds);

    /* Settings: the city's checks apply, and green_share's own. */
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};
    set = (struct tw_hybrid_settings){0};
    set.green_share = 1.5f;
    check_refused("hybrid, green_share 1.5", generate_hybrid, &set, &log);
    CHECK_MSG(captured.errors > 0 && strstr(captured.last, "green_share"),
              "no message about green_share: \"%s\"", captured.last);
    set = (struct tw_hybrid_settings){0};
    set.street_width = 70.0f;
    check_refused("hybrid, street_width 70", generate_hybrid, &set, &log);
    CHECK_MSG(strstr(captured.last, "hybrid") && strstr(captured.last, "footprint"),
              "no message naming the hybrid's footprint: \"%s\"", captured.last);

    const struct tw_hybrid_settings custom = {.prototypes = 9, .footprint = 100.0f,
                                              .street_width = 16.0f, .green_share = 0.7f};
    struct tw_tileset *ts = make_custom("hybrid", generate_hybrid, 4, &custom);
    if (ts) {
        CHECK_MSG(ts->prototype_count == 9, "prototype_count = %u", ts->prototype_count);
        const uint64_t bad = street_band_violations(ts, 7.0f, &where);
        CHECK_MSG(bad == 0, "hybrid, custom settings: %llu triangles in the street band (first in %s)",
                  (unsigned long long)bad, where);
        uint32_t green = 0;
        for (uint32_t p = 0; p < ts->prototype_count; p++)
            green += strstr(ts->prototypes[p].name, "wood") ||
                     strstr(ts->prototypes[p].name, "park");
        CHECK_MSG(green == 6, "hybrid, green_share 0.7 of 9: %u green prototypes", green);
        tw_tileset_destroy(ts);
    }
}

static void test_builtin(void)
{
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};

    static const char *const expected[] = {"city", "forest", "hybrid"};
    for (size_t k = 0; k < sizeof(expected) / sizeof(expected[0]); k++) {
        bool found = false;
        for (const char *const *n = tw_tilesets_builtin_names; *n; n++)
            found |= strcmp(*n, expected[k]) == 0;
        CHECK_MSG(found, "\"%s\" is not among the built-in names", expected[k]);
    }

    struct tw_tileset *ts = NULL, *direct = NULL;
    int err = tw_tilesets_builtin("city", 5, 0, &log, &ts);
    CHECK_MSG(err == 0 && ts, "builtin(city): %s", tw_error_to_str(err));
    err = tw_tilesets_city(5, NULL, NULL, &direct);
    CHECK_MSG(err == 0 && direct, "city(5): %s", tw_error_to_str(err));
    if (ts && direct) {
        CHECK_MSG(ts->max_cluster_triangles == 2048, "default cluster size %u",
                  ts->max_cluster_triangles);
        CHECK_MSG(tilesets_identical(ts, direct), "builtin(city) differs from city()");
    }
    tw_tileset_destroy(ts);
    tw_tileset_destroy(direct);

    ts = NULL;
    err = tw_tilesets_builtin("city", 5, 512, &log, &ts);
    CHECK_MSG(err == 0 && ts && ts->max_cluster_triangles == 512, "builtin(city, 512): %s",
              tw_error_to_str(err));
    tw_tileset_destroy(ts);

    /* An unknown name says which kind of mistake it is. */
    err = tw_tilesets_builtin("citty", 5, 0, &log, &ts);
    CHECK_MSG(err == TW_ERR_INVALID && !ts &&
                  strcmp(captured.last, "tileset \"citty\": no such built-in tileset (city, "
                                        "forest, hybrid)") == 0,
              "unknown name: %s", captured.last);
    err = tw_tilesets_builtin("my/tiles.json", 5, 0, &log, &ts);
    CHECK_MSG(err == TW_ERR_INVALID && !ts &&
                  strstr(captured.last, "tileset \"my/tiles.json\": a file name, not a built-in "
                                        "tileset"),
              "a file name: %s", captured.last);

    /* forest and hybrid: the generators with default settings. */
    ts = NULL;
    direct = NULL;
    err = tw_tilesets_builtin("forest", 5, 0, &log, &ts);
    CHECK_MSG(err == 0 && ts, "builtin(forest): %s", tw_error_to_str(err));
    err = tw_tilesets_forest(5, NULL, NULL, &direct);
    if (ts && direct)
        CHECK_MSG(tilesets_identical(ts, direct), "builtin(forest) differs from forest()");
    tw_tileset_destroy(ts);
    tw_tileset_destroy(direct);
    ts = NULL;
    direct = NULL;
    err = tw_tilesets_builtin("hybrid", 5, 1024, &log, &ts);
    CHECK_MSG(err == 0 && ts && ts->max_cluster_triangles == 1024, "builtin(hybrid, 1024): %s",
              tw_error_to_str(err));
    struct tw_hybrid_settings hybrid = {0};
    hybrid.max_cluster_triangles = 1024;
    err = tw_tilesets_hybrid(5, &hybrid, NULL, &direct);
    if (ts && direct)
        CHECK_MSG(tilesets_identical(ts, direct), "builtin(hybrid) differs from hybrid()");
    tw_tileset_destroy(ts);
    tw_tileset_destroy(direct);

    ts = NULL;
    captured.errors = 0;
    err = tw_tilesets_builtin("nope", 5, 0, &log, &ts);
    CHECK_MSG(err == TW_ERR_INVALID, "builtin(nope) returned %d", err);
    CHECK_MSG(ts == NULL, "builtin(nope) produced a tileset");
    CHECK_MSG(captured.errors == 1 && strstr(captured.last, "nope"),
              "no error naming \"nope\": \"%s\"", captured.last);

    err = tw_tilesets_builtin("nope", 5, 0, NULL, &ts);
    CHECK_MSG(err == TW_ERR_INVALID, "builtin(nope) without a logger returned %d", err);
    err = tw_tilesets_builtin(NULL, 5, 0, NULL, &ts);
    CHECK_MSG(err == TW_ERR_INVALID, "builtin(NULL) returned %d", err);
}

/* ---- merging small instances (tw_tileset_finish) ------------------------------------ */

/* A quad of two triangles in the xz plane, normals up; n_quads quads in a row. */
static int add_strip(struct tw_tileset *ts, uint32_t n_quads)
{
    float pos[4 * 3 * 64], nrm[4 * 3 * 64];
    uint32_t idx[6 * 64];
    for (uint32_t q = 0; q < n_quads && q < 64; q++) {
        const float x = (float)q;
        const float corners[4][3] = {{x, 0, 0}, {x + 1, 0, 0}, {x, 0, 1}, {x + 1, 0, 1}};
        for (int v = 0; v < 4; v++)
            for (int a = 0; a < 3; a++) {
                pos[12 * q + 3 * v + a] = corners[v][a];
                nrm[12 * q + 3 * v + a] = a == 1 ? 1.0f : 0.0f;
            }
        const uint32_t b = 4 * q;
        const uint32_t tri[6] = {b, b + 2, b + 1, b + 1, b + 2, b + 3};
        memcpy(idx + 6 * q, tri, sizeof(tri));
    }
    return tw_tileset_add_mesh(ts, pos, nrm, 4 * n_quads, idx, 2 * n_quads);
}

/* A tileset of one prototype: three small quads of material 0 (one rotated
 * and scaled), one small quad of material 1, one strip of 10 triangles of
 * material 0; merge_triangles 8, clusters of at most 4 triangles. */
static struct tw_tileset *merge_tileset(uint32_t merge_triangles)
{
    struct tw_tileset *ts = NULL;
    if (tw_tileset_create("merge", 40, 40, &ts))
        return NULL;
    ts->merge_triangles = merge_triangles;
    const float grey[4] = {0.5f, 0.5f, 0.5f, 1}, red[4] = {1, 0, 0, 1};
    const int quad = add_strip(ts, 1), strip = add_strip(ts, 5);
    const int m0 = tw_tileset_add_material(ts, grey), m1 = tw_tileset_add_material(ts, red);
    const int p = tw_tileset_add_prototype(ts, "p", 1.0f);
    const float at1[12] = {1, 0, 0, 3, 0, 1, 0, 0, 0, 0, 1, 2};
    /* 90 degrees about y, scaled 2 in x, moved: a transform with rounding. */
    const float at2[12] = {0, 0, 1.5f, 10.25f, 0, 1, 0, 0.5f, -2.0f, 0, 0, 7.125f};
    const float at3[12] = {1, 0, 0, 20, 0, 1, 0, 0, 0, 0, 1, 20};
    const float at4[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 30};
    if (quad < 0 || strip < 0 || m0 < 0 || m1 < 0 || p < 0 ||
        tw_tileset_add_instance(ts, 0, (uint32_t)quad, (uint32_t)m0, at1) != 0 ||
        tw_tileset_add_instance(ts, 0, (uint32_t)quad, (uint32_t)m1, at3) != 1 ||
        tw_tileset_add_instance(ts, 0, (uint32_t)quad, (uint32_t)m0, at2) != 2 ||
        tw_tileset_add_instance(ts, 0, (uint32_t)strip, (uint32_t)m0, at4) != 3 ||
        tw_tileset_add_instance(ts, 0, (uint32_t)quad, (uint32_t)m0, NULL) != 4 ||
        tw_tileset_finish(ts, 4) != TW_OK) {
        tw_tileset_destroy(ts);
        return NULL;
    }
    return ts;
}

static uint64_t mesh_bytes(const struct tw_tileset *ts)
{
    uint64_t bytes = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        bytes += 20ull * ts->meshes[k].vertex_count + 12ull * ts->meshes[k].triangle_count;
    return bytes;
}

/* Baked copies stop at TW_TILESET_MERGE_BYTES: 4 000 instances of a mesh of
 * 63 triangles (189 vertices, 6 048 baked bytes each) bake as many as fit,
 * the rest stay instanced, and a later prototype finds the budget spent. */
static void test_merge_budget(void)
{
    enum { TRIS = 63, VERTS = 3 * TRIS, COUNT = 4000 };
    static float pos[3 * VERTS];
    static uint32_t idx[3 * TRIS];
    for (uint32_t t = 0; t < TRIS; t++) {
        const float x = (float)(t % 8) * 0.1f, y = (float)(t / 8) * 0.1f;
        const float tri[9] = {x, y, 0, x + 0.05f, y, 0, x, y + 0.05f, 0};
        memcpy(pos + 9 * t, tri, sizeof(tri));
        for (int v = 0; v < 3; v++)
            idx[3 * t + v] = 3 * t + (uint32_t)v;
    }
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("budget", 40, 40, &ts) == TW_OK);
    if (!ts)
        return;
    bool ok = tw_tileset_add_mesh(ts, pos, NULL, VERTS, idx, TRIS) == 0 &&
              tw_tileset_add_material(ts, (const float[4]){0.2f, 0.4f, 0.6f, 1}) == 0 &&
              tw_tileset_add_prototype(ts, "many", 1.0f) == 0 &&
              tw_tileset_add_prototype(ts, "later", 1.0f) == 1;
    for (uint32_t k = 0; ok && k < COUNT + 2; k++) {
        const float at[12] = {1, 0, 0, (float)(k % 64) * 0.6f, 0, 1, 0, 0,
                              0, 0, 1, (float)(k / 64 % 64) * 0.6f};
        ok = tw_tileset_add_instance(ts, k < COUNT ? 0 : 1, 0, 0, at) >= 0;
    }
    CHECK(ok && tw_tileset_finish(ts, 2048) == TW_OK);
    const uint64_t each = 28ull * VERTS + 12ull * TRIS;
    const uint32_t fit = (uint32_t)(TW_TILESET_MERGE_BYTES / each);
    uint32_t merged_into[2] = {0, 0}, merged[2] = {0, 0};
    for (uint32_t p = 0; ok && p < 2; p++)
        for (uint32_t k = 0; k < ts->prototypes[p].instance_count; k++) {
            merged_into[p] += ts->prototypes[p].instances[k].merged_into != TW_INSTANCE_NONE;
            merged[p] += ts->prototypes[p].instances[k].merged;
        }
    CHECK_MSG(fit < COUNT && merged_into[0] == fit && merged[0] == 1 && merged_into[1] == 0 &&
                  merged[1] == 0,
              "%u of %u baked (%u fit), later prototype %u baked", merged_into[0], COUNT, fit,
              merged_into[1]);
    /* The baked mesh holds exactly the instances that fit. */
    const struct tw_mesh *baked = ts->mesh_count == 2 ? &ts->meshes[1] : NULL;
    CHECK_MSG(baked && baked->colors && baked->vertex_count == fit * VERTS &&
                  baked->triangle_count == fit * TRIS,
              "%u meshes, the baked one of %u vertices", ts->mesh_count,
              baked ? baked->vertex_count : 0);
    tw_tileset_destroy(ts);
}

/* Small instances, whatever their materials, are baked into one tile-local
 * mesh whose vertices carry their materials' colours, drawn in clusters of
 * at most max_cluster_triangles; the rest is as before. */
static void test_merge_instances(void)
{
    struct tw_tileset *ts = merge_tileset(8), *plain = merge_tileset(1);
    CHECK_MSG(ts && plain, "merge tilesets made");
    if (!ts || !plain)
        goto out;
    const struct tw_prototype *p = &ts->prototypes[0], *q = &plain->prototypes[0];
    /* Unmerged: one cluster per quad, four for the strip of 10 (5 + 5, each 2 + 3). */
    CHECK_MSG(q->instance_count == 5 && q->cluster_count == 4 + 4, "plain: %u instances, %u clusters",
              q->instance_count, q->cluster_count);
    CHECK_MSG(plain->mesh_count == 2, "plain: %u meshes", plain->mesh_count);
    /* Merged: the four quads (grey and red) into instance 5; the strip is not
     * small: as it was. */
    CHECK_MSG(p->instance_count == 6 && ts->mesh_count == 3, "%u instances, %u meshes",
              p->instance_count, ts->mesh_count);
    if (p->instance_count != 6 || ts->mesh_count != 3)
        goto out;
    const struct tw_instance *mi = &p->instances[5];
    /* Its material is a white one, added after grey and red. */
    CHECK_MSG(mi->merged && mi->merged_into == TW_INSTANCE_NONE && mi->material == 2 &&
                  ts->material_count == 3 && mi->mesh == 2,
              "merged instance: merged %d, mesh %u, material %u of %u", mi->merged, mi->mesh,
              mi->material, ts->material_count);
    if (mi->material < ts->material_count)
        for (int c = 0; c < 4; c++)
            CHECK_MSG(ts->materials[mi->material].base_color[c] == 1.0f, "merged material %d: %g", c,
                      (double)ts->materials[mi->material].base_color[c]);
    CHECK_MSG(plain->material_count == 2 && !plain->meshes[0].colors && !plain->meshes[1].colors,
              "plain: %u materials, colours on a mesh", plain->material_count);
    const uint32_t expect_into[5] = {5, 5, 5, TW_INSTANCE_NONE, 5};
    for (uint32_t k = 0; k < 5; k++)
        CHECK_MSG(p->instances[k].merged_into == expect_into[k] && !p->instances[k].merged,
                  "instance %u merged into %u", k, p->instances[k].merged_into);
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    CHECK_MSG(memcmp(mi->transform, identity, sizeof(identity)) == 0, "identity placement");
    const struct tw_mesh *mm = &ts->meshes[2];
    CHECK_MSG(mm->vertex_count == 16 && mm->triangle_count == 8 && mm->colors,
              "merged mesh: %u vertices, %u triangles, colours %p", mm->vertex_count,
              mm->triangle_count, (const void *)mm->colors);
    if (mm->vertex_count != 16 || !mm->colors)
        goto out;
    /* Clusters: the merged 8 triangles in 2 (<= 4 each), the strip's 4. */
    CHECK_MSG(p->cluster_count == 2 + 4, "%u clusters", p->cluster_count);
    uint64_t tris = 0;
    for (uint32_t k = 0; k < p->cluster_count; k++) {
        const struct tw_cluster *c = &p->clusters[k];
        CHECK_MSG(c->triangle_count <= 4, "cluster %u: %u triangles", k, c->triangle_count);
        CHECK_MSG(p->instances[c->instance].merged_into == TW_INSTANCE_NONE,
                  "cluster %u drawn by a merged-away instance", k);
        tris += c->triangle_count;
    }
    CHECK_MSG(tris == p->triangle_count && p->triangle_count == q->triangle_count,
              "%llu cluster triangles, %llu and %llu in the prototypes", (unsigned long long)tris,
              (unsigned long long)p->triangle_count, (unsigned long long)q->triangle_count);
    /* Every transformed vertex of a merged instance is in the merged mesh
     * (up to float rounding), with its normal transformed the same way and
     * its instance's colour. */
    const struct tw_mesh *quad = &ts->meshes[0];
    for (uint32_t k = 0; k < 5; k++) {
        if (k == 3)
            continue;   /* the strip */
        const struct tw_instance *in = &p->instances[k];
        const uint8_t want_rgba[2][4] = {{128, 128, 128, 255}, {255, 0, 0, 255}};
        for (uint32_t v = 0; v < quad->vertex_count; v++) {
            float want[3], n[3];
            transform_point(in->transform, quad->positions + 3 * v, want);
            const float *qn = quad->normals + 3 * v;
            for (int r = 0; r < 3; r++)
                n[r] = in->transform[4 * r] * qn[0] + in->transform[4 * r + 1] * qn[1] +
                       in->transform[4 * r + 2] * qn[2];
            bool found = false;
            for (uint32_t u = 0; u < mm->vertex_count && !found; u++) {
                const float *got = mm->positions + 3 * u, *gn = mm->normals + 3 * u;
                found = fabsf(got[0] - want[0]) < 1e-5f && fabsf(got[1] - want[1]) < 1e-5f &&
                        fabsf(got[2] - want[2]) < 1e-5f && fabsf(gn[0] - n[0]) < 1e-6f &&
                        fabsf(gn[1] - n[1]) < 1e-6f && fabsf(gn[2] - n[2]) < 1e-6f &&
                        memcmp(mm->colors + 4 * u, want_rgba[in->material], 4) == 0;
            }
            CHECK_MSG(found, "instance %u vertex %u (%g %g %g) not in the merged mesh", k, v,
                      (double)want[0], (double)want[1], (double)want[2]);
        }
        /* Its box is where its triangles are, inside the prototype's. */
        CHECK_MSG(box_contains(&p->box, &in->box), "instance %u box outside the prototype", k);
    }
    for (int a = 0; a < 3; a++)
        CHECK_MSG(p->box.min[a] == q->box.min[a] && p->box.max[a] == q->box.max[a],
                  "prototype box axis %d: [%g, %g] vs [%g, %g]", a, (double)p->box.min[a],
                  (double)p->box.max[a], (double)q->box.min[a], (double)q->box.max[a]);
    /* The merged mesh costs its bytes. */
    CHECK_MSG(tw_tileset_geometry_bytes(ts) == mesh_bytes(ts) &&
                  tw_tileset_geometry_bytes(ts) == tw_tileset_geometry_bytes(plain) + 16 * 20 + 8 * 12,
              "geometry bytes %llu, plain %llu", (unsigned long long)tw_tileset_geometry_bytes(ts),
              (unsigned long long)tw_tileset_geometry_bytes(plain));
out:
    tw_tileset_destroy(ts);
    tw_tileset_destroy(plain);
    /* Whole meshes asked for (no cluster size): nothing merged. */
    struct tw_tileset *whole = NULL;
    if (tw_tileset_create("whole", 10, 10, &whole) == TW_OK) {
        const int one = add_strip(whole, 1);
        const int m = tw_tileset_add_material(whole, (const float[4]){1, 1, 1, 1});
        tw_tileset_add_prototype(whole, "p", 1.0f);
        for (int k = 0; k < 3 && one >= 0 && m >= 0; k++)
            tw_tileset_add_instance(whole, 0, (uint32_t)one, (uint32_t)m, NULL);
        CHECK_MSG(tw_tileset_finish(whole, 0) == TW_OK && whole->prototypes[0].instance_count == 3 &&
                      whole->prototypes[0].cluster_count == 3,
                  "max_cluster_triangles 0 merges nothing");
    }
    tw_tileset_destroy(whole);
}

/* The built-in forest: its many small plants are merged, and its clusters
 * are far fewer than its instances. */
static void test_merge_builtin(void)
{
    struct tw_tileset *ts = NULL;
    CHECK_MSG(tw_tilesets_builtin("forest", 1, 0, NULL, &ts) == TW_OK, "forest");
    if (!ts)
        return;
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        uint32_t merged = 0, merged_away = 0;
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            merged += proto->instances[k].merged;
            merged_away += proto->instances[k].merged_into != TW_INSTANCE_NONE;
            if (proto->instances[k].merged_into != TW_INSTANCE_NONE)
                CHECK_MSG(ts->meshes[proto->instances[k].mesh].triangle_count <
                              TW_TILESET_MERGE_TRIANGLES,
                          "%s: instance %u merged with %u triangles", proto->name, k,
                          ts->meshes[proto->instances[k].mesh].triangle_count);
        }
        CHECK_MSG(merged > 0 && merged_away > 4 * merged, "%s: %u merged meshes of %u instances",
                  proto->name, merged, merged_away);
        uint32_t merged_clusters = 0;
        for (uint32_t k = 0; k < proto->cluster_count; k++)
            merged_clusters += proto->instances[proto->clusters[k].instance].merged;
        CHECK_MSG(4 * merged_clusters < merged_away, "%s: %u clusters for %u merged instances",
                  proto->name, merged_clusters, merged_away);
    }
    tw_tileset_destroy(ts);
}

int main(void)
{
    test_city();
    test_city_settings();
    test_forest();
    test_forest_settings();
    test_hybrid();
    test_builtin();
    test_merge_instances();
    test_merge_budget();
    test_merge_builtin();
    return check_summary("test-tilesets");
}
