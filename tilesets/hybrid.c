/* The hybrid tileset (tilesets-private.h; a host gets it through
 * tw_tilesets_builtin(), DESIGN.md §10): city blocks mixed with parks and
 * wooded blocks.
 *
 * Nothing here generates geometry: the city's block generator builds the
 * city blocks and the parks, and a wooded block is the city's streets round
 * a stand of the forest's generator that fills the lot area (canopies
 * included), so streets run along every tile border in every prototype. */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static const float default_green_share = 0.4f;

/* The hybrid's settings that are the city's. */
static void take_city_settings(struct tw_hybrid_settings *s, const struct tw_city_settings *city)
{
    s->prototypes = city->prototypes;
    s->footprint = city->footprint;
    s->street_width = city->street_width;
    s->max_height = city->max_height;
    s->max_cluster_triangles = city->max_cluster_triangles;
}

void tw_tilesets_hybrid_default_settings(struct tw_hybrid_settings *s)
{
    if (!s)
        return;
    struct tw_city_settings city;
    tw_tilesets_city_default_settings(&city);
    take_city_settings(s, &city);
    s->green_share = default_green_share;
}

/* The city's fields are the city's settings, resolved (defaults and
 * checks) by the city; hybrid adds only green_share. */
static int resolve_settings(const struct tw_hybrid_settings *in, struct tw_hybrid_settings *out,
                            struct tw_city_settings *city, const struct tw_log *log)
{
    struct tw_city_settings requested = {0};
    if (in)
        requested = (struct tw_city_settings){
            in->prototypes, in->footprint, in->street_width, in->max_height,
            in->max_cluster_triangles,
        };
    const int err = tw_city_settings_resolve(&requested, city, log, "hybrid");
    if (err)
        return err;
    take_city_settings(out, city);
    out->green_share = in && in->green_share != 0.0f ? in->green_share : default_green_share;
    if (!isfinite(out->green_share) || !(out->green_share > 0.0f) || !(out->green_share < 1.0f)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: hybrid: green_share = %g, must be in (0, 1) (caller's settings)",
                      (double)out->green_share);
        return TW_ERR_INVALID;
    }
    return TW_OK;
}

/* Wooded blocks cycle through these stands. */
static const enum tw_forest_stand_kind wooded_stands[] = {
    TW_FOREST_STAND_MIXED, TW_FOREST_STAND_BEECH, TW_FOREST_STAND_THIN,
    TW_FOREST_STAND_BIRCH, TW_FOREST_STAND_SPRUCE,
};

enum block { BLOCK_DENSE, BLOCK_LOWRISE, BLOCK_PARK, BLOCK_WOOD };

/* Prototype k of n with green of them parks or woods: city blocks first
 * (dense ones, then one low-rise block), then woods and parks alternating,
 * woods first and at least as many as parks. */
static enum block block_of(uint32_t k, uint32_t n, uint32_t green)
{
    const uint32_t city = n - green;
    if (k < city)
        return k + 1 == city ? BLOCK_LOWRISE : BLOCK_DENSE;
    return (k - city) % 3 == 1 ? BLOCK_PARK : BLOCK_WOOD;
}

int tw_tilesets_hybrid(uint64_t seed, const struct tw_hybrid_settings *settings,
                       const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "hybrid"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_hybrid_settings set;
    struct tw_city_settings city_set;
    int err = resolve_settings(settings, &set, &city_set, log);
    if (err)
        return err;
    struct tw_forest_settings forest_set;
    tw_tilesets_forest_default_settings(&forest_set);
    forest_set.footprint = set.footprint;
    forest_set.max_cluster_triangles = set.max_cluster_triangles;

    const uint32_t n = set.prototypes;
    uint32_t green = (uint32_t)floorf(set.green_share * (float)n + 0.5f);
    green = green < 2 ? 2 : green > n - 2 ? n - 2 : green;

    struct tw_tileset *ts = NULL;
    struct tw_city_blocks *blocks = NULL;
    struct tw_forest_stands *stands = NULL;
    if ((err = tw_tileset_create("hybrid", set.footprint, set.footprint, &ts)))
        goto out;
    if ((err = tw_city_blocks_create(ts, &city_set, &blocks)))
        goto out;
    if ((err = tw_forest_stands_create(ts, seed, &forest_set, &stands)))
        goto out;

    uint32_t woods = 0;
    for (uint32_t k = 0; k < n; k++) {
        const enum block b = block_of(k, n, green);
        static const char *const block_names[] = {"dense", "lowrise", "park", "wood"};
        static const float weights[] = {1.0f, 0.7f, 0.5f, 0.7f};
        const enum tw_forest_stand_kind stand =
            wooded_stands[woods % (sizeof(wooded_stands) / sizeof(wooded_stands[0]))];
        char name[48];
        if (b == BLOCK_WOOD)
            snprintf(name, sizeof(name), "hybrid-wood-%s-%02u", tw_forest_stand_name(stand), k);
        else
            snprintf(name, sizeof(name), "hybrid-%s-%02u", block_names[b], k);
        const int proto = tw_tileset_add_prototype(ts, name, weights[b]);
        if (proto < 0) {
            err = proto;
            goto out;
        }
        const uint64_t stream = tw_tiles_hash(seed, (int64_t)k, 0x687962726964);
        if (b == BLOCK_WOOD) {
            struct tw_forest_area area = {{0}, 0.0f, 0.0f};
            tw_city_blocks_lot_area(blocks, area.rect, &area.ground_y);
            err = tw_city_blocks_add_streets(blocks, (uint32_t)proto,
                                             tw_forest_stands_floor_material(stands));
            if (!err)
                err = tw_forest_stands_add(stands, (uint32_t)proto, stand, stream, &area);
            woods++;
        } else {
            const enum tw_city_block_kind kind = b == BLOCK_DENSE     ? TW_CITY_BLOCK_DENSE
                                                 : b == BLOCK_LOWRISE ? TW_CITY_BLOCK_LOWRISE
                                                                      : TW_CITY_BLOCK_PARK;
            err = tw_city_blocks_add(blocks, (uint32_t)proto, kind, stream, k == 0);
        }
        if (err)
            goto out;
    }
out:
    err = tw_procedural_hand_over(ts, err, set.max_cluster_triangles, log, "hybrid", out);
    tw_forest_stands_destroy(stands);
    tw_city_blocks_destroy(blocks);
    return err;
}
