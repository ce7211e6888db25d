/* The procedural city tileset (tilesets.h, DESIGN.md §10): its settings
 * and its prototypes, each one block of the block generator
 * (city-layout.c). */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <math.h>
#include <stdio.h>

void tw_tilesets_city_default_settings(struct tw_city_settings *s)
{
    if (!s)
        return;
    s->prototypes = 12;
    s->footprint = 80.0f;
    s->street_width = 14.0f;
    s->max_height = 90.0f;
    s->max_cluster_triangles = 2048;
}

int tw_city_settings_resolve(const struct tw_city_settings *in, struct tw_city_settings *out,
                             const struct tw_log *log, const char *who)
{
    struct tw_city_settings d;
    tw_tilesets_city_default_settings(&d);
    *out = d;
    if (in) {
        if (in->prototypes)
            out->prototypes = in->prototypes;
        if (in->footprint != 0.0f)
            out->footprint = in->footprint;
        if (in->street_width != 0.0f)
            out->street_width = in->street_width;
        if (in->max_height != 0.0f)
            out->max_height = in->max_height;
        if (in->max_cluster_triangles)
            out->max_cluster_triangles = in->max_cluster_triangles;
    }
    if (!tw_procedural_prototypes_valid(out->prototypes, log, who))
        return TW_ERR_INVALID;
    if (!isfinite(out->street_width) || !(out->street_width >= 4.0f)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: street_width = %g m, must be at least 4 m (caller's settings)",
                      who, (double)out->street_width);
        return TW_ERR_INVALID;
    }
    if (!isfinite(out->footprint) || !(out->footprint - out->street_width >= 40.0f) ||
        !(out->footprint <= 1000.0f)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: footprint = %g m with street_width = %g m: the block "
                      "(footprint - street_width) must be at least 40 m and the footprint at "
                      "most 1000 m (caller's settings)",
                      who, (double)out->footprint, (double)out->street_width);
        return TW_ERR_INVALID;
    }
    if (!tw_procedural_in_range(out->max_height, 20.0f, 1000.0f, "max_height", " m", log,
                                who))
        return TW_ERR_INVALID;
    return TW_OK;
}

int tw_tilesets_city(uint64_t seed, const struct tw_city_settings *settings,
                     const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "city"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_city_settings set;
    int err = tw_city_settings_resolve(settings, &set, log, "city");
    if (err)
        return err;

    struct tw_tileset *ts = NULL;
    struct tw_city_blocks *blocks = NULL;
    if ((err = tw_tileset_create("city", set.footprint, set.footprint, &ts)))
        goto out;
    if ((err = tw_city_blocks_create(ts, &set, &blocks)))
        goto out;

    const uint32_t n = set.prototypes;
    for (uint32_t k = 0; k < n; k++) {
        /* The last prototype is a park, the one before a low-rise block;
         * prototype 0 holds the tallest tower. */
        const enum tw_city_block_kind kind = k == n - 1   ? TW_CITY_BLOCK_PARK
                                             : k == n - 2 ? TW_CITY_BLOCK_LOWRISE
                                                          : TW_CITY_BLOCK_DENSE;
        static const char *const kind_names[] = {"dense", "lowrise", "park"};
        static const float weights[] = {1.0f, 0.6f, 0.4f};
        char name[48];
        snprintf(name, sizeof(name), "city-%s-%02u", kind_names[kind], k);
        const int proto = tw_tileset_add_prototype(ts, name, weights[kind]);
        if (proto < 0) {
            err = proto;
            goto out;
        }
        const uint64_t stream = tw_tiles_hash(seed, (int64_t)k, 0x63697479);
        if ((err = tw_city_blocks_add(blocks, (uint32_t)proto, kind, stream, k == 0)))
            goto out;
    }
out:
    err = tw_procedural_hand_over(ts, err, set.max_cluster_triangles, log, "city", out);
    tw_city_blocks_destroy(blocks);
    return err;
}
