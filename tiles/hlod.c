/* Hierarchical levels of detail (tiles-internal.h): the proxy of a block of
 * cells, each cell's prototype at a coarse level, gathered into one
 * prototype of one tileset for tw_lods_build() to simplify as a whole. */
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* What a source tileset (ts, or its levels) has already given the block:
 * the block's index of each of its meshes and materials, UINT32_MAX where
 * none yet, so that a mesh shown by many cells is copied once. */
struct source {
    const struct tw_tileset *ts;
    uint32_t *mesh;
    uint32_t *material;
};

static int source_init(struct source *s, const struct tw_tileset *ts)
{
    s->ts = ts;
    s->mesh = malloc(sizeof(*s->mesh) * (ts->mesh_count ? ts->mesh_count : 1));
    s->material = malloc(sizeof(*s->material) * (ts->material_count ? ts->material_count : 1));
    if (!s->mesh || !s->material)
        return TW_ERR_NOMEM;
    memset(s->mesh, 0xff, sizeof(*s->mesh) * ts->mesh_count);
    memset(s->material, 0xff, sizeof(*s->material) * ts->material_count);
    return TW_OK;
}

static void source_free(struct source *s)
{
    free(s->mesh);
    free(s->material);
}

/* What one cell shows: prototype proto of tileset ts (ts itself, or its
 * levels), with that level's error. */
struct shown {
    const struct tw_tileset *ts;
    uint32_t proto;
    float error;
};

static struct shown shown_at(const struct tw_tileset *ts, const struct tw_lods *lods, uint32_t p,
                             float max_input_error)
{
    const uint32_t level = tw_lods_pick(lods, p, max_input_error);
    if (level == 0)
        return (struct shown){ts, p, 0.0f};
    const uint32_t k = lods->first[p] + level - 1;
    return (struct shown){lods->levels, k, lods->error[k]};
}

/* Whether instance in is copied into the block. tw_tileset_finish() leaves
 * in a prototype both the instances it was given and, for its small ones,
 * a `merged` identity instance of a baked mesh that draws them (those are
 * marked merged_into). The block copies the instances it was given, every
 * one, and none of the merged ones: the originals are exactly the drawn
 * triangles (a merged mesh is a bake of its originals, nothing more), they
 * share their meshes between cells (a merged mesh is per prototype), and
 * the block's own tw_tileset_finish() merges them again, block-wide, as
 * it expects to: an unfinished tileset of plain instances. Copying the
 * merged meshes instead would bake baked meshes again, and would run the
 * dropping of triangles without area over tile-local triangles that were
 * never checked so. An instance whose mesh lost every triangle to that
 * dropping draws nothing (and a mesh needs a triangle to be added). */
static bool copied(const struct tw_tileset *ts, const struct tw_instance *in)
{
    return !in->merged && ts->meshes[in->mesh].triangle_count > 0;
}

/* The block's index of source mesh k, copied (colours too) the first time. */
static int block_mesh(struct tw_tileset *block, struct source *s, uint32_t k)
{
    if (s->mesh[k] != UINT32_MAX)
        return (int)s->mesh[k];
    const struct tw_mesh *m = &s->ts->meshes[k];
    const int mesh = tw_tileset_add_mesh(block, m->positions, m->normals, m->vertex_count,
                                         m->indices, m->triangle_count);
    if (mesh < 0)
        return mesh;
    if (m->colors) {
        uint8_t *rgba = malloc(4 * (size_t)m->vertex_count);
        if (!rgba)
            return TW_ERR_NOMEM;
        memcpy(rgba, m->colors, 4 * (size_t)m->vertex_count);
        block->meshes[mesh].colors = rgba;     /* the block's now */
    }
    s->mesh[k] = (uint32_t)mesh;
    return mesh;
}

/* The block's index of source material k, copied the first time. */
static int block_material(struct tw_tileset *block, struct source *s, uint32_t k)
{
    if (s->material[k] != UINT32_MAX)
        return (int)s->material[k];
    const int material = tw_tileset_add_material(block, s->ts->materials[k].base_color);
    if (material >= 0)
        s->material[k] = (uint32_t)material;
    return material;
}

/* Copies the instances of prototype shown of s into prototype proto of the
 * block, moved by (dx, 0, dz). */
static int add_cell(struct tw_tileset *block, uint32_t proto, struct source *s, uint32_t shown,
                    float dx, float dz)
{
    const struct tw_prototype *pr = &s->ts->prototypes[shown];
    for (uint32_t k = 0; k < pr->instance_count; k++) {
        const struct tw_instance *in = &pr->instances[k];
        if (!copied(s->ts, in))
            continue;
        const int mesh = block_mesh(block, s, in->mesh);
        if (mesh < 0)
            return mesh;
        const int material = block_material(block, s, in->material);
        if (material < 0)
            return material;
        float transform[12];
        memcpy(transform, in->transform, sizeof(transform));
        transform[3] += dx;
        transform[11] += dz;
        const int added =
            tw_tileset_add_instance(block, proto, (uint32_t)mesh, (uint32_t)material, transform);
        if (added < 0)
            return added;
    }
    return TW_OK;
}

/* What the block holds, counted before anything is built: its baked whole
 * (what tw_lods_build() makes of it) must fit 32-bit counts. */
static int count_block(const struct tw_tileset *ts, const struct tw_lods *lods,
                       const uint32_t *protos, uint32_t side, float max_input_error,
                       uint64_t *triangles_out, float *largest_out)
{
    if ((uint64_t)side * side > UINT32_MAX)
        return TW_ERR_LIMIT;
    /* Levels of another tileset would name other prototypes. */
    if (lods && lods->levels && lods->source_count != ts->prototype_count)
        return TW_ERR_INVALID;
    const uint32_t cells = side * side;
    uint64_t vertices = 0, triangles = 0, instances = 0;
    float largest_error = 0.0f;
    for (uint32_t c = 0; c < cells; c++) {
        if (protos[c] == TW_HLOD_EMPTY)
            continue;
        if (protos[c] >= ts->prototype_count)
            return TW_ERR_INVALID;
        const struct shown sh = shown_at(ts, lods, protos[c], max_input_error);
        if (sh.error > largest_error)
            largest_error = sh.error;
        const struct tw_prototype *pr = &sh.ts->prototypes[sh.proto];
        for (uint32_t k = 0; k < pr->instance_count; k++) {
            const struct tw_instance *in = &pr->instances[k];
            if (!copied(sh.ts, in))
                continue;
            vertices += sh.ts->meshes[in->mesh].vertex_count;
            triangles += sh.ts->meshes[in->mesh].triangle_count;
            instances++;
        }
    }
    if (vertices > UINT32_MAX || triangles > UINT32_MAX / 3 || instances >= TW_INSTANCE_NONE)
        return TW_ERR_LIMIT;
    *triangles_out = triangles;
    *largest_out = largest_error;
    return TW_OK;
}

/* Adds the block's prototype to block, counted already (count_block):
 * the cells' chosen prototypes, moved to their places. */
static int fill(const struct tw_tileset *ts, const struct tw_lods *lods, const uint32_t *protos,
                uint32_t side, float max_input_error, struct tw_tileset *block)
{
    struct source full = {0}, coarse = {0};
    int err = source_init(&full, ts);
    if (!err && lods && lods->levels)
        err = source_init(&coarse, lods->levels);
    /* Small instances merged as the source merges its own. */
    block->merge_triangles = ts->merge_triangles;
    char name[64];
    snprintf(name, sizeof(name), "block%ux%u", side, side);
    const int proto = err ? err : tw_tileset_add_prototype(block, name, 1.0f);
    if (proto < 0)
        err = proto;
    /* Cells in a fixed order, row by row: the same inputs, the same block. */
    for (uint32_t z = 0; z < side && !err; z++)
        for (uint32_t x = 0; x < side && !err; x++) {
            const uint32_t p = protos[z * side + x];
            if (p == TW_HLOD_EMPTY)
                continue;
            const struct shown sh = shown_at(ts, lods, p, max_input_error);
            /* The offset in double, rounded once, like tw_tiles_cell_offset(). */
            const float dx = (float)((double)x * ts->footprint[0]);
            const float dz = (float)((double)z * ts->footprint[1]);
            err = add_cell(block, (uint32_t)proto, sh.ts == ts ? &full : &coarse, sh.proto, dx,
                           dz);
        }
    source_free(&full);
    source_free(&coarse);
    return err;
}

int tw_hlod_block_fill(const struct tw_tileset *ts, const struct tw_lods *lods,
                       const uint32_t *protos, uint32_t side, float max_input_error,
                       struct tw_tileset *block, float *input_error)
{
    if (input_error)
        *input_error = 0.0f;
    if (!ts || !protos || !block || !input_error || side == 0 || !ts->finished ||
        block->finished || block->prototype_count != 0 ||
        block->footprint[0] != (float)side * ts->footprint[0] ||
        block->footprint[1] != (float)side * ts->footprint[1])
        return TW_ERR_INVALID;
    uint64_t triangles;
    float largest_error;
    int err = count_block(ts, lods, protos, side, max_input_error, &triangles, &largest_error);
    if (!err)
        err = fill(ts, lods, protos, side, max_input_error, block);
    if (!err)
        *input_error = largest_error;
    return err;
}

int tw_hlod_block_build(const struct tw_tileset *ts, const struct tw_lods *lods,
                        const uint32_t *protos, uint32_t side, float max_input_error,
                        uint32_t max_cluster_triangles, struct tw_tileset **out,
                        float *input_error)
{
    if (out)
        *out = NULL;
    if (input_error)
        *input_error = 0.0f;
    if (!ts || !protos || !out || !input_error || side == 0 || !ts->finished)
        return TW_ERR_INVALID;
    uint64_t triangles;
    float largest_error;
    int err = count_block(ts, lods, protos, side, max_input_error, &triangles, &largest_error);
    if (err)
        return err;
    if (triangles == 0)
        return TW_OK;   /* all empty: nothing to stand for */
    struct tw_tileset *block = NULL;
    char name[64];
    snprintf(name, sizeof(name), "%.40s/block%u", ts->name, side);
    err = tw_tileset_create(name, (float)side * ts->footprint[0], (float)side * ts->footprint[1],
                            &block);
    if (!err)
        err = fill(ts, lods, protos, side, max_input_error, block);
    if (!err)
        err = tw_tileset_finish(block, max_cluster_triangles);
    if (!err)
        err = tw_tileset_pack(&block);
    if (err) {
        tw_tileset_destroy(block);
        return err;
    }
    *out = block;
    *input_error = largest_error;
    return TW_OK;
}

bool tw_hlod_level_pays(const struct tw_tileset *ts, const struct tw_lods *lods, uint32_t level,
                        float error, uint64_t *input_triangles)
{
    uint64_t heaviest = 0;
    for (uint32_t q = 0; q < ts->prototype_count; q++) {
        const uint32_t at = lods && lods->levels ? tw_lods_pick(lods, q, error) : 0;
        const uint64_t t =
            at == 0 ? ts->prototypes[q].triangle_count
                    : lods->levels->prototypes[lods->first[q] + at - 1].triangle_count;
        heaviest = t > heaviest ? t : heaviest;
    }
    const uint64_t input = level < 31 && heaviest <= (UINT64_MAX >> (2 * level))
                               ? heaviest << (2 * level)
                               : UINT64_MAX;
    if (input_triangles)
        *input_triangles = input;
    return input <= TW_HLOD_MAX_INPUT;
}

float tw_hlod_level_error(const float footprint[2], uint32_t level, float max_screen_error,
                          float block_px)
{
    const double cell = footprint[0] > footprint[1] ? footprint[0] : footprint[1];
    return (float)((double)((uint64_t)1 << level) * cell * max_screen_error / block_px);
}

/* The largest error of any level the block's cells have: past it, every
 * cell is at its coarsest. */
static float block_ceiling(const struct tw_lods *lods, const uint32_t *protos, uint32_t side)
{
    float ceiling = 0.0f;
    for (uint32_t c = 0; c < side * side; c++) {
        const uint32_t p = protos[c];
        if (p == TW_HLOD_EMPTY || lods->count[p] == 0)
            continue;
        const float e = lods->error[lods->first[p] + lods->count[p] - 1];
        ceiling = e > ceiling ? e : ceiling;
    }
    return ceiling;
}

int tw_hlod_block_levels(const struct tw_tileset *ts, const struct tw_lods *lods,
                         const uint32_t *protos, uint32_t side, float base_error,
                         uint32_t max_cluster_triangles, const atomic_bool *stop,
                         struct tw_lods *out)
{
    if (out)
        memset(out, 0, sizeof(*out));
    if (!ts || !protos || !out || side == 0 || !ts->finished || !(base_error >= 0.0f))
        return TW_ERR_INVALID;
    if (!lods || !lods->levels)
        return TW_OK;   /* the cells have no coarser levels to give */
    uint64_t previous;
    float largest;
    int err = count_block(ts, lods, protos, side, base_error, &previous, &largest);
    if (err || previous == 0)
        return err;
    const float ceiling = block_ceiling(lods, protos, side);
    struct tw_tileset *levels = NULL;
    char name[64];
    snprintf(name, sizeof(name), "%.40s/block%u levels", ts->name, side);
    err = tw_tileset_create(name, (float)side * ts->footprint[0], (float)side * ts->footprint[1],
                            &levels);
    float errors[TW_LOD_MAX_LEVELS];
    uint32_t n = 0;
    float at = base_error;
    while (!err && n < TW_LOD_MAX_LEVELS && at < ceiling) {
        if (stop && atomic_load_explicit(stop, memory_order_relaxed)) {
            err = TW_ERR_STATE;
            break;
        }
        at = at > 0.0f ? at * 1.41421356f : ceiling;
        if (at > ceiling)
            at = ceiling;
        uint64_t triangles;
        err = count_block(ts, lods, protos, side, at, &triangles, &largest);
        /* A level that saves little costs memory and a BVH for nothing. */
        if (err || (double)triangles > TW_LOD_KEEP_RATIO * (double)previous)
            continue;
        err = fill(ts, lods, protos, side, at, levels);
        if (err)
            break;
        /* Beyond the block's own (base_error): what the selection adds it
         * to, never less than the level before's. */
        const float beyond = largest - base_error;
        errors[n] = n > 0 && errors[n - 1] > beyond ? errors[n - 1] : beyond;
        n++;
        previous = triangles;
    }
    if (!err && n > 0)
        err = tw_tileset_finish(levels, max_cluster_triangles);
    if (!err && n > 0)
        err = tw_tileset_pack(&levels);
    if (!err && n > 0) {
        out->first = calloc(1, sizeof(*out->first));
        out->count = malloc(sizeof(*out->count));
        out->error = malloc(sizeof(*out->error) * n);
        if (!out->first || !out->count || !out->error)
            err = TW_ERR_NOMEM;
    }
    if (err || n == 0) {
        tw_tileset_destroy(levels);
        tw_lods_free(out);
        return err;
    }
    out->levels = levels;
    out->source_count = 1;
    out->count[0] = n;
    memcpy(out->error, errors, sizeof(*errors) * n);
    return TW_OK;
}
