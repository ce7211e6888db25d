/*
 * chc (DESIGN §6): CHC++ run separately inside every cell in view, tiles
 * front to back, no tile queries. Also CHC++ as the local method of
 * tilequery+chc: the per-view state of a cell's tile lives in its tile
 * instance, and a V-query left in flight at the end of a frame names its
 * instance by handle.
 */
#include "cull/cull-private.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>

struct chc_method {
    struct tw_cull_method_base base;
    struct tw_chc *chc;
};

static const struct tw_cull_method_ops chc_ops;

static struct chc_method *chc_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &chc_ops);
    return (struct chc_method *)m;
}

/* A deferred V-query names its tile instance by handle; the instance is
 * still that tile only if its cell is still the base of a node of the cut
 * and that node still shows the content it was made for. */
static struct tw_chc_node_state *resolve_tag(void *user, uint64_t tag, const struct tw_bvh **bvh)
{
    struct tw_cull_frame *fr = user;
    const struct tw_tile_handle h = tw_tile_handle_unpack(tag);
    const struct tw_tile_info *info = tw_tile_cache_info(fr->cache, h);
    if (!info)
        return NULL;
    struct tw_cell base;
    const uint32_t level = tw_cull_cover(fr->v, fr->g, info->cell, &base);
    struct tw_cull_tile tile;
    if (base.i != info->cell.i || base.j != info->cell.j ||
        fr->g->source.get(fr->g->source.ctx, info->cell, level,
                          tw_cull_frame_cell_distance(fr, info->cell, level),
                          TW_TILE_SOURCE_RESIDENT, &tile) != TW_OK ||
        tile.key != info->prototype)
        return NULL;
    *bvh = tile.bvh;
    return tw_tile_cache_state(fr->cache, h);
}

void tw_cull_chc_begin(struct tw_chc *chc, struct tw_cull_frame *fr)
{
    tw_chc_begin_frame(chc, fr->v, fr->be, resolve_tag, fr);
}

bool tw_cull_chc_draw(struct tw_chc *chc, struct tw_cull_frame *fr, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3], bool async)
{
    struct tw_cull_instance t;
    bool created;
    struct tw_chc_node_state *state = tw_cull_frame_instance(
        fr, cell, tile, offset, tw_chc_state_bytes(tile->bvh), &t, &created);
    if (!state)
        return false;
    if (created)
        tw_chc_state_init(state, tile->bvh, fr->v->frame);
    const uint32_t before = tw_chc_stats(chc)->clusters_drawn;
    if (async)
        tw_chc_traverse_async(chc, fr->v, fr->be, &t);
    else
        tw_chc_traverse(chc, fr->v, fr->be, &t);
    return tw_chc_stats(chc)->clusters_drawn > before;
}

void tw_cull_chc_end(struct tw_chc *chc, struct tw_cull_frame *fr)
{
    tw_chc_finish(chc);
    fr->st->queries_skipped = tw_chc_stats(chc)->queries_skipped;
}

static bool draw_tile(struct tw_cull_method_base *m, struct tw_cull_frame *fr, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3])
{
    return tw_cull_chc_draw(chc_from_method(m)->chc, fr, cell, tile, offset, false);
}

static int chc_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    struct tw_chc *chc = chc_from_method(m)->chc;
    tw_cull_chc_begin(chc, fr);
    const int err = tw_cull_frame_each_cell(m, fr, draw_tile);
    tw_cull_chc_end(chc, fr);
    return err;
}

static void chc_set_costs(struct tw_cull_method_base *m, const struct tw_cost_model *costs)
{
    tw_chc_set_costs(chc_from_method(m)->chc, costs);
}

static size_t chc_bytes(const struct tw_cull_method_base *m)
{
    const struct chc_method *cm = (const struct chc_method *)m;
    return sizeof(*cm) + tw_chc_bytes(cm->chc);
}

static void chc_destroy(struct tw_cull_method_base *m)
{
    struct chc_method *cm = chc_from_method(m);
    tw_chc_destroy(cm->chc);
    free(cm);
}

static const struct tw_cull_method_ops chc_ops = {
    .destroy = chc_destroy,
    .frame = chc_frame,
    .bytes = chc_bytes,
    .set_costs = chc_set_costs,
    .tile_instances = true,
};

int tw_cull_chc_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out)
{
    struct chc_method *cm = calloc(1, sizeof(*cm));
    if (!cm)
        return TW_ERR_NOMEM;
    cm->base.impl = &chc_ops;
    const int err = tw_chc_create(&s->chc, &cm->chc);
    if (err) {
        chc_destroy(&cm->base);
        return err;
    }
    *out = &cm->base;
    return TW_OK;
}
