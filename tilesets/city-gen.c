/* city-gen: a tile provider whose every cell is a city block of its own
 * (tilesets.h, DESIGN.md §10, §12).
 *
 * A cell's tile is what one prototype of the city tileset is: the city's
 * block generator (city-layout.c) fills a tileset of one prototype with the
 * streets along every border and one block, its kind drawn in the shares
 * that selection gives the city's default prototypes, and its stream (the
 * footprints, heights, facades and lot layout) from the cell's hash. So
 * the triangle density is the city's by construction; the test measures it.
 *
 * Thread safety: generate() reads the provider, which nothing writes after
 * creation, and keeps its generator on the heap of the call. */
#include "tiles/tiles-internal.h"
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <stdio.h>
#include <stdlib.h>

struct city_gen {
    struct tw_tilesets_provider base;
    uint64_t seed;
    struct tw_city_settings settings;   /* resolved */
    struct tw_log log;
};

/* The city tileset's twelve default prototypes as selection weighs them:
 * ten dense blocks of weight 1, one of them the tallest, a low-rise block
 * of weight 0.6 and a park of weight 0.4 (tw_tilesets_city()). */
static const struct {
    enum tw_city_block_kind kind;
    bool tallest;
    float share;
    const char *name;
} block_mix[] = {
    {TW_CITY_BLOCK_DENSE, true, 1.0f, "tallest"},
    {TW_CITY_BLOCK_DENSE, false, 9.0f, "dense"},
    {TW_CITY_BLOCK_LOWRISE, false, 0.6f, "lowrise"},
    {TW_CITY_BLOCK_PARK, false, 0.4f, "park"},
};

enum { BLOCK_MIX_COUNT = sizeof(block_mix) / sizeof(block_mix[0]) };

static uint32_t pick_block(struct tw_rng *r)
{
    float total = 0.0f;
    for (uint32_t k = 0; k < BLOCK_MIX_COUNT; k++)
        total += block_mix[k].share;
    float x = tw_rng_float(r) * total;
    for (uint32_t k = 0; k + 1 < BLOCK_MIX_COUNT; k++) {
        if (x < block_mix[k].share)
            return k;
        x -= block_mix[k].share;
    }
    return BLOCK_MIX_COUNT - 1;
}

static int city_gen_generate(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    const struct city_gen *g = user;
    int err = tw_provider_check_tile(&g->base.provider, &g->log, cell, ts);
    if (err)
        return err;
    struct tw_rng r = {tw_tiles_hash(g->seed, cell.i, cell.j)};
    const uint32_t pick = pick_block(&r);
    const uint64_t stream = tw_rng_next(&r);

    struct tw_city_blocks *blocks = NULL;
    if ((err = tw_city_blocks_create_tile(ts, &g->settings, &blocks)))
        goto out;
    char name[48];
    snprintf(name, sizeof(name), "%s %lld,%lld", block_mix[pick].name, (long long)cell.i,
             (long long)cell.j);
    const int proto = tw_tileset_add_prototype(ts, name, 1.0f);
    if (proto < 0) {
        err = proto;
        goto out;
    }
    err = tw_city_blocks_add(blocks, (uint32_t)proto, block_mix[pick].kind, stream,
                             block_mix[pick].tallest);
out:
    tw_city_blocks_destroy(blocks);
    return err;
}

static void city_gen_destroy(struct tw_tilesets_provider *p)
{
    free(p);
}

int tw_tilesets_provider_create_city(uint64_t seed, const struct tw_city_settings *settings,
                                     const struct tw_log *log,
                                     struct tw_tilesets_provider **out)
{
    if (!tw_procedural_out_given(out, log, "city-gen"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_city_settings requested = {0};
    if (settings)
        requested = *settings;
    requested.prototypes = 0;
    struct tw_city_settings set;
    int err = tw_city_settings_resolve(&requested, &set, log, "city-gen");
    if (err)
        return err;

    struct city_gen *g = calloc(1, sizeof(*g));
    if (!g) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: city-gen: out of memory");
        return TW_ERR_NOMEM;
    }
    g->seed = seed;
    g->settings = set;
    if (log)
        g->log = *log;
    /* The streets span the footprint at y = 0; nothing leaves it (lots and
     * everything on them lie inside the block) or goes below the road. */
    tw_provider_init(&g->base.provider, "city-gen", set.footprint, tw_city_blocks_max_top(&set),
                     city_gen_generate, g, set.max_cluster_triangles);
    g->base.destroy = city_gen_destroy;
    *out = &g->base;
    return TW_OK;
}
