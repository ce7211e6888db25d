/*
 * bvh: per-prototype binary BVH over draw clusters (DESIGN.md §1, §7).
 *
 * Both builders (Embree's binned SAH, embree.c, and the median-split
 * reference, median.c) first produce a stage tree (bvh-private.h). One
 * shared flattening pass then applies the leaf rules (max_depth,
 * min_leaf_triangles) by collapsing subtrees into leaves, recomputes tight
 * boxes and triangle counts, and computes the tight-box lists. The stage
 * leaf array becomes tw_bvh.cluster_order as is. The SAH cost and the
 * invariants of a built tree are checked in validate.c.
 */
#include "bvh/bvh-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static bool box_is_valid(const struct tw_box *b)
{
    for (int k = 0; k < 3; k++) {
        if (!isfinite(b->min[k]) || !isfinite(b->max[k]) || b->min[k] > b->max[k])
            return false;
    }
    return true;
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

int tw_bvh_stage_init(struct stage *st, uint32_t cluster_count)
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

/* Every node's box from its clusters up (children come after their
 * parent in pre-order: from the last node up). */
static void fit_boxes(struct tw_bvh *bvh, const struct tw_prototype *proto)
{
    for (uint32_t i = bvh->node_count; i-- > 0;) {
        struct tw_bvh_node *n = &bvh->nodes[i];
        n->box = tw_box_empty();
        if (n->child[0] == TW_BVH_NONE) {
            for (uint32_t c = 0; c < n->cluster_count; c++)
                tw_box_add_box(&n->box,
                               &proto->clusters[bvh->cluster_order[n->first_cluster + c]].box);
        } else {
            tw_box_add_box(&n->box, &bvh->nodes[n->child[0]].box);
            tw_box_add_box(&n->box, &bvh->nodes[n->child[1]].box);
        }
    }
}

/* Every node's tight boxes from the boxes, their counts decided already
 * (stack: room for a frontier's walk). */
static void fill_tight(struct tw_bvh *bvh, uint32_t *stack)
{
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];
        if (n->tight_count == 1) {
            bvh->tight_boxes[n->first_tight] = n->box;
            continue;
        }
        uint32_t count = 0;
        frontier(bvh->nodes, i, bvh->tight_depth, stack, &count, bvh->tight_boxes + n->first_tight);
        assert(count == n->tight_count);
    }
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

    /* Boxes, then triangle counts from the clusters up. */
    fit_boxes(bvh, proto);
    for (uint32_t i = bvh->node_count; i-- > 0;) {
        struct tw_bvh_node *n = &bvh->nodes[i];
        if (n->child[0] == TW_BVH_NONE) {
            uint64_t triangles = 0;
            for (uint32_t c = 0; c < n->cluster_count; c++)
                triangles += proto->clusters[bvh->cluster_order[n->first_cluster + c]]
                                 .triangle_count;
            n->triangle_count = (uint32_t)triangles;
            n->cluster_total = n->cluster_count;
            bvh->leaf_count++;
        } else {
            const struct tw_bvh_node *l = &bvh->nodes[n->child[0]];
            const struct tw_bvh_node *r = &bvh->nodes[n->child[1]];
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
    bvh->tight_depth = s->tight_depth;
    fill_tight(bvh, stack_nodes);
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
    const struct tw_log *log = b ? tw_bvh_builder_log(b) : NULL;
    const double start = tw_clock_monotonic_ms();
    ret = check_prototype(proto, log);
    if (ret < 0)
        goto out;
    ret = resolve_settings(settings, proto->name, log, &s);
    if (ret < 0)
        goto out;
    ret = b ? tw_bvh_stage_embree(b, proto, &st) : tw_bvh_stage_median(proto, &st);
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

/* ---- refitting and joining (moving objects) ---------------------------------------------- */

void tw_bvh_refit(struct tw_bvh *bvh, const struct tw_prototype *proto)
{
    fit_boxes(bvh, proto);
    /* The tight boxes: the same frontiers, as the topology is the same. The
     * depth-first walk holds at most one entry per level and one more:
     * enough for any tree up to 128 deep (builds stop at 32). */
    uint32_t stack[2 * 64 + 2];
    fill_tight(bvh, stack);
}

double tw_bvh_spread(const struct tw_bvh *bvh)
{
    double inner = 0.0, leaves = 0.0;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];
        const double a = tw_box_surface_area(&n->box);
        if (n->child[0] == TW_BVH_NONE)
            leaves += a;
        else
            inner += a;
    }
    return leaves > 0.0 ? 1.0 + inner / leaves : 1.0;
}

/* Copies the nodes of from into to, moving their links by node_shift and
 * their cluster ranges by cluster_shift, one level deeper; their tight
 * boxes from tight_at on: from's own (tight) or one each, the node's box
 * (!tight). */
static void copy_nodes(struct tw_bvh_node *to, const struct tw_bvh *from, uint32_t node_shift,
                       uint32_t cluster_shift, uint32_t tight_at, bool tight)
{
    for (uint32_t i = 0; i < from->node_count; i++) {
        struct tw_bvh_node n = from->nodes[i];
        n.parent = n.parent == TW_BVH_NONE ? 0 : n.parent + node_shift;
        for (int k = 0; k < 2; k++)
            if (n.child[k] != TW_BVH_NONE)
                n.child[k] += node_shift;
        n.first_cluster += cluster_shift;
        if (tight) {
            n.first_tight += tight_at;
        } else {
            n.first_tight = tight_at + i;
            n.tight_count = 1;
        }
        n.depth++;
        to[i] = n;
    }
}

/* b's part of j (nodes 1 + a's onwards, b_capacity of them; its tight
 * boxes one a node, after a's) and the root, from b; the slots b does not
 * fill are leaves of no cluster that no node links to. */
static void join_second(struct tw_bvh *j, const struct tw_bvh *a, const struct tw_bvh *b,
                        uint32_t a_clusters, uint32_t b_capacity)
{
    const uint32_t first = 1 + a->node_count;
    copy_nodes(j->nodes + first, b, first, a->cluster_count, a->tight_box_count, false);
    for (uint32_t i = 0; i < b->node_count; i++)
        j->tight_boxes[a->tight_box_count + i] = b->nodes[i].box;
    for (uint32_t i = b->node_count; i < b_capacity; i++) {
        j->nodes[first + i] = (struct tw_bvh_node){
            .box = b->nodes[0].box, .parent = 0, .child = {TW_BVH_NONE, TW_BVH_NONE},
            .first_tight = a->tight_box_count + i, .tight_count = 1, .depth = 1};
        j->tight_boxes[a->tight_box_count + i] = b->nodes[0].box;
    }
    for (uint32_t c = 0; c < b->cluster_count; c++)
        j->cluster_order[a->cluster_count + c] = b->cluster_order[c] + a_clusters;
    const struct tw_bvh_node *ra = &a->nodes[0], *rb = &b->nodes[0];
    struct tw_bvh_node *root = &j->nodes[0];
    *root = (struct tw_bvh_node){
        .parent = TW_BVH_NONE,
        .child = {1, first},
        .first_tight = j->tight_box_count - 1,
        .tight_count = 1,
        .triangle_count = ra->triangle_count + rb->triangle_count,
        .cluster_total = ra->cluster_total + rb->cluster_total,
    };
    root->box = ra->box;
    tw_box_add_box(&root->box, &rb->box);
    j->tight_boxes[root->first_tight] = root->box;
    j->cluster_count = a->cluster_count + b->cluster_count;
    j->leaf_count = a->leaf_count + b->leaf_count;
    j->depth = 1 + (a->depth > b->depth ? a->depth : b->depth);
    j->tight_depth = a->tight_depth;
}

int tw_bvh_join(const struct tw_bvh *a, uint32_t a_clusters, const struct tw_bvh *b,
                uint32_t b_capacity, struct tw_bvh **out)
{
    *out = NULL;
    if (b_capacity < b->node_count)
        b_capacity = b->node_count;
    if ((uint64_t)a->node_count + b_capacity + 1 > UINT32_MAX ||
        (uint64_t)a->tight_box_count + b_capacity + 1 > UINT32_MAX ||
        (uint64_t)a->cluster_count + b->cluster_count > UINT32_MAX)
        return TW_ERR_LIMIT;
    struct tw_bvh *j = calloc(1, sizeof(*j));
    if (!j)
        return TW_ERR_NOMEM;
    j->node_count = 1 + a->node_count + b_capacity;
    j->tight_box_count = a->tight_box_count + b_capacity + 1;
    j->nodes = malloc((size_t)j->node_count * sizeof(*j->nodes));
    j->cluster_order = malloc(((size_t)a->cluster_count + b->cluster_count) *
                              sizeof(*j->cluster_order));
    j->tight_boxes = malloc((size_t)j->tight_box_count * sizeof(*j->tight_boxes));
    if (!j->nodes || !j->cluster_order || !j->tight_boxes) {
        tw_bvh_destroy(j);
        return TW_ERR_NOMEM;
    }
    copy_nodes(j->nodes + 1, a, 1, 0, 0, true);
    memcpy(j->cluster_order, a->cluster_order, (size_t)a->cluster_count * sizeof(uint32_t));
    memcpy(j->tight_boxes, a->tight_boxes, (size_t)a->tight_box_count * sizeof(struct tw_box));
    join_second(j, a, b, a_clusters, b_capacity);
    j->bytes = bvh_bytes(j);
    *out = j;
    return TW_OK;
}

int tw_bvh_rejoin(struct tw_bvh *j, const struct tw_bvh *a, uint32_t a_clusters,
                  const struct tw_bvh *b)
{
    const uint32_t capacity = j->node_count - 1 - a->node_count;
    if (b->node_count > capacity)
        return TW_ERR_LIMIT;
    const size_t clusters = (size_t)a->cluster_count + b->cluster_count;
    if (clusters != j->cluster_count) {
        uint32_t *order = realloc(j->cluster_order, clusters * sizeof(*order));
        if (!order)
            return TW_ERR_NOMEM;
        j->cluster_order = order;
    }
    join_second(j, a, b, a_clusters, capacity);
    j->bytes = bvh_bytes(j);
    return TW_OK;
}

void tw_bvh_join_refit(struct tw_bvh *j, const struct tw_bvh *a, const struct tw_bvh *b)
{
    for (uint32_t i = 0; i < b->node_count; i++) {
        j->nodes[1 + a->node_count + i].box = b->nodes[i].box;
        j->tight_boxes[a->tight_box_count + i] = b->nodes[i].box;
    }
    struct tw_bvh_node *root = &j->nodes[0];
    root->box = a->nodes[0].box;
    tw_box_add_box(&root->box, &b->nodes[0].box);
    j->tight_boxes[root->first_tight] = root->box;
}
