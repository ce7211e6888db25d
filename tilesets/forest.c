/* The procedural forest tileset (tilesets.h, DESIGN.md §10): its settings
 * and its prototypes, each the floor, the trail along every border and one
 * stand of the stand generator (forest-layout.c) over the whole tile. */
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <stdio.h>

void tw_tilesets_forest_default_settings(struct tw_forest_settings *s)
{
    if (!s)
        return;
    s->prototypes = 10;
    s->footprint = 80.0f;
    s->density = 1.0f;
    s->path_clearance = 1.0f;
    s->max_cluster_triangles = 2048;
}

int tw_forest_settings_resolve(const struct tw_forest_settings *in,
                               struct tw_forest_settings *out, const struct tw_log *log,
                               const char *who)
{
    tw_tilesets_forest_default_settings(out);
    if (in) {
        if (in->prototypes)
            out->prototypes = in->prototypes;
        if (in->footprint != 0.0f)
            out->footprint = in->footprint;
        if (in->density != 0.0f)
            out->density = in->density;
        if (in->path_clearance != 0.0f)
            out->path_clearance = in->path_clearance;
        if (in->max_cluster_triangles)
            out->max_cluster_triangles = in->max_cluster_triangles;
    }
    if (!tw_procedural_prototypes_valid(out->prototypes, log, who) ||
        !tw_procedural_in_range(out->footprint, 40.0f, 1000.0f, "footprint", " m", log, who) ||
        !tw_procedural_in_range(out->density, 0.25f, 2.0f, "density", "", log, who) ||
        !tw_procedural_in_range(out->path_clearance, 0.1f, 5.0f, "path_clearance", " m", log,
                                who))
        return TW_ERR_INVALID;
    return TW_OK;
}

/* The stands of the forest's prototypes, in order; the list repeats when
 * there are more prototypes. Every kind appears within the first 8. */
static const enum tw_forest_stand_kind forest_order[] = {
    TW_FOREST_STAND_SPRUCE, TW_FOREST_STAND_MIXED,    TW_FOREST_STAND_BEECH,
    TW_FOREST_STAND_THIN,   TW_FOREST_STAND_CLEARING, TW_FOREST_STAND_ROCKY,
    TW_FOREST_STAND_BIRCH,  TW_FOREST_STAND_SPRUCE,   TW_FOREST_STAND_MIXED,
    TW_FOREST_STAND_BEECH,
};

int tw_tilesets_forest(uint64_t seed, const struct tw_forest_settings *settings,
                       const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "forest"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_forest_settings set;
    int err = tw_forest_settings_resolve(settings, &set, log, "forest");
    if (err)
        return err;

    struct tw_tileset *ts = NULL;
    struct tw_forest_stands *stands = NULL;
    if ((err = tw_tileset_create("forest", set.footprint, set.footprint, &ts)))
        goto out;
    if ((err = tw_forest_stands_create(ts, seed, &set, &stands)))
        goto out;

    const uint32_t order_count = sizeof(forest_order) / sizeof(forest_order[0]);
    for (uint32_t k = 0; k < set.prototypes; k++) {
        const enum tw_forest_stand_kind kind = forest_order[k % order_count];
        char name[48];
        snprintf(name, sizeof(name), "forest-%s-%02u", tw_forest_stand_name(kind), k);
        const float weight = kind == TW_FOREST_STAND_CLEARING ? 0.5f
                             : kind == TW_FOREST_STAND_ROCKY  ? 0.7f
                                                              : 1.0f;
        const int proto = tw_tileset_add_prototype(ts, name, weight);
        if (proto < 0) {
            err = proto;
            goto out;
        }
        if ((err = tw_forest_stands_add_floor(stands, (uint32_t)proto, set.path_clearance)))
            goto out;
        const struct tw_forest_area area = {
            {0.0f, 0.0f, set.footprint, set.footprint}, 0.0f, set.path_clearance};
        if ((err = tw_forest_stands_add(stands, (uint32_t)proto, kind,
                                        tw_tiles_hash(seed, (int64_t)k, 0x666f72657374), &area)))
            goto out;
    }
out:
    err = tw_procedural_hand_over(ts, err, set.max_cluster_triangles, log, "forest", out);
    tw_forest_stands_destroy(stands);
    return err;
}
