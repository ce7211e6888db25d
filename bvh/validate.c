/*
 * What can be asked of a built BVH (bvh.h): its SAH cost, and whether it
 * keeps its invariants.
 */
#include "bvh/bvh-private.h"

#include <stdio.h>
#include <stdlib.h>

double tw_bvh_sah_cost(const struct tw_bvh *bvh)
{
    if (!bvh || bvh->node_count == 0)
        return 0.0;
    const double root_area = tw_box_surface_area(&bvh->nodes[0].box);
    double cost = 0.0;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];
        /* A degenerate (zero-area) root holds only zero-area boxes: count
         * every node as fully hit rather than divide by zero. */
        const double ratio = root_area > 0.0 ? tw_box_surface_area(&n->box) / root_area : 1.0;
        if (n->child[0] == TW_BVH_NONE)
            cost += ratio * n->triangle_count * SAH_TRIANGLE_COST;
        else
            cost += ratio * SAH_TRAVERSAL_COST;
    }
    return cost;
}

static bool box_contains(const struct tw_box *outer, const struct tw_box *inner)
{
    for (int k = 0; k < 3; k++) {
        if (inner->min[k] < outer->min[k] || inner->max[k] > outer->max[k])
            return false;
    }
    return true;
}

static bool box_equal(const struct tw_box *a, const struct tw_box *b)
{
    for (int k = 0; k < 3; k++) {
        if (a->min[k] != b->min[k] || a->max[k] != b->max[k])
            return false;
    }
    return true;
}

#define FAIL(...)                                                   \
    do {                                                            \
        if (why && why_size > 0)                                    \
            snprintf(why, why_size, __VA_ARGS__);                   \
        ret = TW_ERR_STATE;                                         \
        goto out;                                                   \
    } while (0)

int tw_bvh_validate(const struct tw_bvh *bvh, const struct tw_prototype *proto,
                    uint32_t max_depth, char *why, size_t why_size)
{
    int ret = TW_OK;
    uint8_t *seen = NULL;
    uint8_t *referenced = NULL;

    if (why && why_size > 0)
        why[0] = '\0';
    if (!bvh || !proto)
        FAIL("no BVH or no prototype");
    if (bvh->node_count == 0 || !bvh->nodes)
        FAIL("no nodes");
    if (bvh->cluster_count != proto->cluster_count)
        FAIL("%u clusters in the BVH, %u in the prototype", bvh->cluster_count,
             proto->cluster_count);

    seen = calloc(bvh->cluster_count ? bvh->cluster_count : 1, 1);
    referenced = calloc(bvh->node_count, 1);
    if (!seen || !referenced) {
        if (why && why_size > 0)
            snprintf(why, why_size, "out of memory");
        ret = TW_ERR_NOMEM;
        goto out;
    }

    const struct tw_bvh_node *root = &bvh->nodes[0];
    if (root->parent != TW_BVH_NONE || root->depth != 0)
        FAIL("root has a parent or a non-zero depth");

    uint32_t leaves = 0, deepest = 0;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];
        if (n->depth > max_depth)
            FAIL("node %u at depth %u, deeper than %u", i, n->depth, max_depth);
        if (i > 0 && n->depth == 0)
            FAIL("node %u is not the root but has depth 0", i);
        if (n->depth > deepest)
            deepest = n->depth;
        if (n->tight_count == 0 || n->first_tight > bvh->tight_box_count ||
            n->tight_count > bvh->tight_box_count - n->first_tight)
            FAIL("node %u: tight-box range out of bounds", i);
        if (n->tight_count == 1 && !box_equal(&bvh->tight_boxes[n->first_tight], &n->box))
            FAIL("node %u: a single tight box must be the node's own", i);
        for (uint32_t t = 0; t < n->tight_count; t++) {
            if (!box_contains(&n->box, &bvh->tight_boxes[n->first_tight + t]))
                FAIL("node %u: tight box %u is outside the node's box", i, t);
        }

        if (n->child[0] == TW_BVH_NONE || n->child[1] == TW_BVH_NONE) {
            if (n->child[0] != n->child[1])
                FAIL("node %u has one child", i);
            if (n->cluster_count == 0)
                FAIL("leaf %u has no clusters", i);
            if (n->first_cluster > bvh->cluster_count ||
                n->cluster_count > bvh->cluster_count - n->first_cluster)
                FAIL("leaf %u: cluster range out of bounds", i);
            uint64_t triangles = 0;
            for (uint32_t k = 0; k < n->cluster_count; k++) {
                const uint32_t c = bvh->cluster_order[n->first_cluster + k];
                if (c >= proto->cluster_count)
                    FAIL("leaf %u holds cluster %u, out of range", i, c);
                if (seen[c])
                    FAIL("cluster %u is in two leaves", c);
                seen[c] = 1;
                if (!box_contains(&n->box, &proto->clusters[c].box))
                    FAIL("leaf %u's box does not hold cluster %u", i, c);
                triangles += proto->clusters[c].triangle_count;
            }
            if (triangles != n->triangle_count)
                FAIL("leaf %u counts %u triangles, its clusters %llu", i, n->triangle_count,
                     (unsigned long long)triangles);
            if (n->cluster_total != n->cluster_count)
                FAIL("leaf %u counts %u clusters in all, %u of its own", i, n->cluster_total,
                     n->cluster_count);
            leaves++;
            continue;
        }

        if (n->cluster_count != 0)
            FAIL("interior node %u has clusters", i);
        uint64_t triangles = 0, clusters = 0;
        for (int k = 0; k < 2; k++) {
            const uint32_t c = n->child[k];
            if (c >= bvh->node_count || c == 0 || c == i)
                FAIL("node %u: child %u out of range", i, c);
            if (referenced[c])
                FAIL("node %u is the child of two nodes", c);
            referenced[c] = 1;
            const struct tw_bvh_node *child = &bvh->nodes[c];
            if (child->parent != i)
                FAIL("node %u's parent is %u, not %u", c, child->parent, i);
            if (child->depth != n->depth + 1)
                FAIL("node %u at depth %u under node %u at depth %u", c, child->depth, i,
                     n->depth);
            if (!box_contains(&n->box, &child->box))
                FAIL("node %u's box does not hold child %u's", i, c);
            triangles += child->triangle_count;
            clusters += child->cluster_total;
        }
        if (triangles != n->triangle_count)
            FAIL("node %u counts %u triangles, its children %llu", i, n->triangle_count,
                 (unsigned long long)triangles);
        if (clusters != n->cluster_total)
            FAIL("node %u counts %u clusters in all, its children %llu", i, n->cluster_total,
                 (unsigned long long)clusters);
    }
    /* Depth rises by one along every child link and only the root has
     * depth 0, so every node's parent chain ends at the root: with one
     * reference per non-root node the nodes form a single tree. */
    for (uint32_t i = 1; i < bvh->node_count; i++) {
        if (!referenced[i])
            FAIL("node %u is nobody's child", i);
        const uint32_t p = bvh->nodes[i].parent;
        if (p >= bvh->node_count || (bvh->nodes[p].child[0] != i && bvh->nodes[p].child[1] != i))
            FAIL("node %u's parent %u does not list it", i, p);
    }
    for (uint32_t c = 0; c < proto->cluster_count; c++) {
        if (!seen[c])
            FAIL("cluster %u is in no leaf", c);
    }
    if (leaves != bvh->leaf_count)
        FAIL("leaf_count %u, counted %u", bvh->leaf_count, leaves);
    if (deepest != bvh->depth)
        FAIL("depth %u, deepest node at %u", bvh->depth, deepest);

out:
    free(seen);
    free(referenced);
    return ret;
}
