/* Tests of the built-in tile providers city-gen and forest-gen (tilesets.h,
 * DESIGN.md §12): every generated tile inside the declared bound, and the
 * bound not loose; the same cell gives the same tile bit for bit, also from
 * four threads at once; neighbours differ; the triangle density of the
 * fixed tileset each is named after; streets and trails clear along every
 * border; bytes and generation times reported.
 *
 * usage: test-providers [cells]   (cells swept per provider; default 2000) */
#include "tileworld/tilesets.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tests/tileset-checks.h"
#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"

static const uint64_t seed = 1;

/* ---- helpers ------------------------------------------------------------------------ */

/* CPU time of the calling thread: what generation costs, whatever else the
 * machine runs. */
static double thread_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return 1e3 * (double)ts.tv_sec + 1e-6 * (double)ts.tv_nsec;
}

/* What a world does with a cell: a fresh tileset, generate(), finish(). */
static int make_tile(const struct tw_tile_provider *p, struct tw_cell cell,
                     struct tw_tileset **out, double *generate_ms, double *finish_ms)
{
    struct tw_tileset *ts = NULL;
    int err = tw_tileset_create("tile", p->footprint[0], p->footprint[1], &ts);
    if (err)
        return err;
    const double t0 = thread_ms();
    err = p->generate(p->user, cell, ts);
    const double t1 = thread_ms();
    if (!err)
        err = tw_tileset_finish(ts, p->max_cluster_triangles ? p->max_cluster_triangles : 2048);
    const double t2 = thread_ms();
    if (generate_ms)
        *generate_ms = t1 - t0;
    if (finish_ms)
        *finish_ms = t2 - t1;
    if (err) {
        tw_tileset_destroy(ts);
        return err;
    }
    *out = ts;
    return TW_OK;
}

static bool box_inside(const struct tw_box *inner, const struct tw_box *outer)
{
    for (int k = 0; k < 3; k++)
        if (!(inner->min[k] >= outer->min[k] && inner->max[k] <= outer->max[k]))
            return false;
    return true;
}

/* Bit-for-bit equality of two finished tiles: every array the builder and
 * finish() write. */
static bool tiles_identical(const struct tw_tileset *a, const struct tw_tileset *b)
{
    if (a->material_count != b->material_count || a->mesh_count != b->mesh_count ||
        a->part_count != b->part_count || a->prototype_count != b->prototype_count ||
        memcmp(&a->common_box, &b->common_box, sizeof(a->common_box)) != 0 ||
        memcmp(a->materials, b->materials, sizeof(*a->materials) * a->material_count) != 0 ||
        memcmp(a->parts, b->parts, sizeof(*a->parts) * a->part_count) != 0)
        return false;
    for (uint32_t k = 0; k < a->mesh_count; k++) {
        const struct tw_mesh *x = &a->meshes[k], *y = &b->meshes[k];
        if (!mesh_data_identical(x, y) || x->first_part != y->first_part ||
            x->part_count != y->part_count || memcmp(&x->box, &y->box, sizeof(x->box)) != 0)
            return false;
    }
    for (uint32_t k = 0; k < a->prototype_count; k++) {
        const struct tw_prototype *x = &a->prototypes[k], *y = &b->prototypes[k];
        if (!prototype_head_identical(x, y) ||
            memcmp(x->instances, y->instances, sizeof(*x->instances) * x->instance_count) != 0 ||
            memcmp(x->clusters, y->clusters, sizeof(*x->clusters) * x->cluster_count) != 0)
            return false;
    }
    return true;
}

/* A digest of what a tile places: mesh sizes and boxes, every instance
 * (mesh, material, transform). Tiles that differ in layout differ here. */
static uint64_t tile_digest(const struct tw_tileset *ts)
{
    uint64_t h = 0x9e3779b97f4a7c15ull;
    const unsigned char *bytes;
    size_t n;
#define MIX(ptr, size)                                       \
    do {                                                     \
        bytes = (const unsigned char *)(ptr);                \
        n = (size);                                          \
        for (size_t q = 0; q < n; q++)                       \
            h = (h ^ bytes[q]) * 0x100000001b3ull;           \
    } while (0)
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        MIX(&ts->meshes[k].vertex_count, sizeof(uint32_t));
        MIX(&ts->meshes[k].box, sizeof(struct tw_box));
    }
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        MIX(ts->prototypes[p].instances,
            sizeof(struct tw_instance) * ts->prototypes[p].instance_count);
#undef MIX
    return h;
}

/* Triangles that come within band of a tile border (their bounding
 * rectangle does) and reach into the height slab (lo, hi): what would stand
 * in the way of a camera walking along the border. */
static uint64_t border_slab_triangles(const struct tw_tileset *ts, float band, float lo,
                                      float hi)
{
    const float w = ts->footprint[0], d = ts->footprint[1];
    uint64_t count = 0;
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        for (uint32_t k = 0; k < proto->instance_count; k++) {
            const struct tw_instance *in = &proto->instances[k];
            /* Most instances are far from every border: skip them whole. */
            if (in->box.min[0] >= band && in->box.max[0] <= w - band && in->box.min[2] >= band &&
                in->box.max[2] <= d - band)
                continue;
            if (in->box.max[1] <= lo || in->box.min[1] >= hi)
                continue;
            const struct tw_mesh *m = &ts->meshes[in->mesh];
            for (uint32_t t = 0; t < m->triangle_count; t++) {
                float min[3], max[3];
                placed_triangle_bounds(in, m, t, min, max);
                const bool near_border = min[0] < band || max[0] > w - band || min[2] < band ||
                                         max[2] > d - band;
                if (near_border && max[1] > lo && min[1] < hi)
                    count++;
            }
        }
    }
    return count;
}

/* Meshes of the tile that no instance draws (memory spent on nothing). */
static uint32_t unused_meshes(const struct tw_tileset *ts)
{
    bool *used = calloc(ts->mesh_count, sizeof(bool));
    if (!used)
        return UINT32_MAX;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        for (uint32_t k = 0; k < ts->prototypes[p].instance_count; k++)
            used[ts->prototypes[p].instances[k].mesh] = true;
    uint32_t n = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++)
        n += !used[k];
    free(used);
    return n;
}

/* Mean, standard deviation, quantiles. Sorts v. */
struct summary {
    double mean, sd, min, p10, p50, p90, p99, max;
};

static int compare_doubles(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static int compare_u64(const void *a, const void *b)
{
    const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

static struct summary summarize(double *v, size_t n)
{
    struct summary s = {0};
    if (n == 0)
        return s;
    double sum = 0.0;
    for (size_t k = 0; k < n; k++)
        sum += v[k];
    s.mean = sum / (double)n;
    double var = 0.0;
    for (size_t k = 0; k < n; k++)
        var += (v[k] - s.mean) * (v[k] - s.mean);
    s.sd = n > 1 ? sqrt(var / (double)(n - 1)) : 0.0;
    qsort(v, n, sizeof(*v), compare_doubles);
    s.min = v[0];
    s.p10 = v[n / 10];
    s.p50 = v[n / 2];
    s.p90 = v[n * 9 / 10];
    s.p99 = v[n * 99 / 100];
    s.max = v[n - 1];
    return s;
}

static void print_summary(const char *what, const struct summary *s)
{
    printf("  %-34s mean %9.2f sd %8.2f | min %9.2f p10 %9.2f p50 %9.2f p90 %9.2f p99 %9.2f "
           "max %9.2f\n",
           what, s->mean, s->sd, s->min, s->p10, s->p50, s->p90, s->p99, s->max);
}

/* The triangles per cell of a world of the fixed tileset: its prototypes
 * weighed by their selection weights, over several seeds (one seed's dozen
 * prototypes are a small sample of what the generator draws). */
static void fixed_density(const char *name, uint64_t first_seed, uint32_t seeds, double *mean,
                          double *sd, double *first_mean, double *first_sd)
{
    double w = 0.0, sum = 0.0, sum2 = 0.0;
    for (uint32_t s = 0; s < seeds; s++) {
        struct tw_tileset *ts = NULL;
        const int err = tw_tilesets_builtin(name, first_seed + s, 0, NULL, &ts);
        CHECK_MSG(err == 0, "%s seed %llu: %s", name, (unsigned long long)(first_seed + s),
                  tw_error_to_str(err));
        if (err)
            continue;
        double ws = 0.0, sums = 0.0, sum2s = 0.0;
        for (uint32_t p = 0; p < ts->prototype_count; p++) {
            const double t = (double)ts->prototypes[p].triangle_count;
            const double pw = ts->prototypes[p].weight;
            ws += pw;
            sums += pw * t;
            sum2s += pw * t * t;
        }
        if (s == 0) {
            *first_mean = sums / ws;
            *first_sd = sqrt(fmax(0.0, sum2s / ws - *first_mean * *first_mean));
        }
        w += ws;
        sum += sums;
        sum2 += sum2s;
        tw_tileset_destroy(ts);
    }
    *mean = sum / w;
    *sd = sqrt(fmax(0.0, sum2 / w - *mean * *mean));
}

/* ---- the registry and the boundaries of the API -------------------------------------- */

static void test_registry(void)
{
    CHECK_MSG(tw_tilesets_provider_names[0] && strcmp(tw_tilesets_provider_names[0], "city-gen") == 0 &&
                  tw_tilesets_provider_names[1] &&
                  strcmp(tw_tilesets_provider_names[1], "forest-gen") == 0 &&
                  !tw_tilesets_provider_names[2],
              "provider names");
    CHECK_MSG(tw_tilesets_is_provider("city-gen") && tw_tilesets_is_provider("forest-gen"),
              "is_provider misses a provider");
    CHECK_MSG(!tw_tilesets_is_provider("city") && !tw_tilesets_is_provider("forest") &&
                  !tw_tilesets_is_provider("") && !tw_tilesets_is_provider(NULL) &&
                  !tw_tilesets_is_provider("city-gen2"),
              "is_provider takes a non-provider");
    /* The names arrays list the registry's entries of each kind. */
    for (const char *const *n = tw_tilesets_provider_names; *n; n++)
        CHECK_MSG(tw_tilesets_is_provider(*n), "provider name \"%s\" is not a provider", *n);
    for (const char *const *n = tw_tilesets_builtin_names; *n; n++)
        CHECK_MSG(!tw_tilesets_is_provider(*n), "built-in tileset \"%s\" is a provider", *n);

    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};
    struct tw_tilesets_provider *p = (struct tw_tilesets_provider *)&captured;
    int err = tw_tilesets_provider_create("town-gen", 1, 0, &log, &p);
    CHECK_MSG(err == TW_ERR_INVALID && !p, "unknown name: %s", tw_error_to_str(err));
    CHECK_MSG(captured.errors == 1 && strstr(captured.last, "town-gen") &&
                  strstr(captured.last, "city-gen"),
              "unknown name: message \"%s\"", captured.last);
    err = tw_tilesets_provider_create(NULL, 1, 0, &log, &p);
    CHECK_MSG(err == TW_ERR_INVALID && !p, "NULL name: %s", tw_error_to_str(err));
    err = tw_tilesets_provider_create("city-gen", 1, 0, &log, NULL);
    CHECK_MSG(err == TW_ERR_INVALID, "NULL out: %s", tw_error_to_str(err));
    tw_tilesets_provider_destroy(NULL);
    CHECK_MSG(tw_tilesets_provider_get(NULL) == NULL, "get(NULL)");

    /* Bad settings are refused with a message that names the provider;
     * prototypes means nothing to a provider and is ignored. */
    captured.errors = 0;
    struct tw_city_settings city = {0};
    city.max_height = 5.0f;
    err = tw_tilesets_provider_create_city(1, &city, &log, &p);
    CHECK_MSG(err == TW_ERR_INVALID && !p && captured.errors == 1 &&
                  strstr(captured.last, "city-gen") && strstr(captured.last, "max_height"),
              "city-gen max_height 5: %s, \"%s\"", tw_error_to_str(err), captured.last);
    struct tw_forest_settings forest = {0};
    forest.density = 9.0f;
    err = tw_tilesets_provider_create_forest(1, &forest, &log, &p);
    CHECK_MSG(err == TW_ERR_INVALID && !p && captured.errors == 2 &&
                  strstr(captured.last, "forest-gen") && strstr(captured.last, "density"),
              "forest-gen density 9: %s, \"%s\"", tw_error_to_str(err), captured.last);
    city.max_height = 0.0f;
    city.prototypes = 3;
    err = tw_tilesets_provider_create_city(1, &city, &log, &p);
    CHECK_MSG(err == 0 && p, "city-gen with prototypes 3: %s", tw_error_to_str(err));
    tw_tilesets_provider_destroy(p);

    for (const char *const *name = tw_tilesets_provider_names; *name; name++) {
        p = NULL;
        err = tw_tilesets_provider_create(*name, 7, 512, &log, &p);
        CHECK_MSG(err == 0 && p, "%s: %s", *name, tw_error_to_str(err));
        if (err || !p)
            continue;
        const struct tw_tile_provider *tp = tw_tilesets_provider_get(p);
        CHECK_MSG(tp && strcmp(tp->name, *name) == 0, "%s: provider name", *name);
        CHECK_MSG(tp->footprint[0] == 80.0f && tp->footprint[1] == 80.0f, "%s: footprint %g x %g",
                  *name, (double)tp->footprint[0], (double)tp->footprint[1]);
        CHECK_MSG(tp->max_cluster_triangles == 512, "%s: max_cluster_triangles %u", *name,
                  tp->max_cluster_triangles);
        CHECK_MSG(!tp->content && !tp->shared && tp->generate && tp->user, "%s: callbacks", *name);

        /* generate() is given a fresh tileset of the provider's footprint:
         * anything else is the caller's bug, refused with the cell named. */
        const struct tw_cell cell = {-3, 12};
        struct tw_tileset *ts = NULL;
        captured.errors = 0;
        tw_tileset_create("wrong", 60.0f, 80.0f, &ts);
        err = tp->generate(tp->user, cell, ts);
        CHECK_MSG(err == TW_ERR_INVALID && captured.errors == 1 && strstr(captured.last, "(-3, 12)") &&
                      strstr(captured.last, "footprint"),
                  "%s: wrong footprint: %s, \"%s\"", *name, tw_error_to_str(err), captured.last);
        tw_tileset_destroy(ts);
        tw_tileset_create("taken", 80.0f, 80.0f, &ts);
        tw_tileset_add_prototype(ts, "someone else's", 1.0f);
        err = tp->generate(tp->user, cell, ts);
        CHECK_MSG(err == TW_ERR_INVALID && captured.errors == 2 && strstr(captured.last, "prototype"),
                  "%s: tileset with a prototype: %s, \"%s\"", *name, tw_error_to_str(err),
                  captured.last);
        tw_tileset_destroy(ts);
        err = tp->generate(tp->user, cell, NULL);
        CHECK_MSG(err == TW_ERR_INVALID && captured.errors == 3, "%s: NULL tileset: %s", *name,
                  tw_error_to_str(err));
        /* A good call after the bad ones, with the smaller clusters. */
        ts = NULL;
        err = make_tile(tp, cell, &ts, NULL, NULL);
        CHECK_MSG(err == 0 && ts && captured.errors == 3, "%s: generate: %s (%s)", *name,
                  tw_error_to_str(err), captured.last);
        if (ts) {
            const struct tw_prototype *proto = &ts->prototypes[0];
            uint32_t largest = 0;
            for (uint32_t k = 0; k < proto->cluster_count; k++)
                largest = proto->clusters[k].triangle_count > largest
                              ? proto->clusters[k].triangle_count
                              : largest;
            CHECK_MSG(largest <= 512, "%s: a cluster of %u triangles", *name, largest);
        }
        tw_tileset_destroy(ts);
        tw_tilesets_provider_destroy(p);
    }
}

/* ---- the sweep: bound, borders, variety, density, bytes, time -------------------------- */

static void sweep(const char *name, uint32_t cells)
{
    struct captured_log captured = {0};
    const struct tw_log log = {capture, &captured};
    struct tw_tilesets_provider *p = NULL;
    int err = tw_tilesets_provider_create(name, seed, 0, &log, &p);
    CHECK_MSG(err == 0 && p, "%s: %s", name, tw_error_to_str(err));
    if (err || !p)
        return;
    const struct tw_tile_provider *tp = tw_tilesets_provider_get(p);
    const bool city = strcmp(name, "city-gen") == 0;
    const struct tw_box bound = tp->bound;
    const float w = tp->footprint[0];
    printf("%s seed %llu: bound x [%g, %g] y [%g, %g] z [%g, %g]\n", name,
           (unsigned long long)seed, (double)bound.min[0], (double)bound.max[0],
           (double)bound.min[1], (double)bound.max[1], (double)bound.min[2],
           (double)bound.max[2]);

    double *triangles = calloc(cells, sizeof(double));
    double *generate_ms = calloc(cells, sizeof(double));
    double *total_ms = calloc(cells, sizeof(double));
    double *bytes = calloc(cells, sizeof(double));
    uint64_t *digests = calloc(cells, sizeof(uint64_t));
    uint32_t *tri_count = calloc(cells, sizeof(uint32_t));
    if (!triangles || !generate_ms || !total_ms || !bytes || !digests || !tri_count) {
        CHECK_MSG(false, "%s: out of memory", name);
        goto out;
    }

    /* Cells of a rectangle round the origin, 50 wide, so that every cell
     * but the last row's has neighbours to its right and below. */
    const uint32_t row = 50;
    float tallest = 0.0f;
    uint32_t outside = 0, failed = 0, wasted = 0, off_ground = 0, band_bad = 0, band_seen = 0;
    uint32_t outside_first = UINT32_MAX, band_first = UINT32_MAX;
    const float band = city ? 6.0f : 1.0f;    /* street_width / 2 - 1; path_clearance */
    const float slab_lo = city ? 0.2f : 0.05f, slab_hi = city ? 1e30f : 2.5f;
    for (uint32_t k = 0; k < cells; k++) {
        const struct tw_cell cell = {(int64_t)(k % row) - 25, (int64_t)(k / row) - 20};
        struct tw_tileset *ts = NULL;
        double gen = 0.0, fin = 0.0;
        err = make_tile(tp, cell, &ts, &gen, &fin);
        if (err) {
            failed++;
            continue;
        }
        const struct tw_prototype *proto = &ts->prototypes[0];
        triangles[k] = (double)proto->triangle_count;
        tri_count[k] = (uint32_t)proto->triangle_count;
        generate_ms[k] = gen;
        total_ms[k] = gen + fin;
        bytes[k] = 1e-6 * (double)tw_tileset_bytes(ts);
        digests[k] = tile_digest(ts);
        /* The tile's box holds every cluster's, which hold the triangles. */
        if (ts->prototype_count != 1 || !box_inside(&proto->box, &bound)) {
            if (!outside)
                outside_first = k;
            outside++;
        }
        tallest = fmaxf(tallest, proto->box.max[1]);
        /* The ground spans the tile: the bound's x, z are tight. */
        off_ground += !(proto->box.min[0] == 0.0f && proto->box.min[1] == 0.0f &&
                        proto->box.min[2] == 0.0f && proto->box.max[0] == w &&
                        proto->box.max[2] == w);
        wasted += unused_meshes(ts);
        /* Streets (nothing above the kerb within 6 m of a border) and
         * trails (nothing between 0.05 and 2.5 m within 1 m of one). */
        if (k < 500) {
            const uint64_t bad = border_slab_triangles(ts, band, slab_lo, slab_hi);
            if (bad && band_first == UINT32_MAX)
                band_first = k;
            band_bad += bad > 0;
            /* The check sees what stands beyond the band. */
            band_seen += border_slab_triangles(ts, city ? 7.5f : 6.0f, slab_lo, slab_hi) > 0;
        }
        tw_tileset_destroy(ts);
    }
    const uint32_t checked_borders = cells < 500 ? cells : 500;
    CHECK_MSG(failed == 0 && captured.errors == 0, "%s: %u of %u cells failed (%s)", name, failed,
              cells, captured.last);
    CHECK_MSG(outside == 0, "%s: %u tiles leave the bound (first: cell %u)", name, outside,
              outside_first);
    CHECK_MSG(off_ground == 0, "%s: %u tiles do not span the footprint from y = 0", name, off_ground);
    CHECK_MSG(wasted == 0, "%s: %u meshes that no instance draws", name, wasted);
    CHECK_MSG(band_bad == 0, "%s: %u of %u tiles block the %s (first: cell %u)", name, band_bad,
              checked_borders, city ? "street" : "trail", band_first);
    CHECK_MSG(band_seen * 2 > checked_borders, "%s: the border check sees nothing beyond the band "
              "(%u of %u tiles)", name, band_seen, checked_borders);
    /* A true bound and not a loose one: within 10 % of the tallest tile. */
    printf("  tallest of %u tiles %.3f m: bound %.3f m is %.2f %% above\n", cells,
           (double)tallest, (double)bound.max[1],
           100.0 * ((double)bound.max[1] / (double)tallest - 1.0));
    CHECK_MSG(bound.max[1] <= 1.1f * tallest, "%s: bound height %g m is loose (tallest %g m)", name,
              (double)bound.max[1], (double)tallest);

    /* No two cells alike: every digest differs, and neighbours differ even
     * in their triangle counts. */
    uint32_t neighbours = 0, same_count = 0;
    for (uint32_t k = 0; k < cells; k++) {
        if (k % row + 1 < row && k + 1 < cells) {
            neighbours++;
            same_count += tri_count[k] == tri_count[k + 1];
        }
        if (k + row < cells) {
            neighbours++;
            same_count += tri_count[k] == tri_count[k + row];
        }
    }
    qsort(digests, cells, sizeof(*digests), compare_u64);
    uint32_t equal_digests = 0;
    for (uint32_t k = 0; k + 1 < cells; k++)
        equal_digests += digests[k] == digests[k + 1];
    printf("  variety: %u equal digests among %u tiles; %u of %u neighbour pairs with equal "
           "triangle counts\n",
           equal_digests, cells, same_count, neighbours);
    CHECK_MSG(equal_digests == 0, "%s: %u pairs of equal tiles", name, equal_digests);
    CHECK_MSG(same_count * 100 <= neighbours, "%s: %u of %u neighbours have equal triangle counts",
              name, same_count, neighbours);

    /* Density: the fixed tileset's cells, over 16 seeds (the first one
     * alone shown too), against every swept cell and the first 200. */
    double fixed_mean = 0.0, fixed_sd = 0.0, first_mean = 0.0, first_sd = 0.0;
    fixed_density(city ? "city" : "forest", seed, 16, &fixed_mean, &fixed_sd, &first_mean,
                  &first_sd);
    double *first200 = calloc(cells < 200 ? cells : 200, sizeof(double));
    const uint32_t n200 = cells < 200 ? cells : 200;
    if (first200)
        memcpy(first200, triangles, sizeof(double) * n200);
    const struct summary s200 = first200 ? summarize(first200, n200) : (struct summary){0};
    free(first200);
    const struct summary tri = summarize(triangles, cells);
    printf("  triangles per tile, %s: mean %.0f sd %.0f (16 seeds); seed %llu alone: mean %.0f "
           "sd %.0f\n",
           city ? "city" : "forest", fixed_mean, fixed_sd, (unsigned long long)seed, first_mean,
           first_sd);
    print_summary("triangles per tile, first 200", &s200);
    print_summary("triangles per tile, all", &tri);
    printf("  mean %+.1f %%, sd %+.1f %% against the fixed tileset (all cells); first 200: "
           "mean %+.1f %%, sd %+.1f %%\n",
           100.0 * (tri.mean / fixed_mean - 1.0), 100.0 * (tri.sd / fixed_sd - 1.0),
           100.0 * (s200.mean / fixed_mean - 1.0), 100.0 * (s200.sd / fixed_sd - 1.0));
    CHECK_MSG(fabs(tri.mean / fixed_mean - 1.0) <= 0.10, "%s: mean %.0f triangles, fixed %.0f", name,
              tri.mean, fixed_mean);
    CHECK_MSG(fabs(tri.sd / fixed_sd - 1.0) <= 0.10, "%s: sd %.0f triangles, fixed %.0f", name,
              tri.sd, fixed_sd);

    const struct summary mb = summarize(bytes, cells);
    const struct summary g = summarize(generate_ms, cells);
    const struct summary t = summarize(total_ms, cells);
    print_summary("tw_tileset_bytes per tile, MB", &mb);
    print_summary("generate, CPU ms", &g);
    print_summary("generate + finish, CPU ms", &t);
    CHECK_MSG(mb.min > 0.0, "%s: a tile of no bytes", name);

out:
    free(triangles);
    free(generate_ms);
    free(total_ms);
    free(bytes);
    free(digests);
    free(tri_count);
    tw_tilesets_provider_destroy(p);
}

/* ---- determinism, also from four threads ---------------------------------------------- */

enum { THREADS = 4, SHARED_CELLS = 12 };

struct worker {
    const struct tw_tile_provider *provider;
    const struct tw_cell *cells;
    struct tw_tileset *const *reference;
    uint32_t first;         /* where in cells this worker starts */
    uint32_t errors, mismatches, tiles;
};

static void *work(void *arg)
{
    struct worker *wk = arg;
    /* Every worker makes every cell, starting at a different one: the same
     * cells are made by several threads at once. */
    for (uint32_t n = 0; n < 2 * SHARED_CELLS; n++) {
        const uint32_t k = (wk->first + n) % SHARED_CELLS;
        struct tw_tileset *ts = NULL;
        if (make_tile(wk->provider, wk->cells[k], &ts, NULL, NULL)) {
            wk->errors++;
            continue;
        }
        wk->mismatches += !tiles_identical(ts, wk->reference[k]);
        wk->tiles++;
        tw_tileset_destroy(ts);
    }
    return NULL;
}

static void test_determinism(const char *name)
{
    struct tw_tilesets_provider *p = NULL;
    int err = tw_tilesets_provider_create(name, seed, 0, NULL, &p);
    CHECK_MSG(err == 0 && p, "%s: %s", name, tw_error_to_str(err));
    if (err || !p)
        return;
    const struct tw_tile_provider *tp = tw_tilesets_provider_get(p);
    /* Neighbours, negative cells and cells far from the origin. */
    const struct tw_cell cells[SHARED_CELLS] = {
        {0, 0}, {1, 0}, {0, 1}, {-1, -1}, {5, -7}, {-40, 3},
        {(int64_t)1 << 40, 0}, {0, -((int64_t)1 << 40)}, {INT64_MAX, INT64_MIN},
        {INT64_MIN, INT64_MAX}, {123456789, 987654321}, {2, 2},
    };
    struct tw_tileset *reference[SHARED_CELLS] = {0};
    uint32_t made = 0, same_again = 0;
    for (uint32_t k = 0; k < SHARED_CELLS; k++) {
        err = make_tile(tp, cells[k], &reference[k], NULL, NULL);
        CHECK_MSG(err == 0, "%s: cell (%lld, %lld): %s", name, (long long)cells[k].i,
                  (long long)cells[k].j, tw_error_to_str(err));
        if (err)
            continue;
        made++;
        struct tw_tileset *again = NULL;
        if (make_tile(tp, cells[k], &again, NULL, NULL) == 0 &&
            tiles_identical(reference[k], again))
            same_again++;
        tw_tileset_destroy(again);
    }
    CHECK_MSG(made == SHARED_CELLS && same_again == SHARED_CELLS,
              "%s: %u of %u cells the same when made again", name, same_again, made);
    /* The comparison can fail: neighbours are not identical. */
    if (reference[0] && reference[1])
        CHECK_MSG(!tiles_identical(reference[0], reference[1]), "%s: cells (0, 0) and (1, 0) are "
                  "identical", name);
    if (made != SHARED_CELLS)
        goto out;

    struct worker workers[THREADS];
    pthread_t threads[THREADS];
    bool started[THREADS] = {false};
    for (uint32_t t = 0; t < THREADS; t++) {
        workers[t] = (struct worker){tp, cells, reference, 3 * t, 0, 0, 0};
        started[t] = pthread_create(&threads[t], NULL, work, &workers[t]) == 0;
        CHECK_MSG(started[t], "%s: pthread_create failed", name);
    }
    uint32_t tiles = 0, errors = 0, mismatches = 0;
    for (uint32_t t = 0; t < THREADS; t++) {
        if (!started[t])
            continue;
        pthread_join(threads[t], NULL);
        tiles += workers[t].tiles;
        errors += workers[t].errors;
        mismatches += workers[t].mismatches;
    }
    printf("%s: %u tiles made by %d threads at once, %u errors, %u differ from the "
           "single-threaded ones\n",
           name, tiles, THREADS, errors, mismatches);
    CHECK_MSG(errors == 0 && mismatches == 0 && tiles == THREADS * 2 * SHARED_CELLS,
              "%s: %u errors, %u of %u tiles differ when made by %d threads", name, errors,
              mismatches, tiles, THREADS);
out:
    for (uint32_t k = 0; k < SHARED_CELLS; k++)
        tw_tileset_destroy(reference[k]);
    tw_tilesets_provider_destroy(p);
}

/* ---- other settings: the bound is derived, not fitted to the defaults ------------------ */

static void test_settings(void)
{
    struct tw_city_settings city = {0};
    city.footprint = 120.0f;
    city.street_width = 16.0f;
    city.max_height = 40.0f;
    struct tw_forest_settings forest = {0};
    forest.footprint = 120.0f;
    forest.path_clearance = 2.5f;
    forest.density = 0.5f;
    for (int which = 0; which < 2; which++) {
        struct tw_tilesets_provider *p = NULL;
        const int err = which == 0 ? tw_tilesets_provider_create_city(3, &city, NULL, &p)
                                   : tw_tilesets_provider_create_forest(3, &forest, NULL, &p);
        CHECK_MSG(err == 0 && p, "settings %d: %s", which, tw_error_to_str(err));
        if (err || !p)
            continue;
        const struct tw_tile_provider *tp = tw_tilesets_provider_get(p);
        CHECK_MSG(tp->footprint[0] == 120.0f && tp->bound.max[0] == 120.0f &&
                      tp->bound.max[2] == 120.0f,
                  "%s: footprint %g, bound x %g", tp->name, (double)tp->footprint[0],
                  (double)tp->bound.max[0]);
        if (which == 0)
            CHECK_MSG(tp->bound.max[1] == 40.25f, "city-gen, max_height 40: bound height %g",
                      (double)tp->bound.max[1]);
        uint32_t outside = 0, blocked = 0, made = 0;
        float tallest = 0.0f;
        for (int k = 0; k < 150; k++) {
            struct tw_tileset *ts = NULL;
            const struct tw_cell cell = {k % 15, k / 15};
            if (make_tile(tp, cell, &ts, NULL, NULL))
                continue;
            made++;
            outside += !box_inside(&ts->prototypes[0].box, &tp->bound);
            tallest = fmaxf(tallest, ts->prototypes[0].box.max[1]);
            blocked += border_slab_triangles(ts, which == 0 ? 7.0f : 2.5f,
                                             which == 0 ? 0.2f : 0.05f,
                                             which == 0 ? 1e30f : 2.5f) > 0;
            tw_tileset_destroy(ts);
        }
        printf("%s, footprint 120: %u tiles, tallest %.2f m, bound %.2f m\n", tp->name, made,
               (double)tallest, (double)tp->bound.max[1]);
        CHECK_MSG(made == 150 && outside == 0 && blocked == 0,
                  "%s, other settings: %u made, %u outside the bound, %u with blocked borders",
                  tp->name, made, outside, blocked);
        CHECK_MSG(tp->bound.max[1] <= 1.1f * tallest, "%s, other settings: bound %g, tallest %g",
                  tp->name, (double)tp->bound.max[1], (double)tallest);
        tw_tilesets_provider_destroy(p);
    }
}

int main(int argc, char **argv)
{
    const uint32_t cells = argc > 1 ? (uint32_t)strtoul(argv[1], NULL, 10) : 2000;
    if (cells < 200) {
        fprintf(stderr, "usage: test-providers [cells >= 200]\n");
        return 2;
    }
    test_registry();
    test_determinism("city-gen");
    test_determinism("forest-gen");
    test_settings();
    sweep("city-gen", cells);
    sweep("forest-gen", cells);
    return check_summary("test-providers");
}
