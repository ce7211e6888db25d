/*
 * bvh: per-prototype binary BVH over draw clusters (DESIGN.md §1, §7).
 *
 * Both builders (Embree's binned SAH and the median-split reference) first
 * produce a "stage" tree: a binary tree with one cluster per leaf, laid out in
 * pre-order, whose leaves list the clusters left to right in one array, so
 * that every subtree owns a contiguous range of that array. One shared
 * flattening pass then applies the leaf rules (max_depth,
 * min_leaf_triangles) by collapsing subtrees into leaves, recomputes tight
 * boxes and triangle counts, and computes the tight-box lists. The stage
 * leaf array becomes tw_bvh.cluster_order as is.
 */
#include "bvh/bvh.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <embree3/rtcore.h>

#define SAH_TRAVERSAL_COST 1.0
#define SAH_TRIANGLE_COST (1.0 / 64.0)

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

/* ---- small helpers ---------------------------------------------------------- */

static bool box_is_valid(const struct tw_box *b)
{
    for (int k = 0; k < 3; k++) {
        if (!isfinite(b->min[k]) || !isfinite(b->max[k]) || b->min[k] > b->max[k])
            return false;
    }
    return true;
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

/* ---- settings --------------------------------------------------------------- */

void tw_bvh_default_settings(struct tw_bvh_settings *s)
{
    if (!s)
        return;
    if (s->max_depth == 0)
        s->max_depth = 32;
    if (s->tight_depth == 0)
        s->tight_depth = 3;
    if (s->tight_area_ratio == 0.0f)
        s->tight_area_ratio = 1.4f;
}

static int resolve_settings(const struct tw_bvh_settings *in, const char *proto_name,
                            const struct tw_log *log, struct tw_bvh_settings *out)
{
    if (in)
        *out = *in;
    else
        memset(out, 0, sizeof(*out));
    tw_bvh_default_settings(out);
    if (!isfinite(out->tight_area_ratio) || out->tight_area_ratio < 0.0f) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "prototype '%s': cannot build its bounding volume hierarchy: the "
                      "setting tight_area_ratio (%g) is not a finite non-negative number",
                      proto_name, (double)out->tight_area_ratio);
        return TW_ERR_INVALID;
    }
    return TW_OK;
}

static int check_prototype(const struct tw_prototype *proto, const struct tw_log *log)
{
    if (proto->cluster_count == 0 || !proto->clusters) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "prototype '%.48s': cannot build its bounding volume hierarchy: it has no "
                      "draw clusters (was its tileset finished?)",
                      proto->name);
        return TW_ERR_INVALID;
    }
    /* The stage tree needs up to 2n - 1 nodes, indexed by uint32_t. */
    if (proto->cluster_count > UINT32_MAX / 2) {
        tw_log_printf(log, TW_LOG_ERROR, "prototype '%.48s': %u draw clusters, too many",
                      proto->name, proto->cluster_count);
        return TW_ERR_LIMIT;
    }
    for (uint32_t i = 0; i < proto->cluster_count; i++) {
        if (!box_is_valid(&proto->clusters[i].box)) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "prototype '%.48s', cluster %u: its box is empty or not finite",
                          proto->name, i);
            return TW_ERR_INVALID;
        }
    }
    return TW_OK;
}

/* ---- the stage tree --------------------------------------------------------- */

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

static int stage_init(struct stage *st, uint32_t cluster_count)
{
    memset(st, 0, sizeof(*st));
    st->node_cap = 2 * cluster_count - 1;
    st->nodes = calloc(st->node_cap, sizeof(*st->nodes));
    st->leaf_clusters = malloc((size_t)cluster_count * sizeof(*st->leaf_clusters));
    if (!st->nodes || !st->leaf_clusters)
        return TW_ERR_NOMEM;
    return TW_OK;
}

static void stage_finish(struct stage *st)
{
    free(st->nodes);
    free(st->leaf_clusters);
    memset(st, 0, sizeof(*st));
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

/* ---- Embree build ------------------------------------------------------------ */

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

int tw_bvh_builder_create(const struct tw_log *log, struct tw_bvh_builder **out)
{
    return tw_bvh_builder_create_ex(log, 0, out);
}

int tw_bvh_builder_create_ex(const struct tw_log *log, uint32_t threads,
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

static int stage_build_embree(struct tw_bvh_builder *b, const struct tw_prototype *proto,
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

    ret = stage_init(st, n);
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

/* ---- median build ----------------------------------------------------------- */

/* Moves the k smallest keys of idx[0, count) (keys[idx[i]]) to the front, the
 * k-th in place (quickselect; ties keep it deterministic, not stable). */
static void select_kth(uint32_t *idx, uint32_t count, uint32_t k, const float *keys)
{
    uint32_t lo = 0, hi = count - 1;
    while (lo < hi) {
        /* Median of three as pivot: sorted or reversed input stays O(n). */
        const uint32_t mid = lo + (hi - lo) / 2;
        float a = keys[idx[lo]], b = keys[idx[mid]], c = keys[idx[hi]];
        float pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        uint32_t i = lo, j = hi;
        while (i <= j) {
            while (keys[idx[i]] < pivot)
                i++;
            while (keys[idx[j]] > pivot)
                j--;
            if (i <= j) {
                const uint32_t t = idx[i];
                idx[i] = idx[j];
                idx[j] = t;
                i++;
                if (j == 0)
                    break;
                j--;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            break;
    }
}

struct median_ctx {
    struct stage *st;
    const struct tw_cluster *clusters;
    float *keys;    /* per cluster, the centre on the current axis */
};

static uint32_t median_split(struct median_ctx *m, uint32_t first, uint32_t count)
{
    struct stage *st = m->st;
    const uint32_t index = st->node_count++;
    uint32_t *idx = st->leaf_clusters + first;

    st->nodes[index].child[0] = st->nodes[index].child[1] = TW_BVH_NONE;
    st->nodes[index].first = first;
    st->nodes[index].count = count;
    if (count == 1) {
        st->nodes[index].triangles = m->clusters[idx[0]].triangle_count;
        return index;
    }

    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < count; i++) {
        const struct tw_box *box = &m->clusters[idx[i]].box;
        for (int k = 0; k < 3; k++) {
            const float c = 0.5f * (box->min[k] + box->max[k]);
            lo[k] = fminf(lo[k], c);
            hi[k] = fmaxf(hi[k], c);
        }
    }
    int axis = 0;
    for (int k = 1; k < 3; k++) {
        if (hi[k] - lo[k] > hi[axis] - lo[axis])
            axis = k;
    }
    for (uint32_t i = 0; i < count; i++) {
        const struct tw_box *box = &m->clusters[idx[i]].box;
        m->keys[idx[i]] = 0.5f * (box->min[axis] + box->max[axis]);
    }
    const uint32_t left_count = count / 2;
    select_kth(idx, count, left_count, m->keys);

    /* Recursion depth is ceil(log2 n): median splits are balanced. */
    const uint32_t left = median_split(m, first, left_count);
    const uint32_t right = median_split(m, first + left_count, count - left_count);
    st->nodes[index].child[0] = left;
    st->nodes[index].child[1] = right;
    st->nodes[index].triangles = st->nodes[left].triangles + st->nodes[right].triangles;
    return index;
}

static int stage_build_median(const struct tw_prototype *proto, struct stage *st)
{
    const uint32_t n = proto->cluster_count;
    int ret = stage_init(st, n);
    if (ret < 0)
        return ret;
    float *keys = malloc((size_t)n * sizeof(*keys));
    if (!keys)
        return TW_ERR_NOMEM;
    for (uint32_t i = 0; i < n; i++)
        st->leaf_clusters[i] = i;
    st->leaf_cluster_count = n;
    struct median_ctx m = {st, proto->clusters, keys};
    median_split(&m, 0, n);
    free(keys);
    return TW_OK;
}

/* ---- flattening --------------------------------------------------------------- */

struct walk {
    uint32_t stage;     /* stage node */
    uint32_t parent;    /* output node, TW_BVH_NONE for the root */
    uint32_t depth;
};

/* Walks the stage tree in pre-order, collapsing a subtree into one leaf at
 * max_depth or below min_leaf_triangles, and returns the node count. With
 * nodes non-NULL it also writes the links, depths and leaf ranges. The stack
 * holds at most depth + 1 <= stage node count entries. */
static uint32_t collapse(const struct stage *st, const struct tw_bvh_settings *s,
                         struct tw_bvh_node *nodes, struct walk *stack)
{
    uint32_t count = 0, top = 0;
    stack[top++] = (struct walk){0, TW_BVH_NONE, 0};
    while (top > 0) {
        const struct walk w = stack[--top];
        const struct stage_node *sn = &st->nodes[w.stage];
        const uint32_t index = count++;
        const bool leaf = sn->child[0] == TW_BVH_NONE || w.depth >= s->max_depth ||
                          sn->triangles < s->min_leaf_triangles;
        if (nodes) {
            struct tw_bvh_node *n = &nodes[index];
            n->parent = w.parent;
            n->depth = w.depth;
            n->child[0] = n->child[1] = TW_BVH_NONE;
            n->first_cluster = leaf ? sn->first : 0;
            n->cluster_count = leaf ? sn->count : 0;
            if (w.parent != TW_BVH_NONE) {
                struct tw_bvh_node *p = &nodes[w.parent];
                p->child[p->child[0] == TW_BVH_NONE ? 0 : 1] = index;
            }
        }
        if (!leaf) {
            /* Right pushed first: the left child is emitted first, so leaves
             * keep the stage's left-to-right cluster order. */
            stack[top++] = (struct walk){sn->child[1], index, w.depth + 1};
            stack[top++] = (struct walk){sn->child[0], index, w.depth + 1};
        }
    }
    return count;
}

/* Sum of the surface areas of node's tight-box frontier: its descendants
 * levels down, or the leaves met before. Writes the boxes if out is
 * non-NULL; returns the count in *count. */
static double frontier(const struct tw_bvh_node *nodes, uint32_t node, uint32_t levels,
                       uint32_t *stack, uint32_t *count, struct tw_box *out)
{
    const uint32_t base_depth = nodes[node].depth;
    double area = 0.0;
    uint32_t top = 0, found = 0;
    stack[top++] = node;
    while (top > 0) {
        const struct tw_bvh_node *n = &nodes[stack[--top]];
        if (n->child[0] == TW_BVH_NONE || n->depth - base_depth == levels) {
            area += tw_box_surface_area(&n->box);
            if (out)
                out[found] = n->box;
            found++;
            continue;
        }
        stack[top++] = n->child[1];
        stack[top++] = n->child[0];
    }
    *count = found;
    return area;
}

static uint64_t bvh_bytes(const struct tw_bvh *bvh)
{
    return sizeof(*bvh) + (uint64_t)bvh->node_count * sizeof(*bvh->nodes) +
           (uint64_t)bvh->cluster_count * sizeof(*bvh->cluster_order) +
           (uint64_t)bvh->tight_box_count * sizeof(*bvh->tight_boxes);
}

/* Turns a stage tree into *out; takes stage's leaf array on success. */
static int flatten(struct stage *st, const struct tw_prototype *proto,
                   const struct tw_bvh_settings *s, const struct tw_log *log,
                   struct tw_bvh **out)
{
    int ret = TW_OK;
    struct tw_bvh *bvh = NULL;
    /* Pre-order stacks hold at most depth + 1 <= node count entries. */
    struct walk *stack = malloc((size_t)(st->node_count + 1) * sizeof(*stack));
    uint32_t *stack_nodes = malloc((size_t)(st->node_count + 1) * sizeof(*stack_nodes));
    if (!stack || !stack_nodes) {
        ret = TW_ERR_NOMEM;
        goto fail;
    }
    if (st->nodes[0].triangles > UINT32_MAX) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "prototype '%.48s': %llu triangles, more than a BVH node can count",
                      proto->name, (unsigned long long)st->nodes[0].triangles);
        ret = TW_ERR_LIMIT;
        goto fail;
    }

    bvh = calloc(1, sizeof(*bvh));
    if (!bvh) {
        ret = TW_ERR_NOMEM;
        goto fail;
    }
    bvh->node_count = collapse(st, s, NULL, stack);
    bvh->nodes = calloc(bvh->node_count, sizeof(*bvh->nodes));
    if (!bvh->nodes) {
        ret = TW_ERR_NOMEM;
        goto fail;
    }
    const uint32_t written = collapse(st, s, bvh->nodes, stack);
    assert(written == bvh->node_count);
    (void)written;

    bvh->cluster_order = st->leaf_clusters;
    bvh->cluster_count = st->leaf_cluster_count;
    st->leaf_clusters = NULL;

    /* Boxes and triangle counts from the clusters up: children come after
     * their parent in pre-order. */
    for (uint32_t i = bvh->node_count; i-- > 0;) {
        struct tw_bvh_node *n = &bvh->nodes[i];
        n->box = tw_box_empty();
        if (n->child[0] == TW_BVH_NONE) {
            uint64_t triangles = 0;
            for (uint32_t c = 0; c < n->cluster_count; c++) {
                const struct tw_cluster *cl = &proto->clusters[bvh->cluster_order[n->first_cluster + c]];
                tw_box_add_box(&n->box, &cl->box);
                triangles += cl->triangle_count;
            }
            n->triangle_count = (uint32_t)triangles;
            n->cluster_total = n->cluster_count;
            bvh->leaf_count++;
        } else {
            const struct tw_bvh_node *l = &bvh->nodes[n->child[0]];
            const struct tw_bvh_node *r = &bvh->nodes[n->child[1]];
            tw_box_add_box(&n->box, &l->box);
            tw_box_add_box(&n->box, &r->box);
            n->triangle_count = l->triangle_count + r->triangle_count;
            n->cluster_total = l->cluster_total + r->cluster_total;
        }
        if (n->depth > bvh->depth)
            bvh->depth = n->depth;
    }

    /* Tight boxes (DESIGN §7): first decide every node's count, then fill. */
    uint64_t tight_total = 0;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        struct tw_bvh_node *n = &bvh->nodes[i];
        uint32_t count = 0;
        const double area = frontier(bvh->nodes, i, s->tight_depth, stack_nodes, &count, NULL);
        const double own = tw_box_surface_area(&n->box);
        n->tight_count = count > 1 && area <= (double)s->tight_area_ratio * own ? count : 1;
        n->first_tight = (uint32_t)tight_total;
        tight_total += n->tight_count;
    }
    if (tight_total > UINT32_MAX) {
        ret = TW_ERR_LIMIT;
        goto fail;
    }
    bvh->tight_box_count = (uint32_t)tight_total;
    bvh->tight_boxes = malloc((size_t)tight_total * sizeof(*bvh->tight_boxes));
    if (!bvh->tight_boxes) {
        ret = TW_ERR_NOMEM;
        goto fail;
    }
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];
        if (n->tight_count == 1) {
            bvh->tight_boxes[n->first_tight] = n->box;
        } else {
            uint32_t count = 0;
            frontier(bvh->nodes, i, s->tight_depth, stack_nodes, &count,
                     bvh->tight_boxes + n->first_tight);
            assert(count == n->tight_count);
        }
    }

    bvh->bytes = bvh_bytes(bvh);
    free(stack_nodes);
    free(stack);
    *out = bvh;
    return TW_OK;

fail:
    tw_bvh_destroy(bvh);
    free(stack_nodes);
    free(stack);
    return ret;
}

/* ---- public builds --------------------------------------------------------- */

/* Both builds: Embree's through b, or the median split when b is NULL. */
static int build(struct tw_bvh_builder *b, const struct tw_prototype *proto,
                 const struct tw_bvh_settings *settings, struct tw_bvh **out)
{
    int ret;
    struct stage st;
    struct tw_bvh_settings s;
    memset(&st, 0, sizeof(st));

    if (!out)
        return TW_ERR_INVALID;
    *out = NULL;
    if (!proto)
        return TW_ERR_INVALID;
    const struct tw_log *log = b ? &b->log : NULL;
    const double start = tw_clock_monotonic_ms();
    ret = check_prototype(proto, log);
    if (ret < 0)
        goto out;
    ret = resolve_settings(settings, proto->name, log, &s);
    if (ret < 0)
        goto out;
    ret = b ? stage_build_embree(b, proto, &st) : stage_build_median(proto, &st);
    if (ret < 0)
        goto out;
    ret = flatten(&st, proto, &s, log, out);
    if (ret < 0)
        goto out;
    (*out)->build_ms = tw_clock_monotonic_ms() - start;

out:
    if (ret == TW_ERR_NOMEM)
        tw_log_printf(log, TW_LOG_ERROR,
                      "prototype '%.48s': out of memory for its bounding volume hierarchy",
                      proto->name);
    stage_finish(&st);
    return ret;
}

int tw_bvh_build(struct tw_bvh_builder *b, const struct tw_prototype *proto,
                 const struct tw_bvh_settings *settings, struct tw_bvh **out)
{
    if (!b) {
        if (out)
            *out = NULL;
        return TW_ERR_INVALID;
    }
    return build(b, proto, settings, out);
}

int tw_bvh_build_median(const struct tw_prototype *proto,
                        const struct tw_bvh_settings *settings, struct tw_bvh **out)
{
    return build(NULL, proto, settings, out);
}

void tw_bvh_destroy(struct tw_bvh *bvh)
{
    if (!bvh)
        return;
    if (bvh->packed) {
        tw_pack_free(bvh, bvh->bytes); /* one block (tw_bvh_pack) */
        return;
    }
    free(bvh->nodes);
    free(bvh->cluster_order);
    free(bvh->tight_boxes);
    free(bvh);
}

/* Lays b out at c (sizing only when c->base is NULL); returns the new struct. */
static void *pack_into(const void *from, struct tw_pack_cursor *c)
{
    const struct tw_bvh *b = from;
    struct tw_bvh *out = tw_pack_take(c, b, sizeof(*b));
    struct tw_bvh_node *nodes = tw_pack_take(c, b->nodes, sizeof(*b->nodes) * b->node_count);
    uint32_t *order =
        tw_pack_take(c, b->cluster_order, sizeof(*b->cluster_order) * b->cluster_count);
    struct tw_box *boxes =
        tw_pack_take(c, b->tight_boxes, sizeof(*b->tight_boxes) * b->tight_box_count);
    if (out) {
        out->nodes = nodes;
        out->cluster_order = order;
        out->tight_boxes = boxes;
        out->packed = true;
        out->bytes = c->used;
    }
    return out;
}

int tw_bvh_pack(struct tw_bvh **bvh)
{
    if (!bvh || !*bvh)
        return TW_ERR_INVALID;
    struct tw_bvh *out = tw_pack_block(*bvh, pack_into);
    if (!out)
        return TW_ERR_NOMEM;
    tw_bvh_destroy(*bvh);
    *bvh = out;
    return TW_OK;
}

/* ---- queries ---------------------------------------------------------------- */

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
