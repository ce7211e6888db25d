/*
 * CHC++ inside one tile (DESIGN.md §7, after Mattausch, Bittner, Wimmer 2008,
 * "CHC++: Coherent Hierarchical Culling Revisited").
 *
 * One engine serves every tile of a frame. Per-node state lives with the tile
 * instance (struct tw_chc_node_state); the engine only holds queues and
 * scratch arrays, reserved once per traversal from the BVH's size so that the
 * traversal itself never allocates, and kept (grown geometrically) so that a
 * warm engine does not allocate at all.
 *
 * Queues, as in the paper:
 *   heap      the traversal queue, front to back (distance to the node box);
 *   iqueue    previously invisible nodes waiting to be issued as a batch;
 *   vqueue    previously visible leaves due for a re-query, issued while
 *             waiting or when the tile is done;
 *   iqueries  issued I-queries (single or multi), read in issue order;
 *   vqueries  issued V-queries, read when ready or deferred to the next frame;
 *   render    clusters to draw, flushed before every query batch.
 *
 * Each traversal has its own set (struct queues): the running one's in
 * tw_chc.q, and up to TW_CHC_MAX_SUSPENDED more with the passes that
 * tw_chc_traverse_async() suspended where they would have blocked; resuming
 * one swaps its set in.
 */
#include "cull/cull.h"
#include "cull/cull-private.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DEFAULT_BATCH_SIZE 50
#define DEFAULT_ASSUMED_VISIBLE 8

/* A previously invisible node waiting in the I-queue; seq keeps the front-to-
 * back order among nodes of equal probability, so that sorting is total and
 * deterministic. */
struct iqueue_item {
    uint32_t node;
    uint32_t invisible_frames;
    uint32_t seq;
    float group_cost;   /* what the node adds to a multiquery's cost (its boxes, pixels) */
    float alone_cost;   /* a query of its own */
    float saving;       /* what a hidden answer saves: drawing it whole, times the
                           chance that it stays hidden */
};

/* An issued I-query: count nodes starting at query_nodes[first]. */
struct iquery {
    uint32_t handle;
    uint32_t count;
    size_t first;
};

struct vquery {
    uint32_t handle;
    uint32_t node;
};

/* A V-query left in flight when its tile's traversal ended. */
struct deferred_vquery {
    uint64_t tag;
    uint64_t frame;
    uint32_t node;
    uint32_t handle;
};

/* The queues and scratch arrays of one traversal. */
struct queues {
    struct tw_distance_entry *heap;
    size_t heap_count, heap_cap;
    struct iqueue_item *iqueue;
    size_t iqueue_count, iqueue_cap;
    uint32_t *vqueue;
    size_t vqueue_head, vqueue_count, vqueue_cap;
    struct iquery *iqueries;
    size_t iq_head, iq_count, iq_cap;
    uint32_t *query_nodes;
    size_t query_node_count, query_node_cap;
    struct vquery *vqueries;
    size_t vq_head, vq_count, vq_cap;
    uint32_t *render;
    size_t render_count, render_cap;
    uint32_t *cluster_stamp;    /* == stamp: cluster already queued this traversal */
    size_t stamp_cap;
    uint32_t stamp;
    struct tw_box *boxes;
    size_t box_cap;
    uint32_t *group_len;        /* issue_iqueue: the sizes of the groups it queries */
    size_t group_cap;
};

/* One traversal of one tile. */
struct pass {
    struct tw_chc *chc;
    const struct tw_view *v;
    const struct tw_query_backend *be;
    const struct tw_chc_tile *tile;
    const struct tw_bvh *bvh;
    const struct tw_bvh_node *nodes;
    struct tw_chc_node_state *state;
    uint64_t frame;
    uint32_t iqueue_seq;
};

/* A pass suspended where it would have blocked (tw_chc_traverse_async). */
struct suspended {
    struct pass pass;
    struct tw_chc_tile tile;    /* pass.tile points here */
    struct queues q;
    uint64_t started;
    bool active;
};

/* The buckets of invisible_frames the chance of staying hidden is measured
 * in (the last: that many frames or more), and the decay per answer: about
 * the last thousand answers of a bucket count. */
#define KEEP_BUCKETS 6u
#define KEEP_DECAY 0.999

struct tw_chc {
    struct tw_chc_settings settings;
    uint64_t rng;
    struct tw_chc_stats stats;
    struct tw_cost_model costs;
    bool model;             /* decide with costs (DESIGN §14) */

    struct queues q;            /* the running traversal's */
    struct deferred_vquery *deferred;
    size_t deferred_count, deferred_cap;
    struct suspended slots[TW_CHC_MAX_SUSPENDED];
    uint64_t passes_started;
    /* V-query answers, and of them hidden ones, decayed by VQ_DECAY per
     * answer: the chance that a visible leaf's re-query finds it hidden. */
    double vq_answers, vq_hidden;
    /* I-query answers by the nodes' invisible_frames (the last bucket: that
     * many or more), and of them hidden ones, decayed by VQ_DECAY per
     * answer: the measured chance that a node stays hidden, which the cost
     * model uses instead of the paper's p(i). */
    double iq_answers[KEEP_BUCKETS], iq_hidden[KEEP_BUCKETS];
    bool unflushed;             /* drawn or issued since the last flush */
};

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
    for (uint32_t k = 0; k < TW_CHC_MAX_SUSPENDED; k++)
        free_queues(&chc->slots[k].q);
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
    for (uint32_t k = 0; k < TW_CHC_MAX_SUSPENDED; k++)
        bytes += queues_bytes(&chc->slots[k].q);
    return bytes;
}

/* ---- small helpers ------------------------------------------------------------ */


/* splitmix64: the engine's own stream, so that two engines never interfere and
 * a run is reproducible from settings.seed. */
static uint64_t next_random(struct tw_chc *chc)
{
    uint64_t z = (chc->rng += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

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
static double keep_chance(const struct tw_chc *chc, uint32_t invisible_frames)
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

static bool is_leaf(const struct tw_bvh_node *n)
{
    return n->child[0] == TW_BVH_NONE;
}

/* ---- the cost model (DESIGN §14) ---------------------------------------------------- */

/* The pixels of the screen rectangle of node's box: what its query, or
 * drawing it, can touch at most. */
static float box_pixels(const struct pass *p, uint32_t node)
{
    return p->chc->costs.screen_pixels *
           tw_cull_box_screen_fraction(p->v, &p->nodes[node].box, p->tile->offset);
}

/* Drawing a node whole when it turns out hidden, its box covering pixels: a
 * draw per cluster of its leaves, its triangles, and those pixels,
 * depth-tested (the calibration's figures are those of a hidden cluster: a
 * visible one costs the same queried or not). A node found cheaper to draw
 * than to query has children cheaper still: it is drawn whole. */
static float draw_cost(const struct tw_cost_model *c, const struct tw_bvh_node *n, float pixels)
{
    return (float)n->cluster_total * c->draw + (float)n->triangle_count * c->triangle +
           pixels * c->draw_pixel;
}

/* Visible last frame. visible_frame == frame counts too (already visible this
 * frame): such a node is treated as known visible, never re-queried. At frame
 * 1 a zeroed state reads as visible at frame 0, i.e. first sight: conservative. */
static bool was_visible(const struct tw_chc_node_state *s, uint64_t frame)
{
    return s->visible_frame + 1 >= frame;
}

/* Marks node and its ancestors visible in frame, up to the first ancestor that
 * already is. */
static void pull_up(struct tw_chc_node_state *state, const struct tw_bvh_node *nodes,
                    uint32_t node, uint64_t frame)
{
    while (node != TW_BVH_NONE && state[node].visible_frame < frame) {
        state[node].visible_frame = frame;
        state[node].invisible_frames = 0;
        node = nodes[node].parent;
    }
}

/* About the last thousand V-query answers count. */
#define VQ_DECAY 0.999
/* One re-query in this many that the model would skip is issued anyway, so
 * that the rate above keeps being measured. */
#define VQ_EXPLORE 16u

/* The chance that a re-query finds a visible leaf hidden: the measured rate,
 * from a prior of one hidden answer in two. */
static float vquery_hidden_rate(const struct tw_chc *chc)
{
    return (float)((chc->vq_hidden + 1.0) / (chc->vq_answers + 2.0));
}

/* The result of a V-query (a leaf drawn because it was visible before),
 * applied as the result of frame. */
static void apply_vquery(struct tw_chc *chc, struct tw_chc_node_state *state,
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

static void push_children(struct pass *p, uint32_t node)
{
    for (int k = 0; k < 2; k++)
        if (p->nodes[node].child[k] != TW_BVH_NONE)
            push_node(p, p->nodes[node].child[k]);
}

/* ---- rendering ------------------------------------------------------------------ */

/* Queues the leaf's clusters, skipping those already queued in this traversal
 * (a cluster may be referenced by several leaves). */
static void draw_leaf(struct pass *p, uint32_t node)
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

static void flush_render(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    if (chc->q.render_count == 0)
        return;
    p->be->draw(p->be->ctx, p->tile->cell, p->tile->content, p->tile->offset, chc->q.render,
                (uint32_t)chc->q.render_count);
    chc->q.render_count = 0;
    chc->unflushed = true;
}

/* Sends what was drawn and issued to the GPU, if anything was since the
 * last time. */
static void flush_gpu(struct pass *p)
{
    if (!p->chc->unflushed)
        return;
    p->be->flush(p->be->ctx);
    p->chc->unflushed = false;
}

/* ---- issuing queries ------------------------------------------------------------ */

/* The node's tight boxes, or NULL when its own box is to be drawn. */
static const struct tw_box *tight_boxes(const struct pass *p, uint32_t node, uint32_t *count)
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
        tight_boxes(p, list[k], &tc);
        need += tc;
    }
    /* Room for one box per node is reserved before the traversal; if tight
     * lists do not fit and cannot grow, node boxes still give a correct query. */
    const bool tight =
        tw_cull_reserve((void **)&chc->q.boxes, &chc->q.box_cap, need, sizeof(*chc->q.boxes));
    size_t nb = 0;
    for (uint32_t k = 0; k < count; k++) {
        uint32_t tc = 1;
        const struct tw_box *tb = tight ? tight_boxes(p, list[k], &tc) : NULL;
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
    chc->q.iqueries[chc->q.iq_head + chc->q.iq_count++] = (struct iquery){handle, count, first};
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
        draw_leaf(p, node);
    else
        push_children(p, node);
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
        keep *= keep_chance(chc, items[k].invisible_frames);
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
static void issue_iqueue(struct pass *p)
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
            const double own_again = (1.0 - keep_chance(chc, items[k].invisible_frames)) *
                                     items[k].alone_cost;
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
    flush_render(p);
    if (groups == 0)
        return;
    for (size_t g = 0, i = 0; g < groups; i += chc->q.group_len[g++]) {
        const size_t first = chc->q.query_node_count;
        assert(first + chc->q.group_len[g] <= chc->q.query_node_cap);
        for (size_t k = i; k < i + chc->q.group_len[g]; k++)
            chc->q.query_nodes[chc->q.query_node_count++] = items[k].node;
        issue_iquery(p, first, chc->q.group_len[g]);
    }
    flush_gpu(p);
}

static void issue_vquery(struct pass *p, uint32_t node)
{
    struct tw_chc *chc = p->chc;
    flush_render(p);
    const uint32_t handle = issue_nodes(p, &node, 1);
    assert(chc->q.vq_head + chc->q.vq_count < chc->q.vq_cap);
    chc->q.vqueries[chc->q.vq_head + chc->q.vq_count++] = (struct vquery){handle, node};
}

/* ---- reading results ------------------------------------------------------------ */

static void handle_iquery(struct pass *p, const struct iquery *q, uint32_t samples)
{
    struct tw_chc *chc = p->chc;
    const bool visible = samples > chc->settings.threshold;
    if (visible && q->count > 1) {
        /* A failed multiquery: some of its nodes are visible, find out which. */
        flush_render(p);
        for (uint32_t k = 0; k < q->count; k++) {
            const size_t first = chc->q.query_node_count;
            assert(first < chc->q.query_node_cap);
            chc->q.query_nodes[chc->q.query_node_count++] = chc->q.query_nodes[q->first + k];
            issue_iquery(p, first, 1);
            chc->stats.requeries++;
        }
        flush_gpu(p);
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
            draw_leaf(p, node);
        } else {
            push_children(p, node);
        }
        pull_up(p->state, p->nodes, node, p->frame);
    }
}

static void read_vquery(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    const struct vquery q = chc->q.vqueries[chc->q.vq_head++];
    chc->q.vq_count--;
    const uint32_t samples = p->be->wait(p->be->ctx, q.handle);
    struct tw_chc_node_state *s = &p->state[q.node];
    if (s->pending_query != q.handle)
        return;
    s->pending_query = 0;
    apply_vquery(chc, p->state, p->nodes, q.node, samples > chc->settings.threshold, p->frame);
}

/* Reads the V-queries whose results are in, in issue order, never blocking. */
static void poll_vqueries(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    while (chc->q.vq_count > 0 && p->be->ready(p->be->ctx, chc->q.vqueries[chc->q.vq_head].handle))
        read_vquery(p);
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
            draw_leaf(p, node);
            pull_up(p->state, p->nodes, node, p->frame);
        } else {
            push_children(p, node);
        }
        return;
    }
    const struct tw_cost_model *c = &chc->costs;
    float alone = 1.0f, group = 0.0f, pixels = 0.0f;
    if (chc->model) {
        /* What a query of this node would cost: its fixed part, its boxes
         * beyond the first and the pixels they cover. */
        uint32_t boxes = 1;
        tight_boxes(p, node, &boxes);
        pixels = box_pixels(p, node);
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
            push_children(p, node);
            return;
        }
        draw_leaf(p, node);
        if (s->pending_query == 0 && s->next_query_frame <= p->frame) {
            /* A re-query can pay only if what a hidden answer may save
             * over the next n_av frames, weighted by the measured chance of
             * that answer, exceeds it: a hidden leaf lets its parent be
             * found hidden too and culled whole, so the saving is counted
             * at the parent. */
            const uint32_t up = n->parent != TW_BVH_NONE ? n->parent : node;
            const float n_av = (float)(chc->settings.assumed_visible + 1);
            if (!chc->model ||
                vquery_hidden_rate(chc) * n_av *
                        draw_cost(c, &p->nodes[up], box_pixels(p, up)) >
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
    const float saving =
        chc->model ? (float)keep_chance(chc, s->invisible_frames) * draw_cost(c, n, pixels) : 0.0f;
    chc->q.iqueue[chc->q.iqueue_count++] =
        (struct iqueue_item){node, s->invisible_frames, p->iqueue_seq++, group, alone, saving};
    if (chc->q.iqueue_count >= chc->settings.batch_size)
        issue_iqueue(p);
}

/* Reserves every queue for the worst case of this BVH, so that the traversal
 * cannot fail half way: each node is pushed once, issued at most once as an
 * I-query plus once as a re-query, or once as a V-query. */
static bool reserve_pass(struct tw_chc *chc, const struct tw_chc_tile *tile)
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
                    issue_iqueue(p);
                    continue;
                }
                if (chc->q.vqueue_count > 0) {
                    chc->q.vqueue_count--;
                    issue_vquery(p, chc->q.vqueue[chc->q.vqueue_head++]);
                    flush_gpu(p);
                    continue;
                }
                /* Give the GPU what was traversed before blocking on it,
                 * or before leaving it to the next tile. */
                flush_render(p);
                flush_gpu(p);
                if (may_suspend)
                    return false;
                chc->stats.waits++;
            }
            chc->q.iq_head++;
            chc->q.iq_count--;
            handle_iquery(p, &q, be->wait(be->ctx, q.handle));
        }
        poll_vqueries(p);

        if (chc->q.heap_count > 0)
            process_node(p, heap_pop(chc));
        if (chc->q.heap_count == 0 && chc->q.iqueue_count > 0)
            issue_iqueue(p);
    }
    return true;
}

/* A done pass: its render queue drawn, its V-queries issued; those still in
 * flight are read by the next frame's tw_chc_begin_frame() (or now, if there
 * is no memory to keep them). */
static void end_pass(struct pass *p)
{
    struct tw_chc *chc = p->chc;
    flush_render(p);
    if (chc->q.vqueue_count > 0) {
        while (chc->q.vqueue_count > 0) {
            chc->q.vqueue_count--;
            issue_vquery(p, chc->q.vqueue[chc->q.vqueue_head++]);
        }
        flush_gpu(p);
    }
    poll_vqueries(p);
    if (!tw_cull_reserve((void **)&chc->deferred, &chc->deferred_cap,
                         chc->deferred_count + chc->q.vq_count, sizeof(*chc->deferred))) {
        while (chc->q.vq_count > 0)
            read_vquery(p);
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
                       const struct tw_query_backend *be, const struct tw_chc_tile *tile)
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
                   const struct tw_query_backend *be, const struct tw_chc_tile *tile)
{
    return chc && v && be && tile && tile->bvh && tile->state && tile->bvh->node_count > 0;
}

/* Makes slot k the running pass (its queues in chc->q) or puts it back. */
static void swap_queues(struct tw_chc *chc, uint32_t k)
{
    const struct queues t = chc->q;
    chc->q = chc->slots[k].q;
    chc->slots[k].q = t;
}

/* Resumes suspended pass k; block: runs it to its end. Frees the slot when
 * the pass is done. */
static void resume(struct tw_chc *chc, uint32_t k, bool block)
{
    struct suspended *sl = &chc->slots[k];
    swap_queues(chc, k);
    if (run_pass(&sl->pass, !block)) {
        end_pass(&sl->pass);
        sl->active = false;
    }
    swap_queues(chc, k);
}

/* The suspended pass started first (the nearest tile's), or TW_CHC_MAX_SUSPENDED
 * when none is. */
static uint32_t oldest_suspended(const struct tw_chc *chc)
{
    uint32_t oldest = TW_CHC_MAX_SUSPENDED;
    for (uint32_t k = 0; k < TW_CHC_MAX_SUSPENDED; k++)
        if (chc->slots[k].active &&
            (oldest == TW_CHC_MAX_SUSPENDED || chc->slots[k].started < chc->slots[oldest].started))
            oldest = k;
    return oldest;
}

void tw_chc_traverse(struct tw_chc *chc, const struct tw_view *v,
                     const struct tw_query_backend *be, const struct tw_chc_tile *tile)
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
                           const struct tw_query_backend *be, const struct tw_chc_tile *tile)
{
    if (!usable(chc, v, be, tile))
        return;
    /* Give the suspended passes what has come back; the oldest is finished
     * when every slot is taken. */
    uint32_t free_slot = TW_CHC_MAX_SUSPENDED;
    for (uint32_t k = 0; k < chc->settings.suspended_passes; k++) {
        if (chc->slots[k].active)
            resume(chc, k, false);
        if (!chc->slots[k].active && free_slot == TW_CHC_MAX_SUSPENDED)
            free_slot = k;
    }
    if (free_slot == TW_CHC_MAX_SUSPENDED) {
        free_slot = oldest_suspended(chc);
        resume(chc, free_slot, true);
    }
    struct suspended *sl = &chc->slots[free_slot];
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
    for (uint32_t k = oldest_suspended(chc); k < TW_CHC_MAX_SUSPENDED; k = oldest_suspended(chc))
        resume(chc, k, true);
}

void tw_chc_begin_frame(struct tw_chc *chc, const struct tw_view *v,
                        const struct tw_query_backend *be, tw_chc_resolve_fn resolve,
                        void *resolve_user)
{
    if (!chc)
        return;
    for (uint32_t k = 0; k < TW_CHC_MAX_SUSPENDED; k++)
        assert(!chc->slots[k].active && "tw_chc_finish() was not called at the end of a frame");
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
        apply_vquery(chc, state, bvh->nodes, d->node, samples > chc->settings.threshold,
                     d->frame);
    }
    chc->deferred_count = 0;
}
