/*
 * CHC++ inside one tile (DESIGN.md §7, after Mattausch, Bittner, Wimmer 2008,
 * "CHC++: Coherent Hierarchical Culling Revisited"): the engine and its
 * traversal, front to back, with passes suspended where they would block.
 * Issuing queries, reading their results and the costs that decide what is
 * worth a query are in chc-queries.c.
 *
 * One engine serves every tile of a frame. Per-node state lives with the tile
 * instance (struct tw_chc_node_state); the engine only holds queues and
 * scratch arrays, reserved once per traversal from the BVH's size so that the
 * traversal itself never allocates, and kept (grown geometrically) so that a
 * warm engine does not allocate at all.
 */
#include "cull/chc-private.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DEFAULT_BATCH_SIZE 50
#define DEFAULT_ASSUMED_VISIBLE 8

void tw_chc_default_settings(struct tw_chc_settings *s)
{
    if (!s)
        return;
    if (s->batch_size == 0)
        s->batch_size = DEFAULT_BATCH_SIZE;
    if (s->assumed_visible == 0)
        s->assumed_visible = DEFAULT_ASSUMED_VISIBLE;
    if (s->suspended_passes == 0)
        s->suspended_passes = 1;
}

size_t tw_chc_state_bytes(const struct tw_bvh *bvh)
{
    return bvh ? (size_t)bvh->node_count * sizeof(struct tw_chc_node_state) : 0;
}

void tw_chc_state_init(struct tw_chc_node_state *state, const struct tw_bvh *bvh,
                       uint64_t frame)
{
    if (!state || !bvh)
        return;
    for (uint32_t n = 0; n < bvh->node_count; n++) {
        /* Visible last frame and due now; next_query_frame 0 also marks "not
         * scheduled yet", so the first positive query spreads the leaf's
         * re-queries with a random offset. */
        state[n].visible_frame = frame > 0 ? frame - 1 : 0;
        state[n].next_query_frame = 0;
        state[n].invisible_frames = 0;
        state[n].pending_query = 0;
    }
}

int tw_chc_create(const struct tw_chc_settings *settings, struct tw_chc **out)
{
    if (!out)
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_chc_settings s = {0};
    if (settings)
        s = *settings;
    tw_chc_default_settings(&s);
    if (s.suspended_passes > TW_CHC_MAX_SUSPENDED)
        return TW_ERR_INVALID;
    struct tw_chc *chc = calloc(1, sizeof(*chc));
    if (!chc)
        return TW_ERR_NOMEM;
    chc->settings = s;
    chc->rng = s.seed;
    *out = chc;
    return TW_OK;
}

static void free_queues(struct queues *q)
{
    free(q->heap);
    free(q->iqueue);
    free(q->vqueue);
    free(q->iqueries);
    free(q->query_nodes);
    free(q->vqueries);
    free(q->render);
    free(q->cluster_stamp);
    free(q->boxes);
    free(q->group_len);
}

static size_t queues_bytes(const struct queues *q)
{
    return q->heap_cap * sizeof(*q->heap) + q->iqueue_cap * sizeof(*q->iqueue) +
           q->vqueue_cap * sizeof(*q->vqueue) + q->iq_cap * sizeof(*q->iqueries) +
           q->query_node_cap * sizeof(*q->query_nodes) + q->vq_cap * sizeof(*q->vqueries) +
           q->render_cap * sizeof(*q->render) + q->stamp_cap * sizeof(*q->cluster_stamp) +
           q->box_cap * sizeof(*q->boxes) + q->group_cap * sizeof(*q->group_len);
}

void tw_chc_destroy(struct tw_chc *chc)
{
    if (!chc)
        return;
    free_queues(&chc->q);
    for (uint32_t k = 0; k < chc->slot_count; k++) {
        free_queues(&chc->slots[k]->q);
        free(chc->slots[k]);
    }
    free(chc->slots);
    free(chc->deferred);
    free(chc);
}

const struct tw_chc_stats *tw_chc_stats(const struct tw_chc *chc)
{
    return &chc->stats;
}

void tw_chc_set_costs(struct tw_chc *chc, const struct tw_cost_model *costs)
{
    if (!chc)
        return;
    if (costs && costs->query > 0.0f && isfinite(costs->query) && !chc->settings.no_cost_model) {
        chc->costs = *costs;
        chc->model = true;
    } else {
        memset(&chc->costs, 0, sizeof(chc->costs));
        chc->model = false;
    }
}

size_t tw_chc_bytes(const struct tw_chc *chc)
{
    if (!chc)
        return 0;
    size_t bytes = sizeof(*chc) + queues_bytes(&chc->q) +
                   chc->deferred_cap * sizeof(*chc->deferred);
    bytes += chc->slot_cap * sizeof(*chc->slots);
    for (uint32_t k = 0; k < chc->slot_count; k++)
        bytes += sizeof(*chc->slots[k]) + queues_bytes(&chc->slots[k]->q);
    return bytes;
}

/* Visible last frame. visible_frame == frame counts too (already visible this
 * frame): such a node is treated as known visible, never re-queried. At frame
 * 1 a zeroed state reads as visible at frame 0, i.e. first sight: conservative. */
static bool was_visible(const struct tw_chc_node_state *s, uint64_t frame)
{
    return s->visible_frame + 1 >= frame;
}

/* ---- traversal queue ---------------------------------------------------------- */

static void heap_push(struct tw_chc *chc, float distance, uint32_t node)
{
    assert(chc->q.heap_count < chc->q.heap_cap);
    tw_distance_push(chc->q.heap, &chc->q.heap_count, distance, node);
}

static uint32_t heap_pop(struct tw_chc *chc)
{
    return tw_distance_pop(chc->q.heap, &chc->q.heap_count);
}

/* Queues node for traversal unless it is outside the frustum or beyond the
 * view distance: such nodes are neither drawn nor queried. */
static void push_node(struct pass *p, uint32_t node)
{
    const struct tw_box *b = &p->nodes[node].box;
    const float d = tw_cull_box_distance(p->v, b, p->tile->offset);
    if (!(d <= p->v->view_distance))
        return;
    if (tw_cull_frustum_box(&p->v->frustum, b, p->tile->offset) == TW_CULL_OUTSIDE)
        return;
    heap_push(p->chc, d, node);
}

void tw_chc_push_children(struct pass *p, uint32_t node)
{
    for (int k = 0; k < 2; k++)
        if (p->nodes[node].child[k] != TW_BVH_NONE)
            push_node(p, p->nodes[node].child[k]);
}

/* ---- rendering ------------------------------------------------------------------ */

/* Queues the leaf's clusters, skipping those already queued in this traversal
 * (a cluster may be referenced by several leaves). */
void tw_chc_draw_leaf(struct pass *p, uint32_t node)
{
    struct tw_chc *chc = p->chc;
    const struct tw_bvh_node *n = &p->nodes[node];
    for (uint32_t k = 0; k < n->cluster_count; k++) {
        const uint32_t c = p->bvh->cluster_order[n->first_cluster + k];
        assert(c < chc->q.stamp_cap);
        if (c >= chc->q.stamp_cap || chc->q.cluster_stamp[c] == chc->q.stamp)
            continue;
        chc->q.cluster_stamp[c] = chc->q.stamp;
        chc->q.render[chc->q.render_count++] = c;
        chc->stats.clusters_drawn++;
    }
}

void tw_chc_flush_render(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    if (chc->q.render_count == 0)
        return;
    p->be->draw(p->be->ctx, p->tile->cell, p->tile->content, p->tile->offset, chc->q.render,
                (uint32_t)chc->q.render_count);
    chc->q.render_count = 0;
    chc->unflushed = true;
}

void tw_chc_flush_gpu(struct pass *p)
{
    if (!p->chc->unflushed || p->chc->wavefront)
        return;
    p->be->flush(p->be->ctx);
    p->chc->unflushed = false;
}

/* ---- traversal ------------------------------------------------------------------ */

static void process_node(struct pass *p, uint32_t node)
{
    struct tw_chc *chc = p->chc;
    const struct tw_bvh_node *n = &p->nodes[node];
    struct tw_chc_node_state *s = &p->state[node];
    const bool leaf = is_leaf(n);

    /* A box the near plane may cut can answer 0 samples and lie: never query
     * it, treat it as visible. */
    if (tw_cull_near_box(p->v, &n->box, p->tile->offset)) {
        if (leaf) {
            tw_chc_draw_leaf(p, node);
            pull_up(p->state, p->nodes, node, p->frame);
        } else {
            tw_chc_push_children(p, node);
        }
        return;
    }
    const struct tw_cost_model *c = &chc->costs;
    float alone = 1.0f, group = 0.0f, pixels = 0.0f;
    if (chc->model) {
        /* What a query of this node would cost: its fixed part, its boxes
         * beyond the first and the pixels they cover. */
        uint32_t boxes = 1;
        tw_chc_tight_boxes(p, node, &boxes);
        pixels = tw_chc_box_pixels(p, node);
        group = (float)boxes * c->query_box + pixels * c->query_pixel;
        alone = c->query + group - c->query_box;
    }
    /* A leaf no query has found visible (next_query_frame 0: first sight,
     * or only ever drawn by the near-plane rule) is asked before it is
     * drawn: a new tile's interior nodes are taken as visible, so this costs
     * one round trip for the tile, not one per level, and its hidden leaves
     * are not drawn. */
    const bool unproven =
        leaf && s->next_query_frame == 0 && !chc->settings.first_sight_draws;
    if (was_visible(s, p->frame) && !unproven) {
        if (!leaf) {
            tw_chc_push_children(p, node);
            return;
        }
        tw_chc_draw_leaf(p, node);
        if (s->pending_query == 0 && s->next_query_frame <= p->frame) {
            /* A re-query can pay only if what a hidden answer may save
             * over the next n_av frames, weighted by the measured chance of
             * that answer, exceeds it: a hidden leaf lets its parent be
             * found hidden too and culled whole, so the saving is counted
             * at the parent. */
            const uint32_t up = n->parent != TW_BVH_NONE ? n->parent : node;
            const float n_av = (float)(chc->settings.assumed_visible + 1);
            if (!chc->model ||
                tw_chc_vquery_hidden_rate(chc) * n_av *
                        tw_chc_draw_cost(c, &p->nodes[up], tw_chc_box_pixels(p, up)) >
                    c->query + group - c->query_box ||
                next_random(chc) % VQ_EXPLORE == 0) {
                chc->q.vqueue[chc->q.vqueue_head + chc->q.vqueue_count++] = node;
                return;
            }
            chc->stats.queries_skipped++;
            s->next_query_frame = p->frame + 1 + chc->settings.assumed_visible;
        }
        pull_up(p->state, p->nodes, node, p->frame);
        return;
    }
    /* Whether it pays to ask is decided with its batch (issue_iqueue). */
    const float saving = chc->model ? (float)tw_chc_keep_chance(chc, s->invisible_frames) *
                                          tw_chc_draw_cost(c, n, pixels)
                                    : 0.0f;
    chc->q.iqueue[chc->q.iqueue_count++] =
        (struct iqueue_item){node, s->invisible_frames, p->iqueue_seq++, group, alone, saving};
    if (chc->q.iqueue_count >= chc->settings.batch_size)
        tw_chc_issue_iqueue(p);
}

/* Reserves every queue for the worst case of this BVH, so that the traversal
 * cannot fail half way: each node is pushed once, issued at most once as an
 * I-query plus once as a re-query, or once as a V-query. */
static bool reserve_pass(struct tw_chc *chc, const struct tw_cull_instance *tile)
{
    const size_t nodes = tile->bvh->node_count;
    size_t clusters = tile->bvh->cluster_count;
    if (tile->proto && tile->proto->cluster_count > clusters)
        clusters = tile->proto->cluster_count;
    const bool ok =
        tw_cull_reserve((void **)&chc->q.heap, &chc->q.heap_cap, nodes, sizeof(*chc->q.heap)) &&
        tw_cull_reserve((void **)&chc->q.iqueue, &chc->q.iqueue_cap, nodes, sizeof(*chc->q.iqueue)) &&
        tw_cull_reserve((void **)&chc->q.vqueue, &chc->q.vqueue_cap, nodes, sizeof(*chc->q.vqueue)) &&
        tw_cull_reserve((void **)&chc->q.iqueries, &chc->q.iq_cap, 2 * nodes, sizeof(*chc->q.iqueries)) &&
        tw_cull_reserve((void **)&chc->q.query_nodes, &chc->q.query_node_cap, 2 * nodes,
                sizeof(*chc->q.query_nodes)) &&
        tw_cull_reserve((void **)&chc->q.vqueries, &chc->q.vq_cap, nodes, sizeof(*chc->q.vqueries)) &&
        tw_cull_reserve((void **)&chc->q.render, &chc->q.render_cap, clusters, sizeof(*chc->q.render)) &&
        tw_cull_reserve((void **)&chc->q.cluster_stamp, &chc->q.stamp_cap, clusters,
                sizeof(*chc->q.cluster_stamp)) &&
        tw_cull_reserve((void **)&chc->q.boxes, &chc->q.box_cap, nodes, sizeof(*chc->q.boxes)) &&
        tw_cull_reserve((void **)&chc->q.group_len, &chc->q.group_cap, nodes,
                        sizeof(*chc->q.group_len));
    if (!ok)
        return false;
    chc->q.heap_count = 0;
    chc->q.iqueue_count = 0;
    chc->q.vqueue_head = chc->q.vqueue_count = 0;
    chc->q.iq_head = chc->q.iq_count = 0;
    chc->q.query_node_count = 0;
    chc->q.vq_head = chc->q.vq_count = 0;
    chc->q.render_count = 0;
    if (++chc->q.stamp == 0) {
        memset(chc->q.cluster_stamp, 0, chc->q.stamp_cap * sizeof(*chc->q.cluster_stamp));
        chc->q.stamp = 1;
    }
    return true;
}

/* Out of memory: draw every leaf in view, no queries, state untouched.
 * Conservative, slow, and never taken by a warm engine. */
static void draw_everything(const struct pass *p)
{
    for (uint32_t i = 0; i < p->bvh->node_count; i++) {
        const struct tw_bvh_node *n = &p->nodes[i];
        if (!is_leaf(n) || n->cluster_count == 0)
            continue;
        if (!(tw_cull_box_distance(p->v, &n->box, p->tile->offset) <= p->v->view_distance) ||
            tw_cull_frustum_box(&p->v->frustum, &n->box, p->tile->offset) == TW_CULL_OUTSIDE)
            continue;
        p->be->draw(p->be->ctx, p->tile->cell, p->tile->content, p->tile->offset,
                    &p->bvh->cluster_order[n->first_cluster], n->cluster_count);
        p->chc->stats.clusters_drawn += n->cluster_count;
        p->chc->unflushed = true;
    }
}

/* Runs a pass until it is done (true) or, with may_suspend, until it would
 * block on an I-query with nothing else left to do (false: the caller
 * resumes it later, after giving the GPU other tiles' work). */
static bool run_pass(struct pass *p, bool may_suspend)
{
    struct tw_chc *chc = p->chc;
    const struct tw_query_backend *be = p->be;
    while (chc->q.heap_count > 0 || chc->q.iqueue_count > 0 || chc->q.iq_count > 0) {
        /* Read the I-queries whose results are in; block only when there is
         * nothing left to traverse, and spend that time on V-queries first. */
        while (chc->q.iq_count > 0) {
            const struct iquery q = chc->q.iqueries[chc->q.iq_head];
            if (!be->ready(be->ctx, q.handle)) {
                if (chc->q.heap_count > 0)
                    break;
                if (chc->q.iqueue_count > 0) {
                    tw_chc_issue_iqueue(p);
                    continue;
                }
                if (chc->q.vqueue_count > 0) {
                    /* In wavefront mode the V-queries go with the wavefront's
                     * flush, all at once. */
                    do {
                        chc->q.vqueue_count--;
                        tw_chc_issue_vquery(p, chc->q.vqueue[chc->q.vqueue_head++]);
                    } while (chc->wavefront && chc->q.vqueue_count > 0);
                    tw_chc_flush_gpu(p);
                    continue;
                }
                /* Give the GPU what was traversed before blocking on it,
                 * or before leaving it to the next tile. */
                tw_chc_flush_render(p);
                tw_chc_flush_gpu(p);
                /* In wavefront mode only a query sent by the caller's last
                 * flush is waited on (a batched read); any other waits for
                 * the next one. */
                if (may_suspend && !(chc->wavefront && q.flush < chc->flushes))
                    return false;
                chc->stats.waits++;
            }
            chc->q.iq_head++;
            chc->q.iq_count--;
            tw_chc_handle_iquery(p, &q, be->wait(be->ctx, q.handle));
        }
        tw_chc_poll_vqueries(p);

        if (chc->q.heap_count > 0)
            process_node(p, heap_pop(chc));
        if (chc->q.heap_count == 0 && chc->q.iqueue_count > 0)
            tw_chc_issue_iqueue(p);
    }
    return true;
}

/* A done pass: its render queue drawn, its V-queries issued; those still in
 * flight are read by the next frame's tw_chc_begin_frame() (or now, if there
 * is no memory to keep them). */
static void end_pass(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    tw_chc_flush_render(p);
    if (chc->q.vqueue_count > 0) {
        while (chc->q.vqueue_count > 0) {
            chc->q.vqueue_count--;
            tw_chc_issue_vquery(p, chc->q.vqueue[chc->q.vqueue_head++]);
        }
        tw_chc_flush_gpu(p);
    }
    tw_chc_poll_vqueries(p);
    if (!tw_cull_reserve((void **)&chc->deferred, &chc->deferred_cap,
                         chc->deferred_count + chc->q.vq_count, sizeof(*chc->deferred))) {
        while (chc->q.vq_count > 0)
            tw_chc_read_vquery(p);
    }
    for (size_t k = 0; k < chc->q.vq_count; k++) {
        const struct vquery *q = &chc->q.vqueries[chc->q.vq_head + k];
        chc->deferred[chc->deferred_count++] =
            (struct deferred_vquery){p->tile->tag, p->frame, q->node, q->handle};
    }
    chc->q.vq_head = chc->q.vq_count = 0;
}

/* Starts a pass over tile in chc->q; false when out of memory (then the tile
 * was drawn whole, and there is nothing to run). */
static bool start_pass(struct pass *p, struct tw_chc *chc, const struct tw_view *v,
                       const struct tw_query_backend *be, const struct tw_cull_instance *tile)
{
    *p = (struct pass){
        .chc = chc, .v = v, .be = be, .tile = tile, .bvh = tile->bvh,
        .nodes = tile->bvh->nodes, .state = tile->state, .frame = v->frame,
    };
    if (!reserve_pass(chc, tile)) {
        draw_everything(p);
        return false;
    }
    push_node(p, 0);
    return true;
}

static bool usable(const struct tw_chc *chc, const struct tw_view *v,
                   const struct tw_query_backend *be, const struct tw_cull_instance *tile)
{
    return chc && v && be && tile && tile->bvh && tile->state && tile->bvh->node_count > 0;
}

/* Makes slot k the running pass (its queues in chc->q) or puts it back. */
static void swap_queues(struct tw_chc *chc, uint32_t k)
{
    const struct queues t = chc->q;
    chc->q = chc->slots[k]->q;
    chc->slots[k]->q = t;
}

/* Resumes suspended pass k; block: runs it to its end. Frees the slot when
 * the pass is done. */
static void resume(struct tw_chc *chc, uint32_t k, bool block)
{
    struct suspended *sl = chc->slots[k];
    swap_queues(chc, k);
    if (run_pass(&sl->pass, !block)) {
        end_pass(&sl->pass);
        sl->active = false;
    }
    swap_queues(chc, k);
}

/* The suspended pass started first (the nearest tile's) of those not
 * resumed in round (0: any), or chc->slot_count when there is none. */
static uint32_t oldest_suspended(const struct tw_chc *chc, uint64_t round)
{
    uint32_t oldest = chc->slot_count;
    for (uint32_t k = 0; k < chc->slot_count; k++) {
        const struct suspended *sl = chc->slots[k];
        if (sl->active && (round == 0 || sl->resumed != round) &&
            (oldest == chc->slot_count || sl->started < chc->slots[oldest]->started))
            oldest = k;
    }
    return oldest;
}

/* A slot for one more suspended pass, allocated if there are fewer than
 * want; chc->slot_count when there is no memory for it. */
static uint32_t new_slot(struct tw_chc *chc, uint32_t want)
{
    if (chc->slot_count >= want)
        return chc->slot_count;
    if (chc->slot_count == chc->slot_cap) {
        const uint32_t cap = chc->slot_cap ? 2 * chc->slot_cap : TW_CHC_MAX_SUSPENDED;
        struct suspended **s = realloc(chc->slots, cap * sizeof(*s));
        if (!s)
            return chc->slot_count;
        chc->slots = s;
        chc->slot_cap = cap;
    }
    struct suspended *sl = calloc(1, sizeof(*sl));
    if (!sl)
        return chc->slot_count;
    chc->slots[chc->slot_count] = sl;
    return chc->slot_count++;
}

void tw_chc_traverse(struct tw_chc *chc, const struct tw_view *v,
                     const struct tw_query_backend *be, const struct tw_cull_instance *tile)
{
    if (!usable(chc, v, be, tile))
        return;
    struct pass p;
    if (!start_pass(&p, chc, v, be, tile))
        return;
    run_pass(&p, false);
    end_pass(&p);
}

void tw_chc_traverse_async(struct tw_chc *chc, const struct tw_view *v,
                           const struct tw_query_backend *be, const struct tw_cull_instance *tile)
{
    if (!usable(chc, v, be, tile))
        return;
    const uint32_t limit = chc->wavefront ? UINT32_MAX : chc->settings.suspended_passes;
    /* Give the suspended passes what has come back (in wavefront mode that
     * is tw_chc_resume_flushed's); the oldest is finished when every slot is
     * taken. */
    uint32_t free_slot = chc->slot_count;
    for (uint32_t k = 0; k < chc->slot_count && k < limit; k++) {
        if (chc->slots[k]->active && !chc->wavefront)
            resume(chc, k, false);
        if (!chc->slots[k]->active && free_slot == chc->slot_count)
            free_slot = k;
    }
    if (free_slot == chc->slot_count)
        free_slot = new_slot(chc, limit);
    if (free_slot == chc->slot_count) {
        free_slot = oldest_suspended(chc, 0);
        if (free_slot == chc->slot_count) {
            /* No slot at all (out of memory): the pass runs to its end. */
            tw_chc_traverse(chc, v, be, tile);
            return;
        }
        resume(chc, free_slot, true);
    }
    struct suspended *sl = chc->slots[free_slot];
    sl->tile = *tile;
    swap_queues(chc, free_slot);
    if (start_pass(&sl->pass, chc, v, be, &sl->tile)) {
        if (run_pass(&sl->pass, true)) {
            end_pass(&sl->pass);
        } else {
            sl->active = true;
            sl->started = ++chc->passes_started;
            chc->stats.suspended++;
        }
    }
    swap_queues(chc, free_slot);
}

void tw_chc_finish(struct tw_chc *chc)
{
    if (!chc)
        return;
    /* Oldest first: the nearer tiles' passes, started first. */
    for (uint32_t k = oldest_suspended(chc, 0); k < chc->slot_count;
         k = oldest_suspended(chc, 0))
        resume(chc, k, true);
}

void tw_chc_set_wavefront(struct tw_chc *chc, bool on)
{
    if (chc)
        chc->wavefront = on;
}

bool tw_chc_resume_flushed(struct tw_chc *chc)
{
    if (!chc)
        return false;
    chc->flushes++;
    chc->unflushed = false;
    const uint64_t round = ++chc->rounds;
    bool more = false;
    for (uint32_t k = oldest_suspended(chc, round); k < chc->slot_count;
         k = oldest_suspended(chc, round)) {
        chc->slots[k]->resumed = round;
        resume(chc, k, false);
        more = more || chc->slots[k]->active;
    }
    return more;
}

void tw_chc_begin_frame(struct tw_chc *chc, const struct tw_view *v,
                        const struct tw_query_backend *be, tw_chc_resolve_fn resolve,
                        void *resolve_user)
{
    if (!chc)
        return;
    for (uint32_t k = 0; k < chc->slot_count; k++)
        assert(!chc->slots[k]->active && "tw_chc_finish() was not called at the end of a frame");
    memset(&chc->stats, 0, sizeof(chc->stats));
    if (!be) {
        chc->deferred_count = 0;
        return;
    }
    (void)v;
    for (size_t k = 0; k < chc->deferred_count; k++) {
        const struct deferred_vquery *d = &chc->deferred[k];
        /* Every query is read exactly once, even if its tile is gone. */
        if (!be->ready(be->ctx, d->handle))
            chc->stats.waits++;
        const uint32_t samples = be->wait(be->ctx, d->handle);
        const struct tw_bvh *bvh = NULL;
        struct tw_chc_node_state *state = resolve ? resolve(resolve_user, d->tag, &bvh) : NULL;
        if (!state || !bvh || d->node >= bvh->node_count ||
            state[d->node].pending_query != d->handle)
            continue;
        state[d->node].pending_query = 0;
        tw_chc_apply_vquery(chc, state, bvh->nodes, d->node, samples > chc->settings.threshold,
                            d->frame);
    }
    chc->deferred_count = 0;
}
