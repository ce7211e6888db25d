/*
 * bvh: a binary SAH BVH per tile prototype over its draw clusters, built once
 * with Embree's rtcBuildBVH and flattened into an index-linked node array
 * (DESIGN.md §1, §7). A BVH is immutable after its build and shared by every
 * cell that shows its prototype; per-view state lives elsewhere (cull/).
 */
#ifndef TW_BVH_H
#define TW_BVH_H

#include <stdint.h>

#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

#define TW_BVH_NONE UINT32_MAX

/* One node. Interior nodes have two children; leaves have a cluster range. */
struct tw_bvh_node {
    struct tw_box box;          /* tile-local, tight around its clusters */
    uint32_t parent;            /* TW_BVH_NONE for the root (node 0) */
    uint32_t child[2];          /* TW_BVH_NONE for a leaf */
    uint32_t first_cluster;     /* leaf: range into tw_bvh.cluster_order */
    uint32_t cluster_count;     /* leaf: > 0; interior: 0 */
    uint32_t first_tight;       /* range into tw_bvh.tight_boxes */
    uint32_t tight_count;       /* >= 1; 1 means the node's own box */
    uint32_t depth;             /* root = 0 */
    uint32_t triangle_count;    /* in the whole subtree */
    uint32_t cluster_total;     /* clusters of the whole subtree's leaves: the draws that
                                   drawing it whole makes (a leaf: cluster_count) */
};

struct tw_bvh_settings {
    uint32_t max_depth;            /* default 32 */
    uint32_t min_leaf_triangles;   /* a node with fewer triangles is a leaf; default 0 */
    uint32_t tight_depth;          /* tight boxes from up to this many levels down; default 3 */
    float tight_area_ratio;        /* use them when their area <= ratio * node area; default 1.4 */
};

/* Fills in the defaults of every zero field. */
void tw_bvh_default_settings(struct tw_bvh_settings *s);

struct tw_bvh {
    struct tw_bvh_node *nodes;     /* node 0 is the root */
    uint32_t node_count;
    uint32_t *cluster_order;       /* cluster indices of the prototype, leaf by leaf */
    uint32_t cluster_count;
    struct tw_box *tight_boxes;
    uint32_t tight_box_count;
    uint32_t leaf_count;
    uint32_t depth;                /* deepest node's depth */
    double build_ms;
    uint32_t tight_depth;          /* the settings' tight_depth it was built with (refits) */
    uint64_t bytes;                /* heap bytes of this structure */
    bool packed;                   /* private: one block (tw_bvh_pack) */
};

/* A builder owns an Embree device; Embree's errors go to the logger. One
 * builder may build many BVHs, one at a time. */
struct tw_bvh_builder;

/* log is copied; it may be NULL. threads: how many Embree builds with (0:
 * every core); a pool of workers each building one BVH at a time gives
 * each its own builder with threads = 1. */
int tw_bvh_builder_create(const struct tw_log *log, uint32_t threads,
                          struct tw_bvh_builder **out);
void tw_bvh_builder_destroy(struct tw_bvh_builder *b);

/* Builds the BVH of proto's clusters (settings NULL: defaults). The caller
 * owns *out and frees it with tw_bvh_destroy(). */
int tw_bvh_build(struct tw_bvh_builder *b, const struct tw_prototype *proto,
                 const struct tw_bvh_settings *settings, struct tw_bvh **out);

/* The same tree built by median splits along the longest axis, no SAH, no
 * Embree: the reference that tests and benchmarks compare SAH against. */
int tw_bvh_build_median(const struct tw_prototype *proto,
                        const struct tw_bvh_settings *settings,
                        struct tw_bvh **out);

void tw_bvh_destroy(struct tw_bvh *bvh);

/* Refitting (moving objects, DESIGN §13): recomputes every box of bvh, its
 * tight boxes too, from proto's clusters, keeping its topology. proto is
 * the prototype bvh was built over, its clusters moved but not added or
 * removed. */
void tw_bvh_refit(struct tw_bvh *bvh, const struct tw_prototype *proto);

/* The sum of the surface areas of bvh's interior nodes over the sum of its
 * leaves': 1 for a tree whose nodes are as tight as its leaves allow, and
 * growing as refits let boxes overlap (when it has grown well past its
 * value at the build, a build afresh pays). 1 for a single leaf. */
double tw_bvh_spread(const struct tw_bvh *bvh);

/* Joins two BVHs under a new root: one over the clusters of a prototype
 * made of a's prototype's clusters (first) and b's (numbered after the
 * a_clusters of a's). Node 0 is the new root, a's nodes follow from 1 with
 * their tight boxes, then b_capacity slots (at least b's node count) for
 * b's nodes, each its own box as tight box; the slots b leaves are leaves
 * of no cluster that no node links to. Copies; a and b are unchanged and
 * may go. The node count stays while another b of at most b_capacity
 * nodes takes b's place (tw_bvh_rejoin): what is kept per node of the
 * joined tree (a's part) keeps its meaning. */
int tw_bvh_join(const struct tw_bvh *a, uint32_t a_clusters, const struct tw_bvh *b,
                uint32_t b_capacity, struct tw_bvh **out);

/* Puts another b into j (made by tw_bvh_join with this a), in place:
 * TW_ERR_LIMIT when b has more nodes than j's slots for it. */
int tw_bvh_rejoin(struct tw_bvh *j, const struct tw_bvh *a, uint32_t a_clusters,
                  const struct tw_bvh *b);

/* After b was refitted: its boxes into j (made by tw_bvh_join(a, _, b)) and
 * the root's box. */
void tw_bvh_join_refit(struct tw_bvh *j, const struct tw_bvh *a, const struct tw_bvh *b);

/* Moves a BVH, its struct and its arrays, into one allocation and replaces
 * *bvh with it (the old pointer is freed), so that a long-lived tree leaves
 * no small holes in the heap when it is freed (tw_tileset_pack()). bytes is
 * then the block's size. On TW_ERR_NOMEM *bvh is unchanged and still valid. */
int tw_bvh_pack(struct tw_bvh **bvh);

/* SAH cost of the tree: sum over interior nodes of area(node)/area(root) *
 * C_trav + sum over leaves of area(leaf)/area(root) * triangles(leaf) *
 * C_tri, with C_trav = 1, C_tri = 1 / 64 (clusters are drawn, not
 * intersected, so a triangle costs little next to a node). */
double tw_bvh_sah_cost(const struct tw_bvh *bvh);

/* Checks the invariants (every cluster in exactly one leaf, every box holds
 * its children's, parents and depths consistent, depth <= max_depth).
 * Returns TW_OK or TW_ERR_STATE with a message written to why (may be NULL). */
int tw_bvh_validate(const struct tw_bvh *bvh, const struct tw_prototype *proto,
                    uint32_t max_depth, char *why, size_t why_size);

#ifdef __cplusplus
}
#endif

#endif
