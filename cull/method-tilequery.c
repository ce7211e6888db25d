/*
 * Tile-query propagation (DESIGN §4) with a local method inside every tile
 * found visible:
 *
 *   tilequery      hardware tile queries (cull/tilequery.c); a visible
 *                  tile's clusters in the frustum, drawn whole (method-vfc.c)
 *   tilequery+chc  the same queries; CHC++ inside a visible tile
 *                  (method-chc.c), its pass suspended where it would wait
 *   tilequery+hzb  the two phases of the HZB (method-hzb.c), phase 2 being
 *                  propagation whose tile and node tests the depth pyramid
 *                  answers at once
 *
 * The tiles of the neighbours that a visible cell's propagation is about to
 * test are asked for early (DESIGN §12: prefetch when a neighbour is
 * queried).
 */
#include "cull/cull-private.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>

/* ---- tilequery and tilequery+chc: hardware tile queries ----------------------------- */

struct tilequery_method {
    struct tw_cull_method_base base;
    struct tw_tilequery *tq;
    struct tw_chc *chc;                 /* tilequery+chc's local method */
    struct tw_cull_clusters clusters;   /* tilequery's local method's */
};

/* One frame's propagation, as its render callback sees it. */
struct propagation {
    struct tilequery_method *m;
    struct tw_cull_frame *fr;
};

static const struct tw_cull_method_ops tilequery_ops, tilequery_chc_ops;

static struct tilequery_method *tilequery_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &tilequery_ops || m->impl == &tilequery_chc_ops);
    return (struct tilequery_method *)m;
}

/* The tile of a node found visible, when it is ready (the propagation has
 * asked for its neighbours' tiles already). */
static bool visible_tile(const struct propagation *pr, struct tw_cell cell, uint32_t level,
                         struct tw_cull_tile *tile)
{
    struct tw_cull_frame *fr = pr->fr;
    if (fr->err)
        return false;
    return tw_cull_frame_tile(fr, cell, level, tw_cull_frame_cell_distance(fr, cell, level), tile);
}

/* tilequery's local method. It keeps an instance per visible tile, as the
 * system does, with no state in it. A cell drawn on last frame's word is
 * drawn under its own query where the backend can (the GPU skips it if it
 * is hidden now, and nothing waits). */
static void render_vfc(void *user, struct tw_cell cell, uint32_t level, const float offset[3],
                       uint32_t condition)
{
    const struct propagation *pr = user;
    struct tw_cull_frame *fr = pr->fr;
    struct tw_cull_tile tile;
    if (!visible_tile(pr, cell, level, &tile))
        return;
    struct tw_cull_instance inst;
    bool created;
    tw_cull_frame_instance(fr, cell, &tile, offset, 0, &inst, &created);
    if (condition == 0 || !fr->be->draw_if) {
        tw_cull_vfc_draw(fr, &pr->m->clusters, cell, &tile, offset);
        return;
    }
    uint32_t *out = tw_cull_frame_clusters(fr, &pr->m->clusters, tile.proto->cluster_count);
    if (!out)
        return;
    const uint32_t n = tw_cull_vfc_tile(fr->v, tile.proto, offset, out);
    if (n > 0)
        fr->be->draw_if(fr->be->ctx, condition, cell, tile.content, offset, out, n);
}

/* tilequery+chc's local method. The tile query already found the cell
 * visible: while a tile's pass waits, the next tiles' work goes to the GPU. */
static void render_chc(void *user, struct tw_cell cell, uint32_t level, const float offset[3],
                       uint32_t condition)
{
    (void)condition;
    const struct propagation *pr = user;
    struct tw_cull_tile tile;
    if (visible_tile(pr, cell, level, &tile))
        tw_cull_chc_draw(pr->m->chc, pr->fr, cell, &tile, offset, true);
}

/* tilequery+chc at each wavefront's flush: the suspended CHC++ passes read
 * what that flush sent and go on. */
static bool front_chc(void *user)
{
    const struct propagation *pr = user;
    return tw_chc_resume_flushed(pr->m->chc);
}

static int propagate(struct tilequery_method *m, struct tw_cull_frame *fr,
                     tw_tilequery_render_fn render, tw_tilequery_front_fn front)
{
    struct tw_tilequery_stats tq;
    struct propagation pr = {m, fr};
    const int err = tw_tilequery_frame(m->tq, fr->v, fr->be, fr->g, render, front, &pr, &tq);
    fr->st->tiles_queried = tq.tiles_queried;
    fr->st->predict_fail = tq.predict_fail;
    fr->st->tiles_visible = tq.tiles_visible;
    return err ? err : fr->err;
}

static int tilequery_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    return propagate(tilequery_from_method(m), fr, render_vfc, NULL);
}

static int tilequery_chc_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    struct tilequery_method *tm = tilequery_from_method(m);
    tw_cull_chc_begin(tm->chc, fr);
    const int err = propagate(tm, fr, render_chc, front_chc);
    tw_cull_chc_end(tm->chc, fr);
    return err;
}

static void tilequery_chc_set_costs(struct tw_cull_method_base *m,
                                    const struct tw_cost_model *costs)
{
    tw_chc_set_costs(tilequery_from_method(m)->chc, costs);
}

static const struct tw_tilequery *tilequery_engine(const struct tw_cull_method_base *m)
{
    return ((const struct tilequery_method *)m)->tq;
}

static size_t tilequery_bytes(const struct tw_cull_method_base *m)
{
    const struct tilequery_method *tm = (const struct tilequery_method *)m;
    return sizeof(*tm) + tw_tilequery_bytes(tm->tq) + (tm->chc ? tw_chc_bytes(tm->chc) : 0) +
           sizeof(*tm->clusters.index) * tm->clusters.cap;
}

static void tilequery_destroy(struct tw_cull_method_base *m)
{
    struct tilequery_method *tm = tilequery_from_method(m);
    tw_tilequery_destroy(tm->tq);
    tw_chc_destroy(tm->chc);
    free(tm->clusters.index);
    free(tm);
}

static const struct tw_cull_method_ops tilequery_ops = {
    .destroy = tilequery_destroy,
    .frame = tilequery_frame,
    .bytes = tilequery_bytes,
    .tilequery = tilequery_engine,
    .tile_instances = true,
};

static const struct tw_cull_method_ops tilequery_chc_ops = {
    .destroy = tilequery_destroy,
    .frame = tilequery_chc_frame,
    .bytes = tilequery_bytes,
    .set_costs = tilequery_chc_set_costs,
    .tilequery = tilequery_engine,
    .tile_instances = true,
};

static int tilequery_create(const struct tw_cull_driver_settings *s,
                            const struct tw_cull_method_ops *ops, struct tw_cull_method_base **out)
{
    struct tilequery_method *tm = calloc(1, sizeof(*tm));
    if (!tm)
        return TW_ERR_NOMEM;
    tm->base.impl = ops;
    int err = TW_OK;
    if (ops == &tilequery_chc_ops) {
        err = tw_chc_create(&s->chc, &tm->chc);
        if (!err)
            tw_chc_set_wavefront(tm->chc, !s->chc.per_tile_waits);
    }
    if (!err)
        err = tw_tilequery_create(&s->tilequery, &tm->tq);
    if (err) {
        tilequery_destroy(&tm->base);
        return err;
    }
    *out = &tm->base;
    return TW_OK;
}

int tw_cull_tilequery_method_create(const struct tw_cull_driver_settings *s,
                                    struct tw_cull_method_base **out)
{
    return tilequery_create(s, &tilequery_ops, out);
}

int tw_cull_tilequery_chc_method_create(const struct tw_cull_driver_settings *s,
                                        struct tw_cull_method_base **out)
{
    return tilequery_create(s, &tilequery_chc_ops, out);
}

/* ---- tilequery+hzb: tile queries answered by the depth pyramid ---------------------- */

struct tilequery_hzb_method {
    struct tw_cull_method_base base;
    uint32_t neighbours;
    struct tw_hzb_phases phases;
    struct tw_cull_cell *found;         /* cells found visible this frame */
    size_t found_count, found_cap;
    struct tw_distance_entry *heap;     /* of them, those to visit, nearest first */
    size_t heap_count, heap_cap;
    struct tw_cull_cell *near;          /* a node's neighbours */
    size_t near_cap;
};

static const struct tw_cull_method_ops tilequery_hzb_ops;

static struct tilequery_hzb_method *tilequery_hzb_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &tilequery_hzb_ops);
    return (struct tilequery_hzb_method *)m;
}

/* A cell found visible, queued for its visit. */
static void queue_visible(struct tilequery_hzb_method *hm, struct tw_cull_frame *fr,
                          struct tw_cell cell, uint32_t level, float distance)
{
    const size_t n = hm->found_count;
    if (!tw_cull_frame_reserve(fr, (void **)&hm->found, &hm->found_cap, n + 1,
                               sizeof(*hm->found)) ||
        !tw_cull_frame_reserve(fr, (void **)&hm->heap, &hm->heap_cap, n + 1, sizeof(*hm->heap)))
        return;
    hm->found[hm->found_count++] = (struct tw_cull_cell){cell, distance, level};
    tw_distance_push(hm->heap, &hm->heap_count, distance, (uint32_t)n);
}

/* Phase 2 as §4 with immediate answers. From the camera's cell (or the
 * nearest cell in view), visible cells are visited nearest first; each
 * visit traverses the cell's tile, then decides on its neighbours in view
 * not reached yet, and the visible ones join the queue. A hidden cell stops
 * propagation there. No pending or postponed queue: the pyramid answers at
 * once. */
static void propagate_now(struct tilequery_hzb_method *hm, struct tw_cull_frame *fr)
{
    struct tw_hzb_phases *p = &hm->phases;
    const struct tw_cull_grid *g = fr->g;
    struct tw_cull_cell start;
    float off[3];
    start.level = tw_cull_cover(fr->v, g, fr->v->cell, &start.cell);
    if (!tw_cull_frame_cell_in_view(fr, start.cell, start.level, off, &start.distance)) {
        const int err = tw_cull_cells_of_frame(fr->cells, fr->v, g);
        if (err) {
            fr->err = err;
            return;
        }
        if (fr->cells->count == 0)
            return;
        start = fr->cells->cells[0];
    }
    hm->found_count = hm->heap_count = 0;
    uint64_t prev;
    tw_tiles_cell_offset(start.cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
    tw_hzb_phases_decide(p, fr, start.cell, start.level, off, true, &prev);
    queue_visible(hm, fr, start.cell, start.level, start.distance);
    while (hm->heap_count > 0 && !fr->err) {
        const struct tw_cull_cell c = hm->found[tw_distance_pop(hm->heap, &hm->heap_count)];
        tw_tiles_cell_offset(c.cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
        /* The neighbours' tiles are asked for before this one is drawn. */
        size_t n;
        if (tw_cull_neighbours_into(fr->v, g, c.cell, c.level, hm->neighbours, &hm->near,
                                    &hm->near_cap, &n)) {
            fr->err = TW_ERR_NOMEM;
            break;
        }
        tw_cull_nodes_in_view_prefetch(fr->v, g, hm->near, n);
        tw_hzb_phases_visit(p, fr, c.cell, c.level, c.distance, off,
                            tw_hzb_phases_verdict(p, c.cell));
        for (size_t k = 0; k < n && !fr->err; k++) {
            const struct tw_cull_cell nc = hm->near[k];
            if (nc.distance == INFINITY || tw_hzb_phases_reached(p, fr, nc.cell))
                continue;
            /* Decided once per frame (tw_hzb_phases_reached), so queued at
             * most once. */
            float noff[3];
            tw_tiles_cell_offset(nc.cell, fr->v->cell, g->footprint[0], g->footprint[1], noff);
            const struct tw_box box = tw_cull_node_box(g, nc.level);
            const bool free_pass = tw_cull_near_box(fr->v, &box, noff);
            if (tw_hzb_phases_decide(p, fr, nc.cell, nc.level, noff, free_pass, &prev))
                queue_visible(hm, fr, nc.cell, nc.level, nc.distance);
        }
    }
}

static int tilequery_hzb_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    struct tilequery_hzb_method *hm = tilequery_hzb_from_method(m);
    const uint32_t drawn = tw_hzb_phases_begin(&hm->phases, fr);
    if (!fr->err)
        propagate_now(hm, fr);
    return tw_hzb_phases_end(&hm->phases, fr, drawn);
}

static size_t tilequery_hzb_bytes(const struct tw_cull_method_base *m)
{
    const struct tilequery_hzb_method *hm = (const struct tilequery_hzb_method *)m;
    return sizeof(*hm) + tw_hzb_phases_bytes(&hm->phases) + sizeof(*hm->found) * hm->found_cap +
           sizeof(*hm->heap) * hm->heap_cap + sizeof(*hm->near) * hm->near_cap;
}

static void tilequery_hzb_destroy(struct tw_cull_method_base *m)
{
    struct tilequery_hzb_method *hm = tilequery_hzb_from_method(m);
    tw_hzb_phases_finish(&hm->phases);
    free(hm->found);
    free(hm->heap);
    free(hm->near);
    free(hm);
}

static const struct tw_cull_method_ops tilequery_hzb_ops = {
    .destroy = tilequery_hzb_destroy,
    .frame = tilequery_hzb_frame,
    .bytes = tilequery_hzb_bytes,
    .tile_instances = true,
};

int tw_cull_tilequery_hzb_method_create(const struct tw_cull_driver_settings *s,
                                        struct tw_cull_method_base **out)
{
    struct tilequery_hzb_method *hm = calloc(1, sizeof(*hm));
    if (!hm)
        return TW_ERR_NOMEM;
    hm->base.impl = &tilequery_hzb_ops;
    hm->neighbours = s->tilequery.neighbours;
    const int err = tw_hzb_phases_init(&hm->phases, s->hzb_mutate_shrink);
    if (err) {
        tilequery_hzb_destroy(&hm->base);
        return err;
    }
    *out = &hm->base;
    return TW_OK;
}
