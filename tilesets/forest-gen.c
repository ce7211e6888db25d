/* forest-gen: a tile provider whose every cell is a forest stand of its own
 * (tilesets.h, DESIGN.md §10, §12).
 *
 * A cell's tile is what one prototype of the forest tileset is: the floor,
 * the trail along every border and one stand over the whole tile, made by
 * the forest's stand generator (forest-layout.c). From the cell's hash come
 * the stand's kind (in the shares that selection gives the forest's default
 * prototypes), its species mix (the kind's, each weight varied and now and
 * then one species brought forward), its tree count and every placement.
 * The tree count is scaled by the kind's expected triangles per tree over
 * the cell's, so that a mix of heavier species brings fewer trees and the
 * triangle density stays the forest's.
 *
 * The meshes (species x sizes, rocks, a log, undergrowth patches) come
 * from a few template sets drawn from the seed when the provider is made;
 * a cell copies the meshes of its set that it places into its own tileset
 * (a generated tile can only instance its own meshes). The templates are never written after
 * creation, so generate() may run on any number of threads; its generator
 * lives on the heap of the call. */
#include "tiles/tiles-internal.h"
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

enum { TEMPLATE_COUNT = 4 };

struct forest_template {
    struct tw_tileset *ts;              /* holds the meshes; never finished */
    struct tw_forest_stands *stands;
};

struct forest_gen {
    struct tw_tilesets_provider base;
    uint64_t seed;
    struct tw_forest_settings settings; /* resolved */
    struct tw_log log;
    struct forest_template templates[TEMPLATE_COUNT];
    float base_tree_triangles[TEMPLATE_COUNT][TW_FOREST_STAND_KIND_COUNT];
};

/* The forest tileset's ten default prototypes as selection weighs them
 * (tw_tilesets_forest()): two each of spruce, mixed and beech, one thin and
 * one birch stand of weight 1, a clearing of 0.5 and a rocky stand of 0.7. */
static const float kind_shares[TW_FOREST_STAND_KIND_COUNT] = {
    [TW_FOREST_STAND_SPRUCE] = 2.0f, [TW_FOREST_STAND_MIXED] = 2.0f,
    [TW_FOREST_STAND_BEECH] = 2.0f,  [TW_FOREST_STAND_BIRCH] = 1.0f,
    [TW_FOREST_STAND_THIN] = 1.0f,   [TW_FOREST_STAND_CLEARING] = 0.5f,
    [TW_FOREST_STAND_ROCKY] = 0.7f,
};

static enum tw_forest_stand_kind pick_kind(struct tw_rng *r)
{
    float total = 0.0f;
    for (int k = 0; k < TW_FOREST_STAND_KIND_COUNT; k++)
        total += kind_shares[k];
    float x = tw_rng_float(r) * total;
    for (int k = 0; k + 1 < TW_FOREST_STAND_KIND_COUNT; k++) {
        if (x < kind_shares[k])
            return (enum tw_forest_stand_kind)k;
        x -= kind_shares[k];
    }
    return (enum tw_forest_stand_kind)(TW_FOREST_STAND_KIND_COUNT - 1);
}

/* The kind's species mix, every weight scaled by 0.4 to 1.6 and, in three
 * cells of ten, one species that the kind has brought forward 2.5 times:
 * species the kind lacks stay out. */
static void vary_mix(struct tw_rng *r, enum tw_forest_stand_kind kind,
                     float mix[TW_FOREST_SPECIES_COUNT])
{
    tw_forest_stand_mix(kind, mix);
    for (int s = 0; s < TW_FOREST_SPECIES_COUNT; s++)
        mix[s] *= tw_rng_range(r, 0.4f, 1.6f);
    if (tw_rng_chance(r, 0.3f)) {
        const uint32_t s = tw_rng_below(r, TW_FOREST_SPECIES_COUNT);
        mix[s] *= 2.5f;
    }
}

static int forest_gen_generate(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    const struct forest_gen *g = user;
    int err = tw_provider_check_tile(&g->base.provider, &g->log, cell, ts);
    if (err)
        return err;
    struct tw_rng r = {tw_tiles_hash(g->seed, cell.i, cell.j)};
    const uint32_t variant = tw_rng_below(&r, TEMPLATE_COUNT);
    const enum tw_forest_stand_kind kind = pick_kind(&r);
    float mix[TW_FOREST_SPECIES_COUNT];
    vary_mix(&r, kind, mix);
    const uint64_t stream = tw_rng_next(&r);

    struct tw_forest_stands *stands = NULL;
    if ((err = tw_forest_stands_create_from(g->templates[variant].stands, ts, &stands)))
        goto out;
    char name[48];
    snprintf(name, sizeof(name), "%s %lld,%lld", tw_forest_stand_name(kind), (long long)cell.i,
             (long long)cell.j);
    const int proto = tw_tileset_add_prototype(ts, name, 1.0f);
    if (proto < 0) {
        err = proto;
        goto out;
    }
    if ((err = tw_forest_stands_add_floor(stands, (uint32_t)proto, g->settings.path_clearance)))
        goto out;
    const float footprint = g->settings.footprint;
    const struct tw_forest_area area = {
        {0.0f, 0.0f, footprint, footprint}, 0.0f, g->settings.path_clearance};
    const float per_tree = tw_forest_stands_tree_triangles(stands, kind, mix);
    const float tree_scale = per_tree > 0.0f ? g->base_tree_triangles[variant][kind] / per_tree
                                             : 1.0f;
    err = tw_forest_stands_add_varied(stands, (uint32_t)proto, kind, stream, &area, mix,
                                      tree_scale);
out:
    tw_forest_stands_destroy(stands);
    return err;
}

static void forest_gen_destroy(struct tw_tilesets_provider *p)
{
    struct forest_gen *g = (struct forest_gen *)p;
    for (int v = 0; v < TEMPLATE_COUNT; v++) {
        tw_forest_stands_destroy(g->templates[v].stands);
        tw_tileset_destroy(g->templates[v].ts);
    }
    free(g);
}

int tw_tilesets_provider_create_forest(uint64_t seed, const struct tw_forest_settings *settings,
                                       const struct tw_log *log,
                                       struct tw_tilesets_provider **out)
{
    if (!tw_procedural_out_given(out, log, "forest-gen"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_forest_settings requested = {0};
    if (settings)
        requested = *settings;
    requested.prototypes = 0;
    struct tw_forest_settings set;
    int err = tw_forest_settings_resolve(&requested, &set, log, "forest-gen");
    if (err)
        return err;

    struct forest_gen *g = calloc(1, sizeof(*g));
    if (!g) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: forest-gen: out of memory");
        return TW_ERR_NOMEM;
    }
    g->base.destroy = forest_gen_destroy;
    g->seed = seed;
    g->settings = set;
    if (log)
        g->log = *log;
    float top = 0.0f;
    for (int v = 0; v < TEMPLATE_COUNT && !err; v++) {
        struct forest_template *t = &g->templates[v];
        err = tw_tileset_create("forest-gen-template", set.footprint, set.footprint, &t->ts);
        if (!err)
            err = tw_forest_stands_create(t->ts, tw_tiles_hash(seed, v, 0x666f726573742d67),
                                          &set, &t->stands);
        if (err)
            break;
        top = fmaxf(top, tw_forest_stands_max_top(t->stands));
        for (int k = 0; k < TW_FOREST_STAND_KIND_COUNT; k++) {
            float mix[TW_FOREST_SPECIES_COUNT];
            tw_forest_stand_mix((enum tw_forest_stand_kind)k, mix);
            g->base_tree_triangles[v][k] =
                tw_forest_stands_tree_triangles(t->stands, (enum tw_forest_stand_kind)k, mix);
        }
    }
    if (err) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: forest-gen: templates failed: %s",
                      tw_error_to_str(err));
        forest_gen_destroy(&g->base);
        return err;
    }

    /* The floor spans the footprint at y = 0; a stand keeps every vertex
     * inside its area (the footprint) and on or above its ground (0). */
    tw_provider_init(&g->base.provider, "forest-gen", set.footprint, top, forest_gen_generate, g,
                     set.max_cluster_triangles);
    *out = &g->base;
    return TW_OK;
}
