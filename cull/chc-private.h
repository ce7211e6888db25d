/*
 * The insides of the CHC++ engine (cull-private.h), shared by its traversal
 * (chc.c) and its queries (chc-queries.c). Private to those two files.
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
#ifndef TW_CULL_CHC_PRIVATE_H
#define TW_CULL_CHC_PRIVATE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "cull/cull-private.h"

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
    uint64_t flush;     /* tw_chc.flushes when it was issued: sent to the GPU once that
                           count has grown (wavefront mode) */
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
    const struct tw_cull_instance *tile;
    const struct tw_bvh *bvh;
    const struct tw_bvh_node *nodes;
    struct tw_chc_node_state *state;
    uint64_t frame;
    uint32_t iqueue_seq;
};

/* A pass suspended where it would have blocked (tw_chc_traverse_async).
 * Allocated one by one and kept, so that pass.tile stays put. */
struct suspended {
    struct pass pass;
    struct tw_cull_instance tile;    /* pass.tile points here */
    struct queues q;
    uint64_t started;
    uint64_t resumed;                /* tw_chc_resume_flushed(): the round that resumed it */
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
    struct suspended **slots;   /* slot_count of them: settings.suspended_passes at
                                   most, any number in wavefront mode */
    uint32_t slot_count, slot_cap;
    uint64_t passes_started;
    /* Wavefront mode (tw_chc_set_wavefront): the caller flushes, once per
     * wavefront, and says so (tw_chc_resume_flushed); passes never flush and
     * wait only on queries sent before the last of those flushes. */
    bool wavefront;
    uint64_t flushes;           /* the caller's flushes so far */
    uint64_t rounds;
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

/* splitmix64: the engine's own stream, so that two engines never interfere and
 * a run is reproducible from settings.seed. */
static inline uint64_t next_random(struct tw_chc *chc)
{
    uint64_t z = (chc->rng += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static inline bool is_leaf(const struct tw_bvh_node *n)
{
    return n->child[0] == TW_BVH_NONE;
}

/* Marks node and its ancestors visible in frame, up to the first ancestor that
 * already is. */
static inline void pull_up(struct tw_chc_node_state *state,
                           const struct tw_bvh_node *nodes, uint32_t node, uint64_t frame)
{
    while (node != TW_BVH_NONE && state[node].visible_frame < frame) {
        state[node].visible_frame = frame;
        state[node].invisible_frames = 0;
        node = nodes[node].parent;
    }
}

/* One re-query in this many that the model would skip is issued anyway, so
 * that the chance that a re-query finds its leaf hidden keeps being measured. */
#define VQ_EXPLORE 16u

/* ---- the traversal (chc.c) ------------------------------------------------------- */

/* Queues node's children for traversal, those in the frustum within the view
 * distance. */
void tw_chc_push_children(struct pass *p, uint32_t node);
/* Queues the leaf's clusters for drawing, those not queued yet in this
 * traversal. */
void tw_chc_draw_leaf(struct pass *p, uint32_t node);
/* Draws the render queue. */
void tw_chc_flush_render(struct pass *p);
/* Sends what was drawn and issued to the GPU, if anything was since the
 * last time; in wavefront mode nothing (the caller flushes). */
void tw_chc_flush_gpu(struct pass *p);

/* ---- the queries and the costs they are decided with (chc-queries.c) --------------- */

/* The node's tight boxes (*count of them), or NULL when its own box is to be
 * drawn. */
const struct tw_box *tw_chc_tight_boxes(const struct pass *p, uint32_t node, uint32_t *count);
/* The pixels that the screen rectangle of node's box covers. */
float tw_chc_box_pixels(const struct pass *p, uint32_t node);
/* What drawing node whole costs when it turns out hidden, its box covering
 * pixels. */
float tw_chc_draw_cost(const struct tw_cost_model *c, const struct tw_bvh_node *n, float pixels);
/* The chance that a node hidden for invisible_frames frames is hidden again. */
double tw_chc_keep_chance(const struct tw_chc *chc, uint32_t invisible_frames);
/* The chance that a re-query finds a visible leaf hidden. */
float tw_chc_vquery_hidden_rate(const struct tw_chc *chc);
/* Applies a V-query's answer on node as the result of frame. */
void tw_chc_apply_vquery(struct tw_chc *chc, struct tw_chc_node_state *state,
                         const struct tw_bvh_node *nodes, uint32_t node, bool visible,
                         uint64_t frame);
/* Issues the I-queue as a batch of multiqueries. */
void tw_chc_issue_iqueue(struct pass *p);
/* Issues a V-query on a visible leaf. */
void tw_chc_issue_vquery(struct pass *p, uint32_t node);
/* Applies an I-query's answer (samples passed). */
void tw_chc_handle_iquery(struct pass *p, const struct iquery *q, uint32_t samples);
/* Reads the oldest V-query in flight, blocking until it is in. */
void tw_chc_read_vquery(struct pass *p);
/* Reads the V-queries whose results are in, in issue order, never blocking. */
void tw_chc_poll_vqueries(struct pass *p);

#endif
