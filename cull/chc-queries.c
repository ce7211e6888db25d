/*
 * CHC++'s queries (DESIGN.md §7): the I-queue issued in batches of
 * multiqueries, V-queries on visible leaves, their results read back, and
 * the cost model (DESIGN §14) that decides which queries are worth issuing.
 */
#include "cull/chc-private.h"

#include <assert.h>
#include <math.h>
#include <string.h>

/* Chance that a node found invisible for i frames in a row stays invisible. */
static double keep_probability(uint32_t invisible_frames)
{
    return 0.99 - 0.7 * exp(-(double)invisible_frames);
}

/* The answers the paper's p(i) weighs as, before the measured ones. */
#define KEEP_PRIOR 20.0

static uint32_t keep_bucket(uint32_t invisible_frames)
{
    return invisible_frames < KEEP_BUCKETS - 1 ? invisible_frames : KEEP_BUCKETS - 1;
}

/* The chance that a node hidden for invisible_frames frames is hidden again:
 * with the cost model, as measured on this traversal's answers (from p(i),
 * as strong as KEEP_PRIOR answers); without, the paper's p(i). */
double tw_chc_keep_chance(const struct tw_chc *chc, uint32_t invisible_frames)
{
    const double prior = keep_probability(invisible_frames);
    if (!chc->model)
        return prior;
    const uint32_t b = keep_bucket(invisible_frames);
    return (chc->iq_hidden[b] + KEEP_PRIOR * prior) / (chc->iq_answers[b] + KEEP_PRIOR);
}

/* One I-query answer about a node hidden for invisible_frames frames. */
static void count_keep(struct tw_chc *chc, uint32_t invisible_frames, bool hidden)
{
    const uint32_t b = keep_bucket(invisible_frames);
    chc->iq_answers[b] = chc->iq_answers[b] * KEEP_DECAY + 1.0;
    chc->iq_hidden[b] = chc->iq_hidden[b] * KEEP_DECAY + (hidden ? 1.0 : 0.0);
}

/* ---- the cost model (DESIGN §14) ---------------------------------------------------- */

/* The pixels of the screen rectangle of node's box: what its query, or
 * drawing it, can touch at most. */
float tw_chc_box_pixels(const struct pass *p, uint32_t node)
{
    return p->chc->costs.screen_pixels *
           tw_cull_box_screen_fraction(p->v, &p->nodes[node].box, p->tile->offset);
}

/* Drawing a node whole when it turns out hidden, its box covering pixels: a
 * draw per cluster of its leaves, its triangles, and those pixels,
 * depth-tested (the calibration's figures are those of a hidden cluster: a
 * visible one costs the same queried or not). A node found cheaper to draw
 * than to query has children cheaper still: it is drawn whole. */
float tw_chc_draw_cost(const struct tw_cost_model *c, const struct tw_bvh_node *n, float pixels)
{
    return (float)n->cluster_total * c->draw + (float)n->triangle_count * c->triangle +
           pixels * c->draw_pixel;
}

/* About the last thousand V-query answers count. */
#define VQ_DECAY 0.999

/* The chance that a re-query finds a visible leaf hidden: the measured rate,
 * from a prior of one hidden answer in two. */
float tw_chc_vquery_hidden_rate(const struct tw_chc *chc)
{
    return (float)((chc->vq_hidden + 1.0) / (chc->vq_answers + 2.0));
}

/* The result of a V-query (a leaf drawn because it was visible before),
 * applied as the result of frame. */
void tw_chc_apply_vquery(struct tw_chc *chc, struct tw_chc_node_state *state,
                         const struct tw_bvh_node *nodes, uint32_t node, bool visible,
                         uint64_t frame)
{
    struct tw_chc_node_state *s = &state[node];
    chc->vq_answers = chc->vq_answers * VQ_DECAY + 1.0;
    chc->vq_hidden = chc->vq_hidden * VQ_DECAY + (visible ? 0.0 : 1.0);
    if (!visible) {
        s->invisible_frames = 1;
        return;
    }
    const uint64_t n_av = chc->settings.assumed_visible;
    /* next_query_frame 0: first sight, never scheduled: spread the re-queries
     * of a new tile's leaves over frames instead of repeating them all at once. */
    if (s->next_query_frame == 0)
        s->next_query_frame = frame + 1 + next_random(chc) % (n_av + 1);
    else
        s->next_query_frame = frame + 1 + n_av;
    pull_up(state, nodes, node, frame);
}

/* ---- issuing queries ------------------------------------------------------------ */

const struct tw_box *tw_chc_tight_boxes(const struct pass *p, uint32_t node, uint32_t *count)
{
    const struct tw_bvh_node *n = &p->nodes[node];
    if (p->chc->settings.no_tight_boxes || n->tight_count <= 1 || !p->bvh->tight_boxes ||
        n->first_tight > p->bvh->tight_box_count ||
        n->tight_count > p->bvh->tight_box_count - n->first_tight)
        return NULL;
    *count = n->tight_count;
    return &p->bvh->tight_boxes[n->first_tight];
}

/* Issues one query drawing the boxes of count nodes (a multiquery if more
 * than one) and returns its handle. */
static uint32_t issue_nodes(struct pass *p, const uint32_t *list, uint32_t count)
{
    struct tw_chc *chc = p->chc;
    size_t need = 0;
    for (uint32_t k = 0; k < count; k++) {
        uint32_t tc = 1;
        tw_chc_tight_boxes(p, list[k], &tc);
        need += tc;
    }
    /* Room for one box per node is reserved before the traversal; if tight
     * lists do not fit and cannot grow, node boxes still give a correct query. */
    const bool tight =
        tw_cull_reserve((void **)&chc->q.boxes, &chc->q.box_cap, need, sizeof(*chc->q.boxes));
    size_t nb = 0;
    for (uint32_t k = 0; k < count; k++) {
        uint32_t tc = 1;
        const struct tw_box *tb = tight ? tw_chc_tight_boxes(p, list[k], &tc) : NULL;
        if (tb) {
            memcpy(&chc->q.boxes[nb], tb, tc * sizeof(*tb));
            nb += tc;
        } else {
            chc->q.boxes[nb++] = p->nodes[list[k]].box;
        }
    }
    const uint32_t handle = p->be->issue(p->be->ctx, chc->q.boxes, (uint32_t)nb, p->tile->offset);
    chc->unflushed = true;
    assert(handle != 0);
    for (uint32_t k = 0; k < count; k++)
        p->state[list[k]].pending_query = handle;
    chc->stats.queries++;
    chc->stats.nodes_queried += count;
    if (count > 1)
        chc->stats.multiqueries++;
    return handle;
}

static void issue_iquery(struct pass *p, size_t first, uint32_t count)
{
    struct tw_chc *chc = p->chc;
    const uint32_t handle = issue_nodes(p, &chc->q.query_nodes[first], count);
    assert(chc->q.iq_head + chc->q.iq_count < chc->q.iq_cap);
    chc->q.iqueries[chc->q.iq_head + chc->q.iq_count++] = (struct iquery){handle, count, first, chc->flushes};
}

static bool iqueue_before(const struct iqueue_item *a, const struct iqueue_item *b)
{
    /* p is increasing in invisible_frames: sort by p descending. */
    if (a->invisible_frames != b->invisible_frames)
        return a->invisible_frames > b->invisible_frames;
    return a->seq < b->seq;
}

/* Heapsort (no allocation; keys are unique thanks to seq). */
static void sort_iqueue(struct iqueue_item *a, size_t n)
{
    for (size_t start = n / 2; n > 1;) {
        size_t end = n;
        if (start > 0) {
            start--;
        } else {
            end = --n;
            const struct iqueue_item t = a[0];
            a[0] = a[n];
            a[n] = t;
        }
        /* Sift down within [0, end): the heap's top is the item that comes
         * last, so swapping tops to the back leaves the array in order. */
        size_t i = start;
        for (;;) {
            size_t c = 2 * i + 1;
            if (c >= end)
                break;
            if (c + 1 < end && iqueue_before(&a[c], &a[c + 1]))
                c++;
            if (!iqueue_before(&a[i], &a[c]))
                break;
            const struct iqueue_item t = a[i];
            a[i] = a[c];
            a[c] = t;
            i = c;
        }
    }
}

/* End (exclusive) of the multiquery group that starts at items[i]: grow it
 * while |M| / cost(M) does not fall, with cost(M) = 1 + (1 - prod p) |M| for
 * |M| >= 2. A lone node costs exactly one query (its result is final, no
 * re-query can follow), which keeps nodes likely to turn visible out of groups. */
static size_t group_end(const struct tw_chc *chc, const struct iqueue_item *items, size_t i,
                        size_t n)
{
    if (chc->settings.no_multiqueries)
        return i + 1;
    /* With measured costs, a group is worth what its nodes' own queries
     * would cost, and costs one query of all their boxes plus, with
     * chance 1 - prod p, their own queries again; without, every query is
     * one unit and a node adds nothing to a group's cost. */
    const bool model = chc->model;
    double keep = keep_probability(items[i].invisible_frames);
    double alone = model ? items[i].alone_cost : 1.0;
    double extra = model ? items[i].group_cost : 0.0;
    const double fixed = model ? chc->costs.query : 1.0;
    double value = 1.0;
    size_t j = i + 1;
    while (j < n) {
        const double k = keep * keep_probability(items[j].invisible_frames);
        const double a = alone + (model ? items[j].alone_cost : 1.0);
        const double e = extra + (model ? items[j].group_cost : 0.0);
        const double v = a / (fixed + e + (1.0 - k) * a);
        if (v < value)
            break;
        keep = k;
        alone = a;
        extra = e;
        value = v;
        j++;
    }
    return j;
}

/* A node that the model finds cheaper to draw than to ask about: drawn (or
 * opened) as if visible, never taken as hidden. Nothing was learnt, so
 * nothing is pulled up: its parent may still be found hidden, and queried,
 * whole. */
static void skip_query(struct pass *p, uint32_t node)
{
    p->chc->stats.queries_skipped++;
    if (is_leaf(&p->nodes[node]))
        tw_chc_draw_leaf(p, node);
    else
        tw_chc_push_children(p, node);
}

/* What querying group items[i, j) costs (DESIGN §14): the query of all
 * its boxes and, with the chance that the group comes back visible, its
 * nodes' own queries again; a lone node's answer is final. *saving: what
 * its hidden answers save. */
static double group_cost(const struct tw_chc *chc, const struct iqueue_item *items, size_t i,
                         size_t j, double *saving)
{
    *saving = 0.0;
    for (size_t k = i; k < j; k++)
        *saving += items[k].saving;
    if (j - i == 1)
        return items[i].alone_cost;
    double keep = 1.0, boxes = 0.0, alone = 0.0;
    for (size_t k = i; k < j; k++) {
        keep *= tw_chc_keep_chance(chc, items[k].invisible_frames);
        boxes += items[k].group_cost;
        alone += items[k].alone_cost;
    }
    return chc->costs.query + boxes + (1.0 - keep) * alone;
}

/* Issues the I-queue as multiqueries. With the cost model, a node whose
 * saving is below what it adds to any group (its boxes, and its own query
 * again if the group comes back visible) is drawn instead, and so is a
 * group that does not pay, and the whole batch if what it saves does not
 * pay for sending it and waiting (query_flush): the fixed costs are
 * shared, so the choice is made here and not node by node. What is drawn
 * goes to the GPU before the queries, as an occluder. */
void tw_chc_issue_iqueue(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    struct iqueue_item *items = chc->q.iqueue;
    size_t n = chc->q.iqueue_count;
    if (n == 0)
        return;
    chc->q.iqueue_count = 0;
    if (chc->model) {
        size_t kept = 0;
        for (size_t k = 0; k < n; k++) {
            const double own_again =
                (1.0 - tw_chc_keep_chance(chc, items[k].invisible_frames)) * items[k].alone_cost;
            if (items[k].saving < items[k].group_cost + own_again)
                skip_query(p, items[k].node);
            else
                items[kept++] = items[k];
        }
        n = kept;
    }
    sort_iqueue(items, n);
    size_t groups = 0, queried = 0;
    double batch_saving = 0.0, batch_cost = chc->costs.query_flush;
    for (size_t i = 0; i < n;) {
        const size_t j = group_end(chc, items, i, n);
        double saving = 0.0;
        const double cost = chc->model ? group_cost(chc, items, i, j, &saving) : 0.0;
        if (saving < cost) {
            for (size_t k = i; k < j; k++)
                skip_query(p, items[k].node);
        } else {
            for (size_t k = i; k < j; k++)
                items[queried++] = items[k];
            chc->q.group_len[groups++] = (uint32_t)(j - i);
            batch_saving += saving;
            batch_cost += cost;
        }
        i = j;
    }
    if (chc->model && groups > 0 && batch_saving < batch_cost) {
        for (size_t k = 0; k < queried; k++)
            skip_query(p, items[k].node);
        groups = 0;
    }
    tw_chc_flush_render(p);
    if (groups == 0)
        return;
    for (size_t g = 0, i = 0; g < groups; i += chc->q.group_len[g++]) {
        const size_t first = chc->q.query_node_count;
        assert(first + chc->q.group_len[g] <= chc->q.query_node_cap);
        for (size_t k = i; k < i + chc->q.group_len[g]; k++)
            chc->q.query_nodes[chc->q.query_node_count++] = items[k].node;
        issue_iquery(p, first, chc->q.group_len[g]);
    }
    tw_chc_flush_gpu(p);
}

void tw_chc_issue_vquery(struct pass *p, uint32_t node)
{
    struct tw_chc *chc = p->chc;
    tw_chc_flush_render(p);
    const uint32_t handle = issue_nodes(p, &node, 1);
    assert(chc->q.vq_head + chc->q.vq_count < chc->q.vq_cap);
    chc->q.vqueries[chc->q.vq_head + chc->q.vq_count++] = (struct vquery){handle, node};
}

/* ---- reading results ------------------------------------------------------------ */

void tw_chc_handle_iquery(struct pass *p, const struct iquery *q, uint32_t samples)
{
    struct tw_chc *chc = p->chc;
    const bool visible = samples > chc->settings.threshold;
    if (visible && q->count > 1) {
        /* A failed multiquery: some of its nodes are visible, find out which. */
        tw_chc_flush_render(p);
        for (uint32_t k = 0; k < q->count; k++) {
            const size_t first = chc->q.query_node_count;
            assert(first < chc->q.query_node_cap);
            chc->q.query_nodes[chc->q.query_node_count++] = chc->q.query_nodes[q->first + k];
            issue_iquery(p, first, 1);
            chc->stats.requeries++;
        }
        tw_chc_flush_gpu(p);
        return;
    }
    for (uint32_t k = 0; k < q->count; k++) {
        const uint32_t node = chc->q.query_nodes[q->first + k];
        struct tw_chc_node_state *s = &p->state[node];
        if (s->pending_query == q->handle)
            s->pending_query = 0;
        count_keep(chc, s->invisible_frames, !visible);
        if (!visible) {
            if (s->invisible_frames < UINT32_MAX)
                s->invisible_frames++;
            continue;
        }
        /* Previously invisible, now visible: traverse it this frame. */
        if (is_leaf(&p->nodes[node])) {
            const uint64_t n_av = chc->settings.assumed_visible;
            s->next_query_frame = p->frame + 1 + next_random(chc) % (n_av + 1);
            tw_chc_draw_leaf(p, node);
        } else {
            tw_chc_push_children(p, node);
        }
        pull_up(p->state, p->nodes, node, p->frame);
    }
}

void tw_chc_read_vquery(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    const struct vquery q = chc->q.vqueries[chc->q.vq_head++];
    chc->q.vq_count--;
    const uint32_t samples = p->be->wait(p->be->ctx, q.handle);
    struct tw_chc_node_state *s = &p->state[q.node];
    if (s->pending_query != q.handle)
        return;
    s->pending_query = 0;
    tw_chc_apply_vquery(chc, p->state, p->nodes, q.node, samples > chc->settings.threshold,
                        p->frame);
}

void tw_chc_poll_vqueries(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    while (chc->q.vq_count > 0 && p->be->ready(p->be->ctx, chc->q.vqueries[chc->q.vq_head].handle))
        tw_chc_read_vquery(p);
}
