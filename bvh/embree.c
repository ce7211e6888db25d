/*
 * The Embree builder (bvh.h): Embree's binned SAH builder (rtcBuildBVH) makes
 * the stage tree (bvh-private.h) of a prototype's clusters, one per leaf.
 */
#include "bvh/bvh-private.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <embree3/rtcore.h>

struct tw_bvh_builder {
    struct tw_log log;
    RTCDevice device;
    /* Embree may report an error from one of its worker threads (an
     * allocation failing inside a build callback), while our logger may only
     * be called from the caller's thread: the error callback records the
     * first message here and the caller logs it once Embree returns. */
    atomic_int error_claimed;
    atomic_uint error_count;
    enum RTCError first_error;
    char first_message[256];
};

static const char *embree_error_name(enum RTCError code)
{
    switch (code) {
    case RTC_ERROR_NONE: return "none";
    case RTC_ERROR_UNKNOWN: return "unknown";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    }
    return "unrecognised error code";
}

/* Nodes built by Embree's callbacks, in memory of Embree's thread-local
 * allocator (freed with the RTCBVH). */
enum embree_node_kind { EMBREE_INNER, EMBREE_LEAF };

struct embree_inner {
    enum embree_node_kind kind;
    const void *child[2];
};

struct embree_leaf {
    enum embree_node_kind kind;
    uint32_t count;
    uint32_t cluster[];
};

static void *embree_create_node(RTCThreadLocalAllocator alloc, unsigned int child_count,
                                void *user)
{
    (void)user;
    /* maxBranchingFactor is 2; anything else means Embree ignored it, which
     * the conversion reports as a malformed tree. */
    if (child_count != 2)
        return NULL;
    struct embree_inner *n = rtcThreadLocalAlloc(alloc, sizeof(*n), 16);
    if (!n)
        return NULL;
    n->kind = EMBREE_INNER;
    n->child[0] = n->child[1] = NULL;
    return n;
}

static void embree_set_children(void *node, void **children, unsigned int child_count,
                                void *user)
{
    (void)user;
    struct embree_inner *n = node;
    if (!n)
        return;
    for (unsigned int i = 0; i < child_count && i < 2; i++)
        n->child[i] = children[i];
}

/* Embree's bounds are not used: the flattening pass recomputes tight boxes
 * from the clusters (the builder may round or pad). */
static void embree_set_bounds(void *node, const struct RTCBounds **bounds,
                              unsigned int child_count, void *user)
{
    (void)node;
    (void)bounds;
    (void)child_count;
    (void)user;
}

static void *embree_create_leaf(RTCThreadLocalAllocator alloc,
                                const struct RTCBuildPrimitive *prims, size_t prim_count,
                                void *user)
{
    (void)user;
    if (prim_count == 0 || prim_count > RTC_BUILD_MAX_PRIMITIVES_PER_LEAF)
        return NULL;
    struct embree_leaf *leaf =
        rtcThreadLocalAlloc(alloc, sizeof(*leaf) + prim_count * sizeof(uint32_t), 16);
    if (!leaf)
        return NULL;
    leaf->kind = EMBREE_LEAF;
    leaf->count = (uint32_t)prim_count;
    for (size_t i = 0; i < prim_count; i++)
        leaf->cluster[i] = prims[i].primID;
    return leaf;
}

static void embree_error(void *user, enum RTCError code, const char *str)
{
    struct tw_bvh_builder *b = user;
    atomic_fetch_add(&b->error_count, 1u);
    int expected = 0;
    if (atomic_compare_exchange_strong(&b->error_claimed, &expected, 1)) {
        b->first_error = code;
        snprintf(b->first_message, sizeof(b->first_message), "%s", str ? str : "");
    }
}

/* Logs (on the caller's thread) what Embree reported since the last call,
 * while doing what; returns TW_OK if nothing was, else TW_ERR_NOMEM (it ran
 * out of memory) or TW_ERR_EMBREE. */
static int flush_embree_errors(struct tw_bvh_builder *b, const char *what)
{
    const unsigned int count = atomic_exchange(&b->error_count, 0u);
    if (count == 0)
        return TW_OK;
    const enum RTCError code = b->first_error;
    /* Out of memory: the caller says so, once, with the prototype. */
    if (code != RTC_ERROR_OUT_OF_MEMORY)
        tw_log_printf(&b->log, TW_LOG_ERROR,
                      "the BVH builder (Embree) failed while %s: %s%s%s%s%s", what,
                      embree_error_name(code), b->first_message[0] ? " (" : "",
                      b->first_message, b->first_message[0] ? ")" : "",
                      count > 1 ? " (and more)" : "");
    atomic_store(&b->error_claimed, 0);
    return code == RTC_ERROR_OUT_OF_MEMORY ? TW_ERR_NOMEM : TW_ERR_EMBREE;
}

int tw_bvh_builder_create(const struct tw_log *log, uint32_t threads,
                          struct tw_bvh_builder **out)
{
    int ret = TW_OK;
    if (!out)
        return TW_ERR_INVALID;
    *out = NULL;

    struct tw_bvh_builder *b = calloc(1, sizeof(*b));
    if (!b) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot start the BVH builder: out of memory");
        return TW_ERR_NOMEM;
    }
    if (log)
        b->log = *log;
    atomic_init(&b->error_claimed, 0);
    atomic_init(&b->error_count, 0u);

    /* verbose=0: Embree must not print to stdout on its own. */
    char config[64];
    snprintf(config, sizeof(config), "verbose=0,threads=%u", threads);
    b->device = rtcNewDevice(config);
    if (!b->device) {
        const enum RTCError code = rtcGetDeviceError(NULL);
        tw_log_printf(&b->log, TW_LOG_ERROR, "cannot start the BVH builder (Embree): %s",
                      embree_error_name(code));
        ret = code == RTC_ERROR_OUT_OF_MEMORY ? TW_ERR_NOMEM : TW_ERR_EMBREE;
        goto fail;
    }
    rtcSetDeviceErrorFunction(b->device, embree_error, b);

    *out = b;
    return TW_OK;

fail:
    tw_bvh_builder_destroy(b);
    return ret;
}

void tw_bvh_builder_destroy(struct tw_bvh_builder *b)
{
    if (!b)
        return;
    if (b->device) {
        rtcReleaseDevice(b->device);
        flush_embree_errors(b, "shutting down");
    }
    free(b);
}

const struct tw_log *tw_bvh_builder_log(const struct tw_bvh_builder *b)
{
    return &b->log;
}

/* Fills first/count/triangles of interior nodes from their children; needs
 * leaves to have theirs. Pre-order puts children after parents, so one
 * backwards sweep suffices. */
static void stage_sum_up(struct stage *st)
{
    for (uint32_t i = st->node_count; i-- > 0;) {
        struct stage_node *n = &st->nodes[i];
        if (n->child[0] == TW_BVH_NONE)
            continue;
        const struct stage_node *l = &st->nodes[n->child[0]];
        const struct stage_node *r = &st->nodes[n->child[1]];
        assert(l->first + l->count == r->first);
        n->first = l->first;
        n->count = l->count + r->count;
        n->triangles = l->triangles + r->triangles;
    }
}

/* Converts Embree's pointer tree into the stage tree, checking that every
 * cluster comes out exactly once (Embree reorders but never duplicates
 * primitives without a split callback). */
static int stage_from_embree(struct stage *st, const void *root, uint32_t cluster_count,
                             const struct tw_cluster *clusters, const struct tw_log *log,
                             const char *proto_name)
{
    int ret = TW_OK;
    struct pending {
        const void *node;
        uint32_t parent;
        uint32_t slot;
    };
    /* Pre-order DFS: the stack never holds more than depth + 1 <= n entries. */
    struct pending *stack = malloc((size_t)cluster_count * sizeof(*stack) + sizeof(*stack));
    uint8_t *seen = calloc(cluster_count, 1);
    if (!stack || !seen) {
        ret = TW_ERR_NOMEM;
        goto out;
    }

    uint32_t top = 0;
    stack[top++] = (struct pending){root, TW_BVH_NONE, 0};
    while (top > 0) {
        const struct pending p = stack[--top];
        const enum embree_node_kind *kind = p.node;
        if (!kind || st->node_count == st->node_cap) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "prototype '%s': the BVH builder (Embree) returned a malformed tree "
                          "(%s)", proto_name, kind ? "too many nodes" : "missing node");
            ret = TW_ERR_EMBREE;
            goto out;
        }
        const uint32_t index = st->node_count++;
        struct stage_node *n = &st->nodes[index];
        n->child[0] = n->child[1] = TW_BVH_NONE;
        if (p.parent != TW_BVH_NONE)
            st->nodes[p.parent].child[p.slot] = index;

        if (*kind == EMBREE_INNER) {
            const struct embree_inner *inner = p.node;
            if (top + 2 > cluster_count + 1) {
                tw_log_printf(log, TW_LOG_ERROR,
                              "prototype '%s': the BVH builder (Embree) returned a malformed "
                              "tree (too deep)", proto_name);
                ret = TW_ERR_EMBREE;
                goto out;
            }
            /* Right first, so that the left subtree is emitted first. */
            stack[top++] = (struct pending){inner->child[1], index, 1};
            stack[top++] = (struct pending){inner->child[0], index, 0};
            continue;
        }

        /* A leaf: exactly one cluster, as maxLeafSize is 1; the stage tree
         * and the node-count bound 2n - 1 rely on it. */
        const struct embree_leaf *leaf = p.node;
        if (leaf->count != 1) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "prototype '%s': the BVH builder (Embree) made a leaf of %u "
                          "clusters where one was asked for", proto_name, leaf->count);
            ret = TW_ERR_EMBREE;
            goto out;
        }
        const uint32_t c = leaf->cluster[0];
        if (c >= cluster_count || seen[c] || st->leaf_cluster_count == cluster_count) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "prototype '%s': the BVH builder (Embree) returned cluster %u %s",
                          proto_name, c, c >= cluster_count ? "out of range" : "twice");
            ret = TW_ERR_EMBREE;
            goto out;
        }
        seen[c] = 1;
        n->first = st->leaf_cluster_count;
        n->count = 1;
        n->triangles = clusters[c].triangle_count;
        st->leaf_clusters[st->leaf_cluster_count++] = c;
    }
    if (st->leaf_cluster_count != cluster_count) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "prototype '%s': the BVH builder's (Embree's) tree holds %u of %u "
                      "clusters",
                      proto_name, st->leaf_cluster_count, cluster_count);
        ret = TW_ERR_EMBREE;
        goto out;
    }
    stage_sum_up(st);

out:
    free(seen);
    free(stack);
    return ret;
}

int tw_bvh_stage_embree(struct tw_bvh_builder *b, const struct tw_prototype *proto,
                        struct stage *st)
{
    int ret = TW_OK;
    const uint32_t n = proto->cluster_count;
    RTCBVH embree_bvh = NULL;

    /* Embree loads build primitives with aligned vector loads. */
    struct RTCBuildPrimitive *prims =
        aligned_alloc(32, (size_t)n * sizeof(struct RTCBuildPrimitive));
    if (!prims) {
        ret = TW_ERR_NOMEM;
        goto out;
    }
    uint64_t triangles = 0;
    for (uint32_t i = 0; i < n; i++) {
        const struct tw_box *box = &proto->clusters[i].box;
        prims[i] = (struct RTCBuildPrimitive){
            .lower_x = box->min[0], .lower_y = box->min[1], .lower_z = box->min[2],
            .geomID = 0,
            .upper_x = box->max[0], .upper_y = box->max[1], .upper_z = box->max[2],
            .primID = i,
        };
        triangles += proto->clusters[i].triangle_count;
    }

    embree_bvh = rtcNewBVH(b->device);
    if (!embree_bvh) {
        ret = flush_embree_errors(b, "starting a build");
        if (!ret)
            ret = TW_ERR_EMBREE;
        goto out;
    }

    struct RTCBuildArguments args = rtcDefaultBuildArguments();
    /* MEDIUM is Embree's binned SAH. HIGH without a split callback runs the
     * very same builder (spatial splits need one, and would put a cluster in
     * several leaves, which the renderer cannot have), so it buys nothing. */
    args.buildQuality = RTC_BUILD_QUALITY_MEDIUM;
    args.maxBranchingFactor = 2;
    /* Embree stops doing SAH splits 8 levels above maxDepth and fails if a
     * subtree still has more than 2^8 clusters there. Our depth limit is
     * applied while flattening instead; a depth of n + 9 can never be
     * reached by a tree whose every split removes a cluster. */
    args.maxDepth = n > UINT32_MAX - 16 ? UINT32_MAX : n + 9;
    args.minLeafSize = 1;
    args.maxLeafSize = 1;
    /* Costs: with maxLeafSize 1 the leaf-or-split test never runs and the
     * split chosen minimises area(L) * n(L) + area(R) * n(R) whatever the
     * costs are, so they only document the model of tw_bvh_sah_cost()
     * (C_trav = 1, C_tri = 1/64, scaled by the mean cluster size since
     * Embree counts primitives). Triangle counts cannot weight Embree's SAH:
     * sahBlockSize only rounds primitive counts up to blocks, so it stays 1. */
    args.sahBlockSize = 1;
    args.traversalCost = (float)SAH_TRAVERSAL_COST;
    args.intersectionCost = (float)(SAH_TRIANGLE_COST * ((double)triangles / n));
    if (!(args.intersectionCost > 0.0f))
        args.intersectionCost = (float)SAH_TRIANGLE_COST;
    args.bvh = embree_bvh;
    args.primitives = prims;
    args.primitiveCount = n;
    args.primitiveArrayCapacity = n;
    args.createNode = embree_create_node;
    args.setNodeChildren = embree_set_children;
    args.setNodeBounds = embree_set_bounds;
    args.createLeaf = embree_create_leaf;
    args.userPtr = b;

    const void *root = rtcBuildBVH(&args);
    ret = flush_embree_errors(b, "building");
    if (ret || !root) {
        if (!ret) {
            tw_log_printf(&b->log, TW_LOG_ERROR,
                          "prototype '%.48s': the BVH builder (Embree) returned no tree",
                          proto->name);
            ret = TW_ERR_EMBREE;
        }
        goto out;
    }

    ret = tw_bvh_stage_init(st, n);
    if (ret < 0)
        goto out;
    ret = stage_from_embree(st, root, n, proto->clusters, &b->log, proto->name);

out:
    if (embree_bvh) {
        rtcReleaseBVH(embree_bvh);
        flush_embree_errors(b, "releasing a build");
    }
    free(prims);
    return ret;
}
