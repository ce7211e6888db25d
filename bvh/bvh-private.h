/*
 * bvh's insides shared by its files (bvh.h is the module's contract). Both
 * builders (Embree's binned SAH in embree.c, the median split in median.c)
 * produce a "stage" tree that bvh.c flattens into a struct tw_bvh.
 */
#ifndef TW_BVH_PRIVATE_H
#define TW_BVH_PRIVATE_H

#include <stdint.h>

#include "bvh/bvh.h"

/* The SAH cost model of tw_bvh_sah_cost(). */
#define SAH_TRAVERSAL_COST 1.0
#define SAH_TRIANGLE_COST (1.0 / 64.0)

/* A binary tree with one cluster per leaf, laid out in pre-order, whose
 * leaves list the clusters left to right in one array, so that every
 * subtree owns a contiguous range of that array. */
struct stage_node {
    uint32_t child[2];      /* TW_BVH_NONE for a leaf */
    uint32_t first;         /* subtree's range in stage.leaf_clusters */
    uint32_t count;
    uint64_t triangles;     /* in the subtree */
};

struct stage {
    struct stage_node *nodes;   /* pre-order: children after their parent */
    uint32_t node_count;
    uint32_t node_cap;          /* 2n - 1 */
    uint32_t *leaf_clusters;    /* n cluster indices, leaf by leaf, left to right */
    uint32_t leaf_cluster_count;
};

/* Allocates room for the stage tree of cluster_count clusters (2n - 1
 * nodes); TW_ERR_NOMEM when out of memory (bvh.c frees what was made). */
int tw_bvh_stage_init(struct stage *st, uint32_t cluster_count);

/* The stage tree of proto's clusters by Embree's binned SAH (embree.c). */
int tw_bvh_stage_embree(struct tw_bvh_builder *b, const struct tw_prototype *proto,
                        struct stage *st);
/* The builder's logger (embree.c). */
const struct tw_log *tw_bvh_builder_log(const struct tw_bvh_builder *b);

/* The stage tree of proto's clusters by median splits along the longest
 * axis (median.c). */
int tw_bvh_stage_median(const struct tw_prototype *proto, struct stage *st);

#endif
