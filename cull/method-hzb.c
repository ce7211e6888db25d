/*
 * hzb (DESIGN §6): two-phase hierarchical-Z culling, after niagara and
 * Nanite. Phase 1 draws what was visible last frame, a depth pyramid is
 * built from that depth (cull/hzb.c), phase 2 tests every cell in view and
 * then every node box in the frustum against it and draws what is newly
 * visible. The two phases (struct tw_hzb_phases) also serve tilequery+hzb,
 * whose phase 2 is propagation instead (method-tilequery.c).
 */
#include "cull/cull-private.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>

/* ---- the two phases ------------------------------------------------------------------ */

/* What a frame learnt of a cell, kept in tw_hzb_phases.verdict as
 * frame << HZ_SHIFT | flags. */
#define HZ_VISIBLE 1u       /* its common box passed the pyramid (or needed no test) */
#define HZ_PHASE1 2u        /* phase 1 took it for visible: it had a visible node last frame */
#define HZ_DREW1 4u         /* phase 1 drew some of its clusters */
#define HZ_TESTED 8u        /* phase 2 decided on it */
#define HZ_SHIFT 4

int tw_hzb_phases_init(struct tw_hzb_phases *p, float mutate_shrink)
{
    int err = tw_hzb_create(&p->hzb);
    if (!err)
        err = tw_cell_map_create(&p->verdict);
    if (!err)
        tw_hzb_set_mutation(p->hzb, mutate_shrink);
    return err;
}

void tw_hzb_phases_finish(struct tw_hzb_phases *p)
{
    tw_hzb_destroy(p->hzb);
    tw_cell_map_destroy(p->verdict);
    free(p->last);
    free(p->next);
    memset(p, 0, sizeof(*p));
}

size_t tw_hzb_phases_bytes(const struct tw_hzb_phases *p)
{
    return tw_hzb_bytes(p->hzb) + (p->verdict ? tw_cell_map_bytes(p->verdict) : 0) +
           sizeof(*p->last) * (p->last_cap + p->next_cap);
}

static int compare_cells(const void *a, const void *b)
{
    return tw_cull_cell_order(a, b);
}

uint64_t tw_hzb_phases_verdict(const struct tw_hzb_phases *p, struct tw_cell cell)
{
    const uint64_t *v = tw_cell_map_find(p->verdict, cell);
    return v ? *v : 0;
}

static void set_verdict(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                        uint64_t flags)
{
    if (tw_cell_map_set(p->verdict, cell, fr->v->frame << HZ_SHIFT | flags))
        fr->err = TW_ERR_NOMEM;
}

static bool prune_old(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    return (value >> HZ_SHIFT) + 1 < *(const uint64_t *)user;
}

bool tw_hzb_phases_reached(const struct tw_hzb_phases *p, const struct tw_cull_frame *fr,
                           struct tw_cell cell)
{
    const uint64_t v = tw_hzb_phases_verdict(p, cell);
    return v >> HZ_SHIFT == fr->v->frame && (v & HZ_TESTED);
}

/* The HZB state of the cell's tile instance, made on first sight; *t is set
 * up for the traversals. NULL when the tile is not there (pending, refused). */
static struct tw_hzb_node_state *instance(struct tw_cull_frame *fr, struct tw_cell cell,
                                          float distance, const float off[3],
                                          struct tw_cull_instance *t)
{
    struct tw_cull_tile tile;
    if (!tw_cull_frame_tile(fr, cell, distance, &tile))
        return NULL;
    bool created;
    /* A new instance's state starts zeroed: never visible, never drawn. */
    return tw_cull_frame_instance(fr, cell, &tile, off, tw_hzb_state_bytes(tile.bvh), t,
                                  &created);
}

/* Phase 1: last frame's visible tiles still in view, front to back, each
 * drawing its clusters visible last frame. Returns how many clusters were
 * drawn. */
static uint32_t phase1(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    size_t n = 0;
    for (size_t k = 0; k < p->last_count; k++) {
        float off[3], dist;
        if (tw_cull_frame_cell_in_view(fr, p->last[k].cell, off, &dist))
            p->last[n++] = (struct tw_cull_cell){p->last[k].cell, dist};
    }
    if (n > 1) /* qsort() wants a valid pointer even for no elements */
        qsort(p->last, n, sizeof(*p->last), compare_cells);
    uint32_t drawn = 0;
    for (size_t k = 0; k < n && !fr->err; k++) {
        const struct tw_cell cell = p->last[k].cell;
        float off[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        struct tw_cull_instance t;
        uint32_t c = 0;
        if (instance(fr, cell, p->last[k].distance, off, &t))
            c = tw_hzb_draw_last_visible(p->hzb, fr->v, fr->be, &t);
        if (c > 0)
            fr->st->tiles_visible++;
        drawn += c;
        set_verdict(p, fr, cell, HZ_PHASE1 | (c > 0 ? HZ_DREW1 : 0));
    }
    return drawn;
}

/* The depth drawn so far as a pyramid; none (every box visible) when
 * nothing was drawn or there is no depth to read. */
static void pyramid(struct tw_hzb_phases *p, struct tw_cull_frame *fr, bool drawn)
{
    struct tw_hzb *h = p->hzb;
    const struct tw_query_backend *be = fr->be;
    uint32_t w = 0, hh = 0;
    bool reversed = false;
    tw_hzb_clear(h);
    if (!drawn || !be->read_depth || !be->read_depth(be->ctx, NULL, &w, &hh, &reversed))
        return;
    float *depth = tw_hzb_depth_buffer(h, w, hh);
    if (!depth)
        return;     /* out of memory: no pyramid, nothing culled */
    const double t0 = tw_clock_monotonic_ms();
    if (!be->read_depth(be->ctx, depth, &w, &hh, &reversed))
        return;
    const double t1 = tw_clock_monotonic_ms();
    tw_hzb_build(h, reversed);
    fr->st->ms_hzb_read += t1 - t0;
    fr->st->ms_hzb_build += tw_clock_monotonic_ms() - t1;
}

uint32_t tw_hzb_phases_begin(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    const uint64_t f = fr->v->frame;
    if (f >= p->last_prune + 16) {
        tw_cell_map_filter(p->verdict, prune_old, (void *)&f);
        p->last_prune = f;
    }
    tw_hzb_begin_frame(p->hzb);
    p->next_count = 0;
    const uint32_t drawn = phase1(p, fr);
    if (!fr->err)
        pyramid(p, fr, drawn > 0);
    return drawn;
}

bool tw_hzb_phases_decide(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                          const float off[3], bool free_pass, uint64_t *prev)
{
    const uint64_t f = fr->v->frame;
    const uint64_t old = tw_hzb_phases_verdict(p, cell);
    bool visible = true;
    if (!free_pass) {
        fr->st->tiles_queried++;
        fr->st->hzb_boxes++;
        visible = tw_hzb_visible(p->hzb, fr->v, &fr->g->common_box, off);
    }
    /* A prediction: phase 1 drew the cell (predicted visible), or last
     * frame's phase 2 decided on it. */
    const bool this_frame = old >> HZ_SHIFT == f;
    const bool known = this_frame || (old >> HZ_SHIFT == f - 1 && (old & HZ_TESTED));
    const bool predicted = this_frame ? (old & HZ_PHASE1) != 0 : (old & HZ_VISIBLE) != 0;
    if (known && predicted != visible)
        fr->st->predict_fail++;
    *prev = this_frame ? old : 0;
    set_verdict(p, fr, cell, (*prev & (HZ_PHASE1 | HZ_DREW1)) | HZ_TESTED |
                                 (visible ? HZ_VISIBLE : 0));
    return visible;
}

void tw_hzb_phases_visit(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                         float distance, const float off[3], uint64_t prev)
{
    struct tw_cull_instance t;
    struct tw_hzb_node_state *state = instance(fr, cell, distance, off, &t);
    if (!state)
        return;
    const uint32_t tested = tw_hzb_stats(p->hzb)->boxes_tested;
    const uint32_t c = tw_hzb_traverse(p->hzb, fr->v, fr->be, &t);
    fr->st->hzb_boxes += tw_hzb_stats(p->hzb)->boxes_tested - tested;
    if (c > 0 && !(prev & HZ_DREW1))
        fr->st->tiles_visible++;
    if (state[0].visible_frame == fr->v->frame &&
        tw_cull_frame_reserve(fr, (void **)&p->next, &p->next_cap, p->next_count + 1,
                              sizeof(*p->next)))
        p->next[p->next_count++] = (struct tw_cull_cell){cell, distance};
}

/* The visible set for the next frame, decided again against the frame's
 * final depth: the tiles kept are those with a node still visible. */
static void retest(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    const struct tw_cull_grid *g = fr->g;
    const uint32_t tested = tw_hzb_stats(p->hzb)->boxes_tested;
    size_t n = 0;
    for (size_t k = 0; k < p->next_count; k++) {
        const struct tw_cell cell = p->next[k].cell;
        struct tw_cull_tile tile;
        struct tw_tile_handle h;
        const struct tw_tile_info *info;
        /* The tile was at hand a moment ago: never wait, never request. */
        if (g->source.get(g->source.ctx, cell, 0.0f,
                          fr->source_flags | TW_TILE_SOURCE_RESIDENT | TW_TILE_SOURCE_QUIET,
                          &tile) != TW_OK ||
            !tile.proto || !tw_tile_cache_find(fr->cache, cell, &h) ||
            !(info = tw_tile_cache_info(fr->cache, h)) || info->prototype != tile.key) {
            p->next[n++] = p->next[k];    /* kept: the next phase 1 sorts it out */
            continue;
        }
        struct tw_cull_instance t = {
            .cell = cell, .content = tile.content, .proto = tile.proto, .bvh = tile.bvh,
            .state = tw_tile_cache_state(fr->cache, h), .tag = tw_tile_handle_pack(h),
        };
        tw_tiles_cell_offset(cell, fr->v->cell, g->footprint[0], g->footprint[1], t.offset);
        if (tw_hzb_retest(p->hzb, fr->v, &t))
            p->next[n++] = p->next[k];
    }
    p->next_count = n;
    fr->st->hzb_boxes += tw_hzb_stats(p->hzb)->boxes_tested - tested;
}

int tw_hzb_phases_end(struct tw_hzb_phases *p, struct tw_cull_frame *fr, uint32_t phase1)
{
    /* Phase 2 drew more than phase 1 (the first frame, a jump, a fast turn):
     * what it drew was tested against too little depth, and would all be
     * drawn blind by the next phase 1. Worth a second readback. */
    const uint32_t phase2 = tw_hzb_stats(p->hzb)->clusters_drawn - phase1;
    if (!fr->err && phase2 > phase1) {
        pyramid(p, fr, true);
        if (tw_hzb_built(p->hzb))
            retest(p, fr);
    }
    /* This frame's visible cells are the next one's phase 1. */
    struct tw_cull_cell *t = p->last;
    const size_t cap = p->last_cap;
    p->last = p->next;
    p->last_cap = p->next_cap;
    p->last_count = p->next_count;
    p->next = t;
    p->next_cap = cap;
    p->next_count = 0;
    return fr->err;
}

/* ---- hzb: phase 2 over every cell in view ---------------------------------------------- */

struct hzb_method {
    struct tw_cull_method_base base;
    struct tw_hzb_phases phases;
};

static const struct tw_cull_method_ops hzb_ops;

static struct hzb_method *hzb_from_method(struct tw_cull_method_base *m)
{
    assert(m->impl == &hzb_ops);
    return (struct hzb_method *)m;
}

/* Every cell in view, front to back. */
static void phase2(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    const int err = tw_cull_cells_of_frame(fr->cells, fr->v, fr->g);
    if (err) {
        fr->err = err;
        return;
    }
    const struct tw_cull_cells *cells = fr->cells;
    for (size_t k = 0; k < cells->count && !fr->err; k++) {
        const struct tw_cell cell = cells->cells[k].cell;
        float off[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        uint64_t prev;
        if (tw_hzb_phases_decide(p, fr, cell, off,
                                 tw_cull_near_box(fr->v, &fr->g->common_box, off), &prev))
            tw_hzb_phases_visit(p, fr, cell, cells->cells[k].distance, off, prev);
    }
}

static int hzb_frame(struct tw_cull_method_base *m, struct tw_cull_frame *fr)
{
    struct tw_hzb_phases *p = &hzb_from_method(m)->phases;
    const uint32_t drawn = tw_hzb_phases_begin(p, fr);
    if (!fr->err)
        phase2(p, fr);
    return tw_hzb_phases_end(p, fr, drawn);
}

static size_t hzb_bytes(const struct tw_cull_method_base *m)
{
    const struct hzb_method *hm = (const struct hzb_method *)m;
    return sizeof(*hm) + tw_hzb_phases_bytes(&hm->phases);
}

static void hzb_destroy(struct tw_cull_method_base *m)
{
    struct hzb_method *hm = hzb_from_method(m);
    tw_hzb_phases_finish(&hm->phases);
    free(hm);
}

static const struct tw_cull_method_ops hzb_ops = {
    .destroy = hzb_destroy,
    .frame = hzb_frame,
    .bytes = hzb_bytes,
    .tile_instances = true,
};

int tw_cull_hzb_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out)
{
    struct hzb_method *hm = calloc(1, sizeof(*hm));
    if (!hm)
        return TW_ERR_NOMEM;
    hm->base.impl = &hzb_ops;
    const int err = tw_hzb_phases_init(&hm->phases, s->hzb_mutate_shrink);
    if (err) {
        hzb_destroy(&hm->base);
        return err;
    }
    *out = &hm->base;
    return TW_OK;
}
