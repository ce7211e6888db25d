/*
 * The proxy of a block of cells (tiles/hlod.c): a block of one cell is its
 * prototype, a block of several the sum of its cells' chosen levels, placed;
 * empty cells show nothing; meshes shared between cells are copied once;
 * the block simplifies with tw_lods_build(); bad input is refused; the
 * same inputs give the same block. Then, printed only, NULL, the figures of the
 * built-in city's blocks as side doubles.
 */
#include "check.h"
#include "meshes.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"
#include "tileworld/tilesets.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CLUSTER 256u


/* Five prototypes on 40 x 40 m cells, small instances merged (the default),
 * so that a block meets merged instances:
 * 0 houses: 400 small red cubes (merged by tw_tileset_finish into one mesh);
 * 1 field: a green height field of 8192 triangles;
 * 2 facade: a grey wall and 100 dark windows in front of it;
 * 3 towers: 16 tall blue boxes on a green field, 8 of them turned;
 * 4 lone: one red cube, too small for levels. */
static struct tw_tileset *make_tileset(void)
{
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("hlod", 40, 40, &ts) == TW_OK);
    if (!ts)
        return NULL;
    const int red = tw_tileset_add_material(ts, (const float[4]){1, 0, 0, 1});
    const int green = tw_tileset_add_material(ts, (const float[4]){0, 1, 0, 1});
    const int grey = tw_tileset_add_material(ts, (const float[4]){0.6f, 0.6f, 0.6f, 1});
    const int dark = tw_tileset_add_material(ts, (const float[4]){0.1f, 0.1f, 0.2f, 1});
    const int blue = tw_tileset_add_material(ts, (const float[4]){0.2f, 0.3f, 0.9f, 1});
    const int cube = add_cube(ts);
    const int terrain = add_grid(ts, 64, 40.0f, false);
    const int small_terrain = add_grid(ts, 32, 40.0f, false);
    int wall, windows;
    add_facade(ts, 32, &wall, &windows);
    CHECK(red >= 0 && green >= 0 && grey >= 0 && dark >= 0 && blue >= 0 && cube >= 0 &&
          terrain >= 0 && small_terrain >= 0 && wall >= 0 && windows >= 0);

    const int houses = tw_tileset_add_prototype(ts, "houses", 1.0f);
    CHECK(add_houses(ts, houses, cube, red));
    const int field = tw_tileset_add_prototype(ts, "field", 1.0f);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)field, (uint32_t)terrain, (uint32_t)green, NULL) >= 0);
    const int facade = tw_tileset_add_prototype(ts, "facade", 1.0f);
    const float at[12] = {1, 0, 0, 10, 0, 1, 0, 0, 0, 0, 1, 20};
    CHECK(tw_tileset_add_instance(ts, (uint32_t)facade, (uint32_t)wall, (uint32_t)grey, at) >= 0);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)facade, (uint32_t)windows, (uint32_t)dark, at) >= 0);
    const int towers = tw_tileset_add_prototype(ts, "towers", 1.0f);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)towers, (uint32_t)small_terrain,
                                  (uint32_t)green, NULL) >= 0);
    for (int k = 0; k < 16; k++) {
        const float x = 4.0f + 9.0f * (float)(k % 4), z = 4.0f + 9.0f * (float)(k / 4);
        const float c = k % 2 ? 0.8f : 1.0f, s = k % 2 ? 0.6f : 0.0f;
        const float m[12] = {4 * c, 0, 4 * s, x, 0, 10.0f + (float)k, 0, 0, -4 * s, 0, 4 * c, z};
        CHECK(tw_tileset_add_instance(ts, (uint32_t)towers, (uint32_t)cube, (uint32_t)blue, m) >= 0);
    }
    const int lone = tw_tileset_add_prototype(ts, "lone", 1.0f);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)lone, (uint32_t)cube, (uint32_t)red, NULL) >= 0);
    CHECK(tw_tileset_finish(ts, CLUSTER) == TW_OK);
    return ts;
}

static bool box_near(const struct tw_box *a, const struct tw_box *b, float tolerance)
{
    for (int k = 0; k < 3; k++)
        if (fabsf(a->min[k] - b->min[k]) > tolerance || fabsf(a->max[k] - b->max[k]) > tolerance)
            return false;
    return true;
}

static bool box_inside(const struct tw_box *in, const struct tw_box *out)
{
    for (int a = 0; a < 3; a++)
        if (in->min[a] < out->min[a] || in->max[a] > out->max[a])
            return false;
    return true;
}

/* What a cell shows at max_error: the prototype (of ts or of its levels)
 * and its error. */
static const struct tw_prototype *chosen(const struct tw_tileset *ts, const struct tw_lods *l,
                                         uint32_t p, float max_error, float *error)
{
    const uint32_t level = tw_lods_pick(l, p, max_error);
    *error = level ? l->error[l->first[p] + level - 1] : 0.0f;
    return level ? &l->levels->prototypes[l->first[p] + level - 1] : &ts->prototypes[p];
}

/* The drawn triangles of prototype p of ts, baked (the instances that no
 * other draws): their number, and order-independent sums of their corners'
 * positions and colours. */
struct drawn_sums {
    uint64_t triangles;
    double position[3];
    double colour[4];
};

static struct drawn_sums drawn(const struct tw_tileset *ts, uint32_t p)
{
    struct drawn_sums s = {0};
    const struct tw_prototype *pr = &ts->prototypes[p];
    uint32_t *list = malloc(sizeof(*list) * pr->instance_count);
    uint64_t vertices = 0, triangles = 0;
    uint32_t count = 0;
    for (uint32_t k = 0; list && k < pr->instance_count; k++)
        if (pr->instances[k].merged_into == TW_INSTANCE_NONE) {
            list[count++] = k;
            vertices += ts->meshes[pr->instances[k].mesh].vertex_count;
            triangles += ts->meshes[pr->instances[k].mesh].triangle_count;
        }
    float *pos = malloc(sizeof(float) * 3 * vertices);
    float *nrm = malloc(sizeof(float) * 3 * vertices);
    uint8_t *rgba = malloc(4 * vertices);
    uint32_t *idx = malloc(sizeof(uint32_t) * 3 * triangles);
    CHECK(list && pos && nrm && rgba && idx);
    if (list && pos && nrm && rgba && idx) {
        uint32_t nv, nt;
        tw_tileset_bake(ts, p, list, count, pos, nrm, rgba, idx, &nv, &nt);
        s.triangles = nt;
        for (size_t k = 0; k < 3 * (size_t)nt; k++) {
            for (int a = 0; a < 3; a++)
                s.position[a] += pos[3 * (size_t)idx[k] + a];
            for (int c = 0; c < 4; c++)
                s.colour[c] += rgba[4 * (size_t)idx[k] + c];
        }
    }
    free(list);
    free(pos);
    free(nrm);
    free(rgba);
    free(idx);
    return s;
}

static bool sums_near(const struct drawn_sums *a, const struct drawn_sums *b)
{
    if (a->triangles != b->triangles)
        return false;
    for (int k = 0; k < 3; k++)
        if (fabs(a->position[k] - b->position[k]) > 1e-4 * (1.0 + fabs(a->position[k])))
            return false;
    for (int k = 0; k < 4; k++)
        if (a->colour[k] != b->colour[k])
            return false;
    return true;
}

/* 1: a block of one cell at no error is its prototype: the same triangles
 * drawn (merged instances neither lost nor drawn twice), the same box. At
 * a large error it is the prototype's coarsest level. */
static void test_one_cell(const struct tw_tileset *ts, const struct tw_lods *l)
{
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        struct tw_tileset *b = NULL;
        float e = -1.0f;
        CHECK(tw_hlod_block_build(ts, l, &p, 1, 0.0f, CLUSTER, &b, &e) == TW_OK);
        CHECK(b != NULL && e == 0.0f);
        if (!b)
            continue;
        const struct tw_prototype *src = &ts->prototypes[p], *blk = &b->prototypes[0];
        CHECK(b->prototype_count == 1 && b->finished);
        CHECK(b->footprint[0] == ts->footprint[0] && b->footprint[1] == ts->footprint[1]);
        CHECK_MSG(blk->triangle_count == src->triangle_count, "%s: %llu triangles, not %llu",
                  src->name, (unsigned long long)blk->triangle_count,
                  (unsigned long long)src->triangle_count);
        CHECK_MSG(memcmp(&blk->box, &src->box, sizeof(blk->box)) == 0, "%s: another box",
                  src->name);
        for (uint32_t c = 0; c < blk->cluster_count; c++)
            CHECK(blk->clusters[c].triangle_count <= CLUSTER);
        const struct drawn_sums x = drawn(ts, p), y = drawn(b, 0);
        CHECK_MSG(sums_near(&x, &y), "%s: another drawn set (%llu, %llu triangles)", src->name,
                  (unsigned long long)x.triangles, (unsigned long long)y.triangles);
        tw_tileset_destroy(b);

        /* The coarsest level. */
        CHECK(tw_hlod_block_build(ts, l, &p, 1, 1e9f, CLUSTER, &b, &e) == TW_OK && b);
        if (!b)
            continue;
        float expected_error;
        const struct tw_prototype *lv = chosen(ts, l, p, 1e9f, &expected_error);
        CHECK(l->count[p] == 0 || lv != src);
        CHECK_MSG(b->prototypes[0].triangle_count == lv->triangle_count &&
                      e == expected_error,
                  "%s coarsest: %llu triangles, error %g; level %llu, %g", src->name,
                  (unsigned long long)b->prototypes[0].triangle_count, e,
                  (unsigned long long)lv->triangle_count, expected_error);
        tw_tileset_destroy(b);
    }
}

/* 2 and 3: a 2 x 2 block is the sum of its cells' chosen levels, placed;
 * with an error between a prototype's first two levels, it takes the
 * first; empty cells add nothing. */
static void check_block(const struct tw_tileset *ts, const struct tw_lods *l,
                        const uint32_t protos[4], float max_error, const char *what)
{
    struct tw_tileset *b = NULL;
    float e = -1.0f;
    CHECK(tw_hlod_block_build(ts, l, protos, 2, max_error, CLUSTER, &b, &e) == TW_OK && b);
    if (!b)
        return;
    uint64_t triangles = 0;
    float largest = 0.0f;
    struct tw_box box = tw_box_empty();
    for (uint32_t c = 0; c < 4; c++) {
        if (protos[c] == TW_HLOD_EMPTY)
            continue;
        float error;
        const struct tw_prototype *pr = chosen(ts, l, protos[c], max_error, &error);
        triangles += pr->triangle_count;
        largest = fmaxf(largest, error);
        struct tw_box placed = pr->box;
        const float d[3] = {(float)(c % 2) * ts->footprint[0], 0.0f,
                            (float)(c / 2) * ts->footprint[1]};
        for (int a = 0; a < 3; a++) {
            placed.min[a] += d[a];
            placed.max[a] += d[a];
        }
        tw_box_add_box(&box, &placed);
    }
    const struct tw_prototype *blk = &b->prototypes[0];
    CHECK(b->prototype_count == 1);
    CHECK(b->footprint[0] == 2 * ts->footprint[0] && b->footprint[1] == 2 * ts->footprint[1]);
    CHECK_MSG(blk->triangle_count == triangles, "%s: %llu triangles, not %llu", what,
              (unsigned long long)blk->triangle_count, (unsigned long long)triangles);
    CHECK_MSG(box_near(&blk->box, &box, 1e-3f),
              "%s: box (%g %g %g)-(%g %g %g), not (%g %g %g)-(%g %g %g)", what, blk->box.min[0],
              blk->box.min[1], blk->box.min[2], blk->box.max[0], blk->box.max[1],
              blk->box.max[2], box.min[0], box.min[1], box.min[2], box.max[0], box.max[1],
              box.max[2]);
    CHECK_MSG(e == largest && (largest == 0.0f || e <= max_error),
              "%s: input error %g, expected %g at most %g", what, e, largest, max_error);
    tw_tileset_destroy(b);
}

static void test_blocks(const struct tw_tileset *ts, const struct tw_lods *l)
{
    /* Between the field's first and second levels: the first. */
    CHECK(l->count[1] >= 2);
    if (l->count[1] < 2)
        return;
    const float e1 = l->error[l->first[1]], e2 = l->error[l->first[1] + 1];
    CHECK(e2 > e1);
    const float between = 0.5f * (e1 + e2);
    CHECK(tw_lods_pick(l, 1, between) == 1);
    const uint32_t four[4] = {0, 1, 2, 3};
    check_block(ts, l, four, between, "2x2 between");
    check_block(ts, l, four, 0.0f, "2x2 full detail");
    check_block(ts, l, four, 1e9f, "2x2 coarsest");

    /* 3: empty cells. */
    const uint32_t two[4] = {0, TW_HLOD_EMPTY, TW_HLOD_EMPTY, 3};
    check_block(ts, l, two, between, "2x2 with two empty");
    const uint32_t one[4] = {TW_HLOD_EMPTY, TW_HLOD_EMPTY, TW_HLOD_EMPTY, 4};
    check_block(ts, l, one, between, "2x2 with three empty");
    const uint32_t none[4] = {TW_HLOD_EMPTY, TW_HLOD_EMPTY, TW_HLOD_EMPTY, TW_HLOD_EMPTY};
    struct tw_tileset *b = (struct tw_tileset *)1;
    float e = -1.0f;
    CHECK(tw_hlod_block_build(ts, l, none, 2, between, CLUSTER, &b, &e) == TW_OK);
    CHECK(b == NULL && e == 0.0f);

    /* Without levels: full detail. */
    struct tw_lods empty = {0};
    check_block(ts, &empty, four, 1e9f, "2x2 no levels");
    check_block(ts, NULL, four, 1e9f, "2x2 NULL levels");
}

/* The meshes of prototype p of ts that its instances given to the builder
 * use, or (merged) those that tw_tileset_finish() made. */
static uint32_t meshes_used(const struct tw_tileset *ts, uint32_t p, bool merged)
{
    uint32_t n = 0;
    const struct tw_prototype *pr = &ts->prototypes[p];
    for (uint32_t k = 0; k < pr->instance_count; k++) {
        if (pr->instances[k].merged != merged)
            continue;
        bool seen = false;
        for (uint32_t j = 0; j < k; j++)
            seen |= pr->instances[j].mesh == pr->instances[k].mesh;
        n += !seen;
    }
    return n;
}

/* 4: a 4 x 4 block of one prototype has that prototype's meshes, not 16
 * times them (houses: the cube; facade: wall and windows; a level: its
 * mesh), and at most one mesh of its own: the small instances of all its
 * cells merged by tw_tileset_finish(). */
static void test_shared_meshes(const struct tw_tileset *ts, const struct tw_lods *l)
{
    const struct {
        uint32_t proto;
        float max_error;
    } cases[] = {{0, 0.0f}, {2, 0.0f}, {3, 0.0f}, {1, 1e9f}, {3, 1e9f}};
    for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
        uint32_t protos[16];
        for (int k = 0; k < 16; k++)
            protos[k] = cases[c].proto;
        struct tw_tileset *b = NULL;
        float e;
        CHECK(tw_hlod_block_build(ts, l, protos, 4, cases[c].max_error, CLUSTER, &b, &e) == TW_OK &&
              b);
        if (!b)
            continue;
        const uint32_t level = tw_lods_pick(l, cases[c].proto, cases[c].max_error);
        const uint32_t expected =
            level ? meshes_used(l->levels, l->first[cases[c].proto] + level - 1, false)
                  : meshes_used(ts, cases[c].proto, false);
        const uint32_t copied = meshes_used(b, 0, false), merged = meshes_used(b, 0, true);
        CHECK_MSG(copied == expected && merged <= 1 && b->mesh_count == copied + merged,
                  "4x4 of %s at level %u: %u meshes copied, not %u, and %u merged",
                  ts->prototypes[cases[c].proto].name, level, copied, expected, merged);
        float error;
        CHECK(b->prototypes[0].triangle_count ==
              16 * chosen(ts, l, cases[c].proto, cases[c].max_error, &error)->triangle_count);
        tw_tileset_destroy(b);
    }
}

/* 5: the block's own levels, as the runtime builds them. */
static void test_block_levels(const struct tw_tileset *ts, const struct tw_lods *l)
{
    const uint32_t protos[4] = {0, 1, 2, 3};
    struct tw_tileset *b = NULL;
    float e;
    CHECK(tw_hlod_block_build(ts, l, protos, 2, 0.2f, CLUSTER, &b, &e) == TW_OK && b);
    if (!b)
        return;
    struct tw_lods bl;
    CHECK(tw_lods_build(b, CLUSTER, NULL, NULL, &bl) == TW_OK);
    CHECK(bl.levels != NULL && bl.source_count == 1 && bl.count[0] >= 2);
    float previous = 0.0f;
    uint64_t triangles = b->prototypes[0].triangle_count;
    for (uint32_t k = 0; bl.levels && k < bl.count[0]; k++) {
        const struct tw_prototype *lv = &bl.levels->prototypes[bl.first[0] + k];
        const float err = bl.error[bl.first[0] + k];
        CHECK_MSG(err >= previous && isfinite(err), "block level %u: error %g after %g", k + 1,
                  err, previous);
        CHECK_MSG(lv->triangle_count < triangles, "block level %u: %llu triangles after %llu",
                  k + 1, (unsigned long long)lv->triangle_count, (unsigned long long)triangles);
        CHECK(box_inside(&lv->box, &b->prototypes[0].box));
        previous = err;
        triangles = lv->triangle_count;
    }
    tw_lods_free(&bl);
    tw_tileset_destroy(b);
}

/* 5b: a proxy's levels from its cells' coarser levels: each level is the
 * block tw_hlod_block_build() makes of the same cells at a larger error
 * (the same triangles), fewer triangles than the level before, its error
 * beyond the base the largest of its cells' levels' less the base; a stop
 * set gives TW_ERR_STATE and nothing; no cell coarser (the base past every
 * level), no levels. */
static void test_levels_from_cells(const struct tw_tileset *ts, const struct tw_lods *l)
{
    const uint32_t protos[4] = {0, 1, 2, 3};
    const float base = 0.2f;
    struct tw_lods bl;
    CHECK(tw_hlod_block_levels(ts, l, protos, 2, base, CLUSTER, NULL, &bl) == TW_OK);
    CHECK(bl.levels != NULL && bl.source_count == 1 && bl.first[0] == 0 && bl.count[0] >= 2 &&
          bl.count[0] <= TW_LOD_MAX_LEVELS);
    struct tw_tileset *b0 = NULL;
    float e0;
    CHECK(tw_hlod_block_build(ts, l, protos, 2, base, CLUSTER, &b0, &e0) == TW_OK && b0);
    uint64_t triangles = b0 ? b0->prototypes[0].triangle_count : 0;
    float previous = 0.0f;
    for (uint32_t k = 0; bl.levels && k < bl.count[0]; k++) {
        const struct tw_prototype *lv = &bl.levels->prototypes[k];
        const float err = bl.error[k];
        CHECK_MSG(err > 0.0f && err >= previous, "level %u: error %g after %g", k + 1, err,
                  previous);
        CHECK_MSG((double)lv->triangle_count <= TW_LOD_KEEP_RATIO * (double)triangles,
                  "level %u: %llu triangles after %llu", k + 1,
                  (unsigned long long)lv->triangle_count, (unsigned long long)triangles);
        /* The same cells at the level's error, merged: the same triangles,
         * and the largest of their errors is what the level says. */
        struct tw_tileset *same = NULL;
        float e;
        CHECK(tw_hlod_block_build(ts, l, protos, 2, base + err, CLUSTER, &same, &e) == TW_OK &&
              same);
        if (same) {
            CHECK_MSG(same->prototypes[0].triangle_count == lv->triangle_count,
                      "level %u: %llu triangles, the block at %g m has %llu", k + 1,
                      (unsigned long long)lv->triangle_count, (double)(base + err),
                      (unsigned long long)same->prototypes[0].triangle_count);
            CHECK_MSG(fabsf(e - (base + err)) <= 1e-4f * (1.0f + e) || err == previous,
                      "level %u: error %g beyond %g, its cells' %g", k + 1, err, base, e);
        }
        tw_tileset_destroy(same);
        previous = err;
        triangles = lv->triangle_count;
    }
    tw_lods_free(&bl);
    tw_tileset_destroy(b0);
    atomic_bool stop = true;
    CHECK(tw_hlod_block_levels(ts, l, protos, 2, base, CLUSTER, &stop, &bl) == TW_ERR_STATE &&
          bl.levels == NULL);
    CHECK(tw_hlod_block_levels(ts, l, protos, 2, 1e9f, CLUSTER, NULL, &bl) == TW_OK &&
          bl.levels == NULL);
    CHECK(tw_hlod_block_levels(ts, NULL, protos, 2, base, CLUSTER, NULL, &bl) == TW_OK &&
          bl.levels == NULL);
    CHECK(tw_hlod_block_levels(ts, l, protos, 0, base, CLUSTER, NULL, &bl) == TW_ERR_INVALID);
}

/* 6: bad input. */
static void test_refused(const struct tw_tileset *ts, const struct tw_lods *l)
{
    const uint32_t protos[4] = {0, 1, 2, 3};
    struct tw_tileset *b = (struct tw_tileset *)1;
    float e = -1.0f;
    CHECK(tw_hlod_block_build(ts, l, protos, 0, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    CHECK(b == NULL && e == 0.0f);
    CHECK(tw_hlod_block_build(ts, l, NULL, 2, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    CHECK(tw_hlod_block_build(NULL, l, protos, 2, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    CHECK(tw_hlod_block_build(ts, l, protos, 2, 1.0f, CLUSTER, NULL, &e) == TW_ERR_INVALID);
    CHECK(tw_hlod_block_build(ts, l, protos, 2, 1.0f, CLUSTER, &b, NULL) == TW_ERR_INVALID);
    const uint32_t out_of_range[4] = {0, 1, ts->prototype_count, 3};
    b = (struct tw_tileset *)1;
    CHECK(tw_hlod_block_build(ts, l, out_of_range, 2, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    CHECK(b == NULL);
    /* Levels of another tileset (another number of prototypes). */
    struct tw_lods other = *l;
    other.source_count = ts->prototype_count + 1;
    CHECK(tw_hlod_block_build(ts, &other, protos, 2, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    /* Unfinished. */
    struct tw_tileset *raw = NULL;
    CHECK(tw_tileset_create("raw", 40, 40, &raw) == TW_OK);
    CHECK(tw_hlod_block_build(raw, NULL, protos, 1, 1.0f, CLUSTER, &b, &e) == TW_ERR_INVALID);
    tw_tileset_destroy(raw);
    /* A block too wide to lie within reach of its origin. */
    uint32_t *far = malloc(sizeof(*far) * 3000u * 3000u);
    if (far) {
        for (uint32_t c = 0; c < 3000u * 3000u; c++)
            far[c] = TW_HLOD_EMPTY;
        far[3000u * 3000u - 1] = 4;
        const int err = tw_hlod_block_build(ts, l, far, 3000, 1.0f, CLUSTER, &b, &e);
        CHECK_MSG(err == TW_ERR_LIMIT && b == NULL, "a cell 120 km out: %s",
                  tw_error_to_str(err));
        free(far);
    }
}

/* 7: the same inputs, the same block. */
static void test_deterministic(const struct tw_tileset *ts, const struct tw_lods *l)
{
    const uint32_t protos[9] = {0, 1, 2, 3, 4, 3, 2, 1, 0};
    struct tw_tileset *a = NULL, *b = NULL;
    float ea, eb;
    CHECK(tw_hlod_block_build(ts, l, protos, 3, 0.3f, CLUSTER, &a, &ea) == TW_OK && a);
    CHECK(tw_hlod_block_build(ts, l, protos, 3, 0.3f, CLUSTER, &b, &eb) == TW_OK && b);
    if (a && b) {
        bool same = ea == eb && a->mesh_count == b->mesh_count &&
                    a->material_count == b->material_count &&
                    a->prototypes[0].instance_count == b->prototypes[0].instance_count &&
                    a->prototypes[0].cluster_count == b->prototypes[0].cluster_count &&
                    tw_tileset_bytes(a) == tw_tileset_bytes(b);
        for (uint32_t k = 0; same && k < a->mesh_count; k++) {
            const struct tw_mesh *x = &a->meshes[k], *y = &b->meshes[k];
            same = x->vertex_count == y->vertex_count && x->triangle_count == y->triangle_count &&
                   memcmp(x->positions, y->positions, sizeof(float) * 3 * x->vertex_count) == 0 &&
                   memcmp(x->indices, y->indices, sizeof(uint32_t) * 3 * x->triangle_count) == 0 &&
                   (x->colors != NULL) == (y->colors != NULL) &&
                   (!x->colors || memcmp(x->colors, y->colors, 4 * (size_t)x->vertex_count) == 0);
        }
        for (uint32_t k = 0; same && k < a->prototypes[0].instance_count; k++) {
            const struct tw_instance *x = &a->prototypes[0].instances[k],
                                     *y = &b->prototypes[0].instances[k];
            same = memcmp(x, y, sizeof(*x)) == 0;
        }
        CHECK_MSG(same, "two builds of one block differ");
    }
    tw_tileset_destroy(a);
    tw_tileset_destroy(b);
}

/* 8: printed, not checked: blocks of side 2 to 16 with an error that grows
 * as side (0.6 m a cell), and what tw_lods_build makes of each (the
 * triangles and error of every level; the level that error picks). A proxy
 * that stands for 4 times the cells at twice the error should cost about as
 * many triangles. */
static void print_blocks(const struct tw_tileset *ts, const struct tw_lods *l)
{
    uint64_t full = 0;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        full += ts->prototypes[p].triangle_count;
    printf("%s: %u prototypes of %.0f triangles on average, %.0f x %.0f m\n", ts->name,
           ts->prototype_count, (double)full / ts->prototype_count, ts->footprint[0],
           ts->footprint[1]);
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        printf("  %-12.12s %7llu", ts->prototypes[p].name,
               (unsigned long long)ts->prototypes[p].triangle_count);
        for (uint32_t k = 0; l->levels && k < l->count[p]; k++)
            printf(" %llu@%.2f",
                   (unsigned long long)l->levels->prototypes[l->first[p] + k].triangle_count,
                   l->error[l->first[p] + k]);
        printf("\n");
    }
    printf("side max_err input_err input_tris build_ms levels_ms picked  "
           "| block levels: triangles@error\n");
    int err = TW_OK;
    for (uint32_t side = 2; side <= 16 && !err; side *= 2) {
        const float max_error = 0.6f * (float)side;
        uint32_t *protos = malloc(sizeof(*protos) * side * side);
        CHECK(protos != NULL);
        if (!protos)
            break;
        const struct tw_selection sel = {.seed = 1};
        for (uint32_t z = 0; z < side; z++)
            for (uint32_t x = 0; x < side; x++)
                protos[z * side + x] =
                    tw_tiles_select(ts, &sel, (struct tw_cell){(int64_t)x, (int64_t)z});
        struct tw_tileset *b = NULL;
        float e = 0.0f;
        double t0 = tw_clock_monotonic_ms();
        err = tw_hlod_block_build(ts, l, protos, side, max_error, CLUSTER, &b, &e);
        const double build_ms = tw_clock_monotonic_ms() - t0;
        free(protos);
        CHECK_MSG(err == TW_OK && b, "%s block %u: %s", ts->name, side, tw_error_to_str(err));
        if (!b)
            break;
        struct tw_lods bl;
        t0 = tw_clock_monotonic_ms();
        err = tw_lods_build(b, CLUSTER, NULL, NULL, &bl);
        const double levels_ms = tw_clock_monotonic_ms() - t0;
        CHECK_MSG(err == TW_OK, "%s block %u levels: %s", ts->name, side, tw_error_to_str(err));
        const uint32_t pick = tw_lods_pick(&bl, 0, max_error);
        const uint64_t picked = pick ? bl.levels->prototypes[bl.first[0] + pick - 1].triangle_count
                                     : b->prototypes[0].triangle_count;
        printf("%4u %7.1f %9.2f %10llu %8.1f %9.1f %6llu  |", side, max_error, e,
               (unsigned long long)b->prototypes[0].triangle_count, build_ms, levels_ms,
               (unsigned long long)picked);
        for (uint32_t k = 0; !err && bl.levels && k < bl.count[0]; k++)
            printf(" %llu@%.2f",
                   (unsigned long long)bl.levels->prototypes[bl.first[0] + k].triangle_count,
                   bl.error[bl.first[0] + k]);
        printf("\n");
        tw_lods_free(&bl);
        tw_tileset_destroy(b);
    }
}

/* The figures of the built-in city (`test-hlod city`): its 16 x 16 block
 * holds millions of triangles, and simplifying it takes about half a
 * minute on one core, too long for the unit suite. */
static void print_city(void)
{
    struct tw_tileset *city = NULL;
    int err = tw_tilesets_builtin("city", 1, CLUSTER, NULL, &city);
    CHECK_MSG(err == TW_OK && city, "city: %s", tw_error_to_str(err));
    if (!city)
        return;
    struct tw_lods l;
    err = tw_lods_build(city, CLUSTER, NULL, NULL, &l);
    CHECK_MSG(err == TW_OK, "city levels: %s", tw_error_to_str(err));
    if (!err)
        print_blocks(city, &l);
    tw_lods_free(&l);
    tw_tileset_destroy(city);
}

/* 9: whether a level pays: 4^level cells of the heaviest prototype at its
 * level for the error, against TW_HLOD_MAX_INPUT; no overflow far up. */
static void test_level_pays(const struct tw_tileset *ts, const struct tw_lods *l)
{
    uint64_t heaviest = 0;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        if (ts->prototypes[p].triangle_count > heaviest)
            heaviest = ts->prototypes[p].triangle_count;
    uint64_t input = 0;
    /* No error allowed: every cell at full detail. */
    const bool pays = tw_hlod_level_pays(ts, l, 1, 0.0f, &input);
    CHECK(input == 4 * heaviest && pays == (input <= TW_HLOD_MAX_INPUT));
    CHECK(tw_hlod_level_pays(ts, NULL, 1, 1000.0f, &input) && input == 4 * heaviest);
    /* A large error picks each prototype's coarsest level: fewer. */
    uint64_t coarse = 0;
    tw_hlod_level_pays(ts, l, 1, 1e6f, &coarse);
    CHECK(coarse < input);
    CHECK(!tw_hlod_level_pays(ts, l, 12, 0.0f, &input) && input == heaviest << 24);
    CHECK(!tw_hlod_level_pays(ts, l, 40, 0.0f, &input) && input == UINT64_MAX);
    /* A 4x4 block of 80 x 60 m cells, 16 px across: 1 px is 20 m. */
    CHECK(tw_hlod_level_error((const float[2]){80.0f, 60.0f}, 2, 1.0f, 16.0f) == 20.0f);
    CHECK(tw_hlod_level_error((const float[2]){60.0f, 80.0f}, 2, 2.0f, 16.0f) == 40.0f);
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "city") == 0) {
        print_city();
        return check_summary("test-hlod");
    }
    struct tw_tileset *ts = make_tileset();
    if (!ts)
        return check_summary("test-hlod");
    /* The houses are drawn by a merged mesh: the case to get right. */
    bool merged = false;
    for (uint32_t k = 0; k < ts->prototypes[0].instance_count; k++)
        merged |= ts->prototypes[0].instances[k].merged;
    CHECK(merged);
    struct tw_lods l;
    CHECK(tw_lods_build(ts, CLUSTER, NULL, NULL, &l) == TW_OK);
    CHECK(l.levels != NULL && l.count[4] == 0);
    if (l.levels) {
        test_one_cell(ts, &l);
        test_blocks(ts, &l);
        test_shared_meshes(ts, &l);
        test_block_levels(ts, &l);
        test_levels_from_cells(ts, &l);
        test_refused(ts, &l);
        test_deterministic(ts, &l);
        test_level_pays(ts, &l);
        print_blocks(ts, &l);
    }
    tw_lods_free(&l);
    tw_tileset_destroy(ts);
    return check_summary("test-hlod");
}
