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

#include <assert.h>
#include <stdlib.h>
#include <string.h>

/* What a candidate of the GPU's test was, to apply its answer when it
 * arrives: a cell's common box (taken: its tile was instantiated and its
 * leaves queued; not taken: a box that passes is a tile late), or a leaf
 * of a tile instance. */
enum { GPU_CELL_TAKEN, GPU_CELL_NOT_TAKEN, GPU_LEAF };
struct tw_hzb_gpu_candidate {
    struct tw_cell cell;
    uint32_t level;                     /* of the node whose base is cell */
    uint64_t tag;                       /* leaf: the tile instance's handle */
    uint32_t node;                      /* leaf: its BVH node */
    uint32_t kind;
    bool inside;                        /* cell: its common box wholly in the frustum */
};

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
        err = tw_cell_map_create(&p->gpu_verdict);
    if (!err)
        tw_hzb_set_mutation(p->hzb, mutate_shrink);
    p->shrink = mutate_shrink > 0.0f && mutate_shrink < 1.0f ? mutate_shrink : 0.0f;
    return err;
}

void tw_hzb_phases_finish(struct tw_hzb_phases *p)
{
    tw_hzb_destroy(p->hzb);
    tw_cell_map_destroy(p->verdict);
    tw_cell_map_destroy(p->gpu_verdict);
    for (int k = 0; k < TW_HZB_GPU_LISTS; k++)
        free(p->lists[k].items);
    free(p->stack);
    free(p->render);
    free(p->near);
    free(p->last);
    free(p->next);
    memset(p, 0, sizeof(*p));
}

size_t tw_hzb_phases_bytes(const struct tw_hzb_phases *p)
{
    size_t lists = 0;
    for (int k = 0; k < TW_HZB_GPU_LISTS; k++)
        lists += p->lists[k].cap * sizeof(*p->lists[k].items);
    return tw_hzb_bytes(p->hzb) + (p->verdict ? tw_cell_map_bytes(p->verdict) : 0) +
           (p->gpu_verdict ? tw_cell_map_bytes(p->gpu_verdict) : 0) + lists +
           sizeof(*p->stack) * p->stack_cap + sizeof(*p->render) * p->render_cap +
           sizeof(*p->last) * (p->last_cap + p->next_cap) + sizeof(*p->near) * p->near_cap;
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
                                          uint32_t level, float distance, const float off[3],
                                          struct tw_cull_instance *t)
{
    struct tw_cull_tile tile;
    if (!tw_cull_frame_tile(fr, cell, level, distance, &tile))
        return NULL;
    bool created;
    /* A new instance's state starts zeroed: never visible, never drawn. */
    return tw_cull_frame_instance(fr, cell, &tile, off, tw_hzb_state_bytes(tile.bvh), t,
                                  &created);
}

/* Keeps of p->last the nodes still in view and still in the frame's cut
 * (a node the cut has refined or merged since shows other content: what
 * the frame draws there is phase 2's to decide), with their distance,
 * front to back; returns how many. */
static size_t last_in_view(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    size_t n = 0;
    const bool cut = tw_cull_grid_hierarchical(fr->g);
    for (size_t k = 0; k < p->last_count; k++) {
        const struct tw_cull_cell c = p->last[k];
        float off[3], dist;
        struct tw_cell base;
        if (cut && (tw_cull_cover(fr->v, fr->g, c.cell, &base) != c.level ||
                    base.i != c.cell.i || base.j != c.cell.j))
            continue;
        if (tw_cull_frame_cell_in_view(fr, c.cell, c.level, off, &dist))
            p->last[n++] = (struct tw_cull_cell){c.cell, dist, c.level};
    }
    if (n > 1) /* qsort() wants a valid pointer even for no elements */
        qsort(p->last, n, sizeof(*p->last), compare_cells);
    return n;
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

/* ---- the two phases on the GPU --------------------------------------------------------- */

static struct tw_hzb_gpu_list *gpu_list(struct tw_hzb_phases *p, uint64_t frame)
{
    for (int k = 0; k < TW_HZB_GPU_LISTS; k++)
        if (p->lists[k].frame == frame)
            return &p->lists[k];
    return NULL;
}

/* Queues a candidate of the frame's test; false: out of memory (the
 * frame's error). */
static bool gpu_queue(struct tw_hzb_phases *p, struct tw_cull_frame *fr, const struct tw_box *box,
                      bool always, const struct tw_hzb_gpu_candidate *c, uint32_t content,
                      const float off[3], const uint32_t *clusters, uint32_t count)
{
    struct tw_hzb_gpu_list *l = gpu_list(p, fr->v->frame);
    if (!l || !tw_cull_frame_reserve(fr, (void **)&l->items, &l->cap, l->count + 1,
                                     sizeof(*l->items)))
        return false;
    const struct tw_query_backend *be = fr->be;
    struct tw_box q = *box;
    if (p->shrink > 0.0f) /* testing: a broken culler the checks must catch */
        for (int a = 0; a < 3; a++) {
            const float m = 0.5f * (q.min[a] + q.max[a]), r = 0.5f * (q.max[a] - q.min[a]);
            q.min[a] = m - r * (1.0f - p->shrink);
            q.max[a] = m + r * (1.0f - p->shrink);
        }
    const uint32_t i = be->gpu_hzb_candidate(be->ctx, &q, always, c->cell, content, off,
                                             clusters, count);
    if (i == UINT32_MAX)
        return true;    /* drawn untested (the backend out of memory) */
    /* Indices are consecutive from 0 in a frame. */
    assert(i == l->count);
    l->items[l->count++] = *c;
    fr->st->hzb_boxes++;
    return true;
}

/* Applies the answers of the latest frame the GPU has finished: leaves
 * that passed are marked visible in that frame (phase 1 draws them next),
 * cells get their verdict, and the cells with a visible leaf become the
 * next phase 1's list. */
static void gpu_apply(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    const struct tw_query_backend *be = fr->be;
    uint32_t n = 0;
    uint64_t frame = 0;
    const uint32_t *bits = be->gpu_hzb_results(be->ctx, p, false, &n, &frame);
    if (bits) {
        struct tw_hzb_gpu_list *l = gpu_list(p, frame);
        if (l) {
            p->last_count = 0;
            /* Only the latest answers count: older verdicts go. */
            tw_cell_map_clear(p->gpu_verdict);
            struct tw_cell last_cell = {0, 0};
            bool have_last = false;
            const size_t count = n < l->count ? n : l->count;
            for (size_t i = 0; i < count; i++) {
                const struct tw_hzb_gpu_candidate *c = &l->items[i];
                const bool passed = bits[i >> 5] >> (i & 31) & 1u;
                if (c->kind != GPU_LEAF) {
                    /* A box partly outside the frustum was tested only where it
                     * showed: hidden there says nothing of the rest, which a
                     * turn may bring in (no verdict). */
                    if ((passed || c->inside) &&
                        tw_cell_map_set(p->gpu_verdict, c->cell,
                                        (uint64_t)c->level << 1 | (passed ? 1u : 0u)))
                        fr->err = TW_ERR_NOMEM;
                    if (passed && c->kind == GPU_CELL_NOT_TAKEN)
                        fr->st->tiles_late++;
                    continue;
                }
                if (!passed || !fr->cache)
                    continue;
                struct tw_hzb_node_state *state =
                    tw_tile_cache_state(fr->cache, tw_tile_handle_unpack(c->tag));
                if (!state)
                    continue;   /* gone since */
                state[c->node].visible_frame = frame;
                if (!have_last || last_cell.i != c->cell.i || last_cell.j != c->cell.j) {
                    /* A tile's leaves are consecutive: one entry per tile. */
                    if (tw_cull_frame_reserve(fr, (void **)&p->last, &p->last_cap,
                                              p->last_count + 1, sizeof(*p->last)))
                        p->last[p->last_count++] =
                            (struct tw_cull_cell){c->cell, 0.0f, c->level};
                    last_cell = c->cell;
                    have_last = true;
                }
            }
            p->known = frame;
        }
        for (int k = 0; k < TW_HZB_GPU_LISTS; k++)
            if (p->lists[k].frame <= frame)
                p->lists[k].frame = 0;
    }
    fr->st->hzb_results_lag = p->known ? (uint32_t)(fr->v->frame - p->known) : 0;
    /* A list for this frame's candidates: the oldest in flight gives way
     * (its answers, if they ever come, are then ignored). */
    int free_list = -1;
    for (int k = 0; k < TW_HZB_GPU_LISTS; k++)
        if (free_list < 0 || p->lists[k].frame < p->lists[free_list].frame)
            free_list = k;
    p->lists[free_list].frame = fr->v->frame;
    p->lists[free_list].count = 0;
}

/* The GPU's latest verdict on node (cell, level): -1 none in the latest
 * answers (or one on another node of that base: a verdict on a smaller box
 * says nothing of a larger one), 0 hidden, 1 visible. */
static int gpu_verdict(const struct tw_hzb_phases *p, struct tw_cell cell, uint32_t level)
{
    const uint64_t *v = tw_cell_map_find(p->gpu_verdict, cell);
    if (!v || *v >> 1 != level)
        return -1;
    return (int)(*v & 1u);
}

/* Taken (its tile instantiated and its leaves tested): a node the GPU
 * found visible in its latest answers, or did not test, or next to one it
 * found visible (the paper's remedy for late answers, applied to the
 * ring of eight: the nodes of the cut around it). */
static bool gpu_take(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                     uint32_t level)
{
    if (gpu_verdict(p, cell, level) != 0)
        return true;
    size_t n;
    if (tw_cull_neighbours_into(fr->v, fr->g, cell, level, 8, &p->near, &p->near_cap, &n))
        return true;    /* out of memory: taken, which is always safe */
    for (size_t k = 0; k < n; k++)
        if (gpu_verdict(p, p->near[k].cell, p->near[k].level) == 1)
            return true;
    return false;
}

/* The tile's BVH in the frustum and view distance, nearer child first:
 * leaves go to leaf(). */
static void gpu_traverse(struct tw_hzb_phases *p, struct tw_cull_frame *fr,
                         const struct tw_cull_instance *t,
                         void (*leaf)(struct tw_hzb_phases *, struct tw_cull_frame *,
                                      const struct tw_cull_instance *, uint32_t))
{
    const struct tw_view *v = fr->v;
    const struct tw_bvh_node *nodes = t->bvh->nodes;
    if (!tw_cull_frame_reserve(fr, (void **)&p->stack, &p->stack_cap, t->bvh->node_count + 1,
                               sizeof(*p->stack)))
        return;
    size_t top = 0;
    p->stack[top++] = 0;
    while (top > 0 && !fr->err) {
        const uint32_t node = p->stack[--top];
        const struct tw_box *b = &nodes[node].box;
        if (!(tw_cull_box_distance(v, b, t->offset) <= v->view_distance) ||
            tw_cull_frustum_box(&v->frustum, b, t->offset) == TW_CULL_OUTSIDE)
            continue;
        if (nodes[node].child[0] == TW_BVH_NONE) {
            leaf(p, fr, t, node);
            continue;
        }
        uint32_t a = nodes[node].child[0], c = nodes[node].child[1];
        if (c != TW_BVH_NONE &&
            tw_cull_box_distance(v, &nodes[c].box, t->offset) <
                tw_cull_box_distance(v, &nodes[a].box, t->offset)) {
            const uint32_t x = a;
            a = c;
            c = x;
        }
        if (c != TW_BVH_NONE)
            p->stack[top++] = c;
        p->stack[top++] = a;
    }
}

static void phase1_leaf(struct tw_hzb_phases *p, struct tw_cull_frame *fr,
                        const struct tw_cull_instance *t, uint32_t node)
{
    struct tw_hzb_node_state *state = t->state;
    const struct tw_bvh_node *n = &t->bvh->nodes[node];
    if (state[node].visible_frame != p->known || p->known == 0)
        return;
    state[node].drawn_frame = fr->v->frame;
    memcpy(p->render + p->render_count, &t->bvh->cluster_order[n->first_cluster],
           n->cluster_count * sizeof(*p->render));
    p->render_count += n->cluster_count;
}

static void phase2_leaf(struct tw_hzb_phases *p, struct tw_cull_frame *fr,
                        const struct tw_cull_instance *t, uint32_t node)
{
    struct tw_hzb_node_state *state = t->state;
    const struct tw_bvh_node *n = &t->bvh->nodes[node];
    if (n->cluster_count == 0)
        return;
    /* A leaf phase 1 drew is tested too, not drawn again: its answer
     * keeps it in the next phase 1 (niagara's late pass). */
    const bool drawn = state[node].drawn_frame == fr->v->frame;
    state[node].drawn_frame = fr->v->frame;
    const struct tw_box q = tw_cull_query_box(fr->v->eye, &n->box, t->offset);
    const struct tw_hzb_gpu_candidate c = {t->cell, t->level, t->tag, node, GPU_LEAF, false};
    if (!gpu_queue(p, fr, &q, tw_cull_near_box(fr->v, &n->box, t->offset), &c, t->content,
                   t->offset, &t->bvh->cluster_order[n->first_cluster],
                   drawn ? 0 : n->cluster_count))
        fr->err = TW_ERR_NOMEM;
}

/* Phase 1 of a tile on the GPU's answers: its leaves visible in the
 * latest answers that lie in the frustum. Returns how many clusters it
 * drew. */
static uint32_t gpu_draw_last_visible(struct tw_hzb_phases *p, struct tw_cull_frame *fr,
                                      const struct tw_cull_instance *t)
{
    if (!t->bvh || t->bvh->node_count == 0 ||
        !tw_cull_frame_reserve(fr, (void **)&p->render, &p->render_cap,
                               t->bvh->cluster_count + 1, sizeof(*p->render)))
        return 0;
    p->render_count = 0;
    gpu_traverse(p, fr, t, phase1_leaf);
    if (p->render_count > 0)
        fr->be->draw(fr->be->ctx, t->cell, t->content, t->offset, p->render,
                     (uint32_t)p->render_count);
    return (uint32_t)p->render_count;
}

/* Phase 2 on the GPU in a taken cell: every leaf in the frustum that phase
 * 1 did not draw, queued for the GPU's test. */
static void gpu_visit(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                      uint32_t level, float distance, const float off[3])
{
    struct tw_cull_instance t;
    if (!instance(fr, cell, level, distance, off, &t) || !t.bvh || t.bvh->node_count == 0)
        return;
    gpu_traverse(p, fr, &t, phase2_leaf);
}

/* Phase 1: last frame's visible tiles still in view, front to back, each
 * drawing its clusters visible last frame. Returns how many clusters were
 * drawn. */
static uint32_t phase1(struct tw_hzb_phases *p, struct tw_cull_frame *fr)
{
    const size_t n = last_in_view(p, fr);
    p->last_count = n;  /* on the GPU the list stays until new answers come */
    uint32_t drawn = 0;
    for (size_t k = 0; k < n && !fr->err; k++) {
        const struct tw_cell cell = p->last[k].cell;
        float off[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        struct tw_cull_instance t;
        uint32_t c = 0;
        if (instance(fr, cell, p->last[k].level, p->last[k].distance, off, &t))
            c = p->gpu ? gpu_draw_last_visible(p, fr, &t)
                       : tw_hzb_draw_last_visible(p->hzb, fr->v, fr->be, &t);
        if (c > 0)
            fr->st->tiles_visible++;
        drawn += c;
        set_verdict(p, fr, cell, HZ_PHASE1 | (c > 0 ? HZ_DREW1 : 0));
    }
    return drawn;
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
    const struct tw_query_backend *be = fr->be;
    p->gpu = be->gpu_hzb_build && be->gpu_hzb_candidate && be->gpu_hzb_test &&
             be->gpu_hzb_results && fr->cache;
    if (p->gpu) {
        gpu_apply(p, fr);
        const uint32_t drawn = fr->err ? 0 : phase1(p, fr);
        if (!fr->err) {
            const double t0 = tw_clock_monotonic_ms();
            be->gpu_hzb_build(be->ctx, p, f);
            fr->st->ms_hzb_build += tw_clock_monotonic_ms() - t0;
        }
        return drawn;
    }
    const uint32_t drawn = phase1(p, fr);
    if (!fr->err)
        pyramid(p, fr, drawn > 0);
    return drawn;
}

bool tw_hzb_phases_decide(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                          uint32_t level, const float off[3], bool free_pass, uint64_t *prev)
{
    const uint64_t f = fr->v->frame;
    const uint64_t old = tw_hzb_phases_verdict(p, cell);
    const struct tw_box box = tw_cull_node_box(fr->g, level);
    if (p->gpu) {
        /* The GPU tests the common box; the cell is taken on its latest
         * answers (gpu_take), its box's answer applies to later frames. */
        fr->st->tiles_queried++;
        const bool taken = free_pass || gpu_take(p, fr, cell, level);
        /* A cell not taken whose tile is at hand anyway has its leaves
         * tested all the same (nothing requested, nothing waited for):
         * late answers then cost only tiles never loaded. */
        bool resident = false;
        if (!taken) {
            struct tw_cull_tile tile;
            const float dist = tw_cull_box_distance(fr->v, &box, off);
            if (fr->g->source.get(fr->g->source.ctx, cell, level, dist,
                                  fr->source_flags | TW_TILE_SOURCE_RESIDENT |
                                      TW_TILE_SOURCE_QUIET,
                                  &tile) == TW_OK) {
                resident = true;
                tile.level = level;
                struct tw_cull_instance t;
                bool created;
                if (tile.proto && tile.bvh && tile.bvh->node_count > 0 &&
                    tw_cull_frame_instance(fr, cell, &tile, off, tw_hzb_state_bytes(tile.bvh), &t,
                                           &created))
                    gpu_traverse(p, fr, &t, phase2_leaf);
            }
        }
        const struct tw_box q = tw_cull_query_box(fr->v->eye, &box, off);
        const struct tw_hzb_gpu_candidate c = {
            cell, level, 0, 0, taken || resident ? GPU_CELL_TAKEN : GPU_CELL_NOT_TAKEN,
            tw_cull_frustum_box(&fr->v->frustum, &box, off) == TW_CULL_INSIDE};
        if (!gpu_queue(p, fr, &q, tw_cull_near_box(fr->v, &box, off), &c, 0, off, NULL, 0))
            fr->err = TW_ERR_NOMEM;
        const bool this_frame = old >> HZ_SHIFT == f;
        *prev = this_frame ? old : 0;
        set_verdict(p, fr, cell, (*prev & (HZ_PHASE1 | HZ_DREW1)) | HZ_TESTED |
                                     (taken ? HZ_VISIBLE : 0));
        return taken;
    }
    bool visible = true;
    if (!free_pass) {
        fr->st->tiles_queried++;
        fr->st->hzb_boxes++;
        visible = tw_hzb_visible(p->hzb, fr->v, &box, off);
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
                         uint32_t level, float distance, const float off[3], uint64_t prev)
{
    if (p->gpu) {
        gpu_visit(p, fr, cell, level, distance, off);
        return;
    }
    struct tw_cull_instance t;
    struct tw_hzb_node_state *state = instance(fr, cell, level, distance, off, &t);
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
        p->next[p->next_count++] = (struct tw_cull_cell){cell, distance, level};
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
        const uint32_t level = p->next[k].level;
        struct tw_cull_tile tile;
        struct tw_tile_handle h;
        const struct tw_tile_info *info;
        /* The tile was at hand a moment ago: never wait, never request. */
        if (g->source.get(g->source.ctx, cell, level, tw_cull_frame_cell_distance(fr, cell, level),
                          fr->source_flags | TW_TILE_SOURCE_RESIDENT | TW_TILE_SOURCE_QUIET,
                          &tile) != TW_OK ||
            !tile.proto || !tw_tile_cache_find(fr->cache, cell, &h) ||
            !(info = tw_tile_cache_info(fr->cache, h)) || info->prototype != tile.key) {
            p->next[n++] = p->next[k];    /* kept: the next phase 1 sorts it out */
            continue;
        }
        struct tw_cull_instance t = {
            .cell = cell, .level = level, .content = tile.content, .proto = tile.proto, .bvh = tile.bvh,
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
    if (p->gpu) {
        /* The answers the method decided with are a frame old or more: a
         * cell its choice did not reach (tilequery+hzb's propagation
         * stopped short of it) still has its box tested, and its tile's
         * leaves where the tile is at hand, so that nothing visible now
         * waits for an answer. */
        int err = fr->err ? fr->err : tw_cull_cells_of_frame(fr->cells, fr->v, fr->g);
        for (size_t k = 0; !err && k < fr->cells->count && !fr->err; k++) {
            const struct tw_cull_cell *c = &fr->cells->cells[k];
            if (tw_hzb_phases_reached(p, fr, c->cell))
                continue;
            float off[3];
            uint64_t prev;
            tw_tiles_cell_offset(c->cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1],
                                 off);
            const struct tw_box box = tw_cull_node_box(fr->g, c->level);
            if (tw_hzb_phases_decide(p, fr, c->cell, c->level, off,
                                     tw_cull_near_box(fr->v, &box, off), &prev))
                gpu_visit(p, fr, c->cell, c->level, c->distance, off);
        }
        if (err)
            fr->err = err;
        /* The GPU tests and draws; its answers make a later phase 1. */
        if (!fr->err)
            fr->be->gpu_hzb_test(fr->be->ctx);
        return fr->err;
    }
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
        const struct tw_cull_cell *c = &cells->cells[k];
        float off[3];
        tw_tiles_cell_offset(c->cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        const struct tw_box box = tw_cull_node_box(fr->g, c->level);
        uint64_t prev;
        if (tw_hzb_phases_decide(p, fr, c->cell, c->level, off, tw_cull_near_box(fr->v, &box, off),
                                 &prev))
            tw_hzb_phases_visit(p, fr, c->cell, c->level, c->distance, off, prev);
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
