/*
 * HZB (cull-private.h): a depth pyramid built on the CPU from the depth buffer read
 * back after phase 1, boxes tested against it, and the two per-tile
 * traversals of the two-phase methods (DESIGN §6; Greene, Kass, Miller 1993
 * for the pyramid, niagara and Nanite for the two phases).
 *
 * Inside the pyramid depths are kept as keys that grow with distance
 * (standard depth as it is, reversed depth negated, which is exact), so that
 * one max-reduction and one comparison serve both conventions.
 */
#include "cull/cull-private.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LEVELS 32

/* How many times a box not hidden as a whole is halved (split_visible). */
#define SPLITS 2

/* Tolerances of the depth comparison, on top of the query box's margin in
 * metres: a box is hidden only when its nearest key exceeds a texel's by
 * more than REL times the texel's magnitude plus ABS. Reversed float depth:
 * a few ulps relative (the CPU's projection and the GPU's interpolation
 * differ by about one). Standard depth is stored in 24 bits: eight steps of
 * 2^-24, since far away one step is wider than the metric margin. */
#define REVERSED_REL 1e-6f
#define STANDARD_ABS (8.0f / 16777216.0f)

struct tw_hzb {
    float *texels;              /* every level, level 0 first */
    size_t texel_cap;
    uint32_t width, height, levels;
    uint32_t level_w[MAX_LEVELS], level_h[MAX_LEVELS];
    size_t level_at[MAX_LEVELS];
    bool reversed;
    bool built;
    float shrink;               /* testing only */
    struct tw_hzb_stats stats;
    struct tw_distance_entry *heap;
    size_t heap_count, heap_cap;
    uint32_t *render;
    size_t render_count, render_cap;
};

int tw_hzb_create(struct tw_hzb **out)
{
    if (!out)
        return TW_ERR_INVALID;
    *out = calloc(1, sizeof(**out));
    return *out ? TW_OK : TW_ERR_NOMEM;
}

void tw_hzb_destroy(struct tw_hzb *h)
{
    if (!h)
        return;
    free(h->texels);
    free(h->heap);
    free(h->render);
    free(h);
}

size_t tw_hzb_bytes(const struct tw_hzb *h)
{
    return h ? sizeof(*h) + h->texel_cap * sizeof(*h->texels) +
                   h->heap_cap * sizeof(*h->heap) + h->render_cap * sizeof(*h->render)
             : 0;
}

void tw_hzb_set_mutation(struct tw_hzb *h, float shrink_fraction)
{
    h->shrink = shrink_fraction > 0.0f && shrink_fraction < 1.0f ? shrink_fraction : 0.0f;
}

/* ---- the pyramid ---------------------------------------------------------------- */

float *tw_hzb_depth_buffer(struct tw_hzb *h, uint32_t width, uint32_t height)
{
    if (!h)
        return NULL;
    h->built = false;
    if (width == 0 || height == 0 || width > 65536 || height > 65536)
        return NULL;
    size_t total = 0;
    uint32_t w = width, hh = height, n = 0;
    for (;;) {
        assert(n < MAX_LEVELS);
        h->level_w[n] = w;
        h->level_h[n] = hh;
        h->level_at[n] = total;
        total += (size_t)w * hh;
        n++;
        if (w == 1 && hh == 1)
            break;
        w = (w + 1) / 2;
        hh = (hh + 1) / 2;
    }
    if (total > h->texel_cap) {
        float *t = realloc(h->texels, total * sizeof(*t));
        if (!t)
            return NULL;
        h->texels = t;
        h->texel_cap = total;
    }
    h->width = width;
    h->height = height;
    h->levels = n;
    return h->texels;
}

static float farther(float a, float b)
{
    return a > b ? a : b;
}

/* dst = the farthest of each 2 x 2 block of src (sw x sh); a block at an odd
 * right or top edge holds only the texels that exist. */
static void reduce(const float *src, uint32_t sw, uint32_t sh, float *dst, uint32_t dw,
                   uint32_t dh)
{
    const uint32_t pairs = sw / 2;
    for (uint32_t y = 0; y < dh; y++) {
        const float *r0 = src + (size_t)(2 * y) * sw;
        const float *r1 = 2 * y + 1 < sh ? r0 + sw : r0;
        float *out = dst + (size_t)y * dw;
        for (uint32_t x = 0; x < pairs; x++)
            out[x] = farther(farther(r0[2 * x], r0[2 * x + 1]), farther(r1[2 * x], r1[2 * x + 1]));
        if (sw & 1)
            out[pairs] = farther(r0[sw - 1], r1[sw - 1]);
    }
}

void tw_hzb_build(struct tw_hzb *h, bool reversed)
{
    if (!h || h->levels == 0)
        return;
    h->reversed = reversed;
    if (reversed) {
        const size_t n = (size_t)h->width * h->height;
        for (size_t k = 0; k < n; k++)
            h->texels[k] = -h->texels[k];
    }
    for (uint32_t k = 1; k < h->levels; k++)
        reduce(h->texels + h->level_at[k - 1], h->level_w[k - 1], h->level_h[k - 1],
               h->texels + h->level_at[k], h->level_w[k], h->level_h[k]);
    h->built = true;
}

void tw_hzb_clear(struct tw_hzb *h)
{
    if (h)
        h->built = false;
}

bool tw_hzb_built(const struct tw_hzb *h)
{
    return h && h->built;
}

uint32_t tw_hzb_levels(const struct tw_hzb *h)
{
    return h && h->built ? h->levels : 0;
}

/* ---- testing a box ----------------------------------------------------------------- */

/* True if query box q (view-relative, margin included) is certainly hidden:
 * its nearest depth lies beyond the farthest depth of every texel its
 * screen rectangle touches. */
static bool box_hidden(const struct tw_hzb *h, const struct tw_view *v, const struct tw_box *q)
{
    /* No rectangle: a corner on or before the near plane (nothing drawn
     * lies in front of it), or figures not finite. */
    float lo[2], hi[2], wmin;
    if (!tw_cull_box_screen_rect(v, q, NULL, lo, hi, &wmin))
        return false;
    const float xmin = lo[0], ymin = lo[1], xmax = hi[0], ymax = hi[1];
    /* Depth is a function of the eye distance w alone: the nearest corner
     * (smallest w) has the nearest depth. */
    const float *proj = h->reversed ? v->proj_rz : v->proj;
    const double ndc = -(double)proj[10] + (double)proj[14] / (double)wmin;
    const float key_near = h->reversed ? (float)-ndc : (float)(0.5 * ndc + 0.5);

    /* Pixels whose centre (i + 0.5) the rectangle may hold, one more on each
     * side for the rasteriser's snapping. */
    const float W = (float)h->width, H = (float)h->height;
    const float fx0 = floorf((xmin * 0.5f + 0.5f) * W - 0.5f);
    const float fx1 = floorf((xmax * 0.5f + 0.5f) * W - 0.5f) + 1.0f;
    const float fy0 = floorf((ymin * 0.5f + 0.5f) * H - 0.5f);
    const float fy1 = floorf((ymax * 0.5f + 0.5f) * H - 0.5f) + 1.0f;
    if (fx1 < 0.0f || fy1 < 0.0f || fx0 > W - 1.0f || fy0 > H - 1.0f)
        return true;    /* it covers no pixel centre of the buffer */
    const uint32_t x0 = fx0 > 0.0f ? (uint32_t)fx0 : 0;
    const uint32_t y0 = fy0 > 0.0f ? (uint32_t)fy0 : 0;
    const uint32_t x1 = fx1 < W - 1.0f ? (uint32_t)fx1 : h->width - 1;
    const uint32_t y1 = fy1 < H - 1.0f ? (uint32_t)fy1 : h->height - 1;
    uint32_t k = 0;
    while (k + 1 < h->levels &&
           ((x1 >> k) - (x0 >> k) >= TW_HZB_SPAN || (y1 >> k) - (y0 >> k) >= TW_HZB_SPAN))
        k++;
    const float *level = h->texels + h->level_at[k];
    const size_t lw = h->level_w[k];
    for (uint32_t ty = y0 >> k; ty <= y1 >> k; ty++) {
        const float *row = level + ty * lw;
        for (uint32_t tx = x0 >> k; tx <= x1 >> k; tx++) {
            const float t = row[tx];
            const float tol = h->reversed ? REVERSED_REL * fabsf(t) : STANDARD_ABS;
            if (!(key_near > t + tol))
                return false;
        }
    }
    return true;
}

/* A box not hidden as a whole may still be: its nearest depth stands for
 * all of it, which is loose for a box that recedes (a street's length of
 * ground, a long facade) or that reaches the near plane. Its two halves
 * along its longest axis each have their own rectangle and nearest depth;
 * the box is hidden if both are, tried SPLITS levels deep. */
static bool split_visible(const struct tw_hzb *h, const struct tw_view *v, const struct tw_box *q,
                          int splits)
{
    if (box_hidden(h, v, q))
        return false;
    if (splits == 0)
        return true;
    int a = 0;
    for (int ax = 1; ax < 3; ax++)
        if (q->max[ax] - q->min[ax] > q->max[a] - q->min[a])
            a = ax;
    struct tw_box lo = *q, hi = *q;
    lo.max[a] = hi.min[a] = 0.5f * (q->min[a] + q->max[a]);
    return split_visible(h, v, &lo, splits - 1) || split_visible(h, v, &hi, splits - 1);
}

bool tw_hzb_visible(const struct tw_hzb *h, const struct tw_view *v, const struct tw_box *b,
                    const float offset[3])
{
    if (!h || !h->built)
        return true;
    struct tw_box q = tw_cull_query_box(v->eye, b, offset);
    if (h->shrink > 0.0f)
        for (int a = 0; a < 3; a++) {
            const float c = 0.5f * (q.min[a] + q.max[a]), r = 0.5f * (q.max[a] - q.min[a]);
            q.min[a] = c - r * (1.0f - h->shrink);
            q.max[a] = c + r * (1.0f - h->shrink);
        }
    return split_visible(h, v, &q, SPLITS);
}

/* ---- the per-tile traversals --------------------------------------------------------- */

size_t tw_hzb_state_bytes(const struct tw_bvh *bvh)
{
    return bvh ? (size_t)bvh->node_count * sizeof(struct tw_hzb_node_state) : 0;
}

void tw_hzb_begin_frame(struct tw_hzb *h)
{
    memset(&h->stats, 0, sizeof(h->stats));
}

const struct tw_hzb_stats *tw_hzb_stats(const struct tw_hzb *h)
{
    return &h->stats;
}

/* Room for a traversal of t: every node pushed at most once, every cluster
 * drawn at most once. */
static bool reserve_tile(struct tw_hzb *h, const struct tw_cull_instance *t)
{
    size_t clusters = t->bvh->cluster_count;
    if (t->proto && t->proto->cluster_count > clusters)
        clusters = t->proto->cluster_count;
    h->heap_count = 0;
    h->render_count = 0;
    return tw_cull_reserve((void **)&h->heap, &h->heap_cap, t->bvh->node_count,
                           sizeof(*h->heap)) &&
           tw_cull_reserve((void **)&h->render, &h->render_cap, clusters, sizeof(*h->render));
}

/* Queues node unless it lies outside the frustum or beyond the view
 * distance (neither drawn nor tested, as CHC++ does). */
static void push_node(struct tw_hzb *h, const struct tw_view *v, const struct tw_cull_instance *t,
                      uint32_t node)
{
    const struct tw_box *b = &t->bvh->nodes[node].box;
    const float d = tw_cull_box_distance(v, b, t->offset);
    if (!(d <= v->view_distance) ||
        tw_cull_frustum_box(&v->frustum, b, t->offset) == TW_CULL_OUTSIDE)
        return;
    assert(h->heap_count < h->heap_cap);
    tw_distance_push(h->heap, &h->heap_count, d, node);
}

static bool is_leaf(const struct tw_bvh_node *n)
{
    return n->child[0] == TW_BVH_NONE;
}

static void queue_leaf(struct tw_hzb *h, const struct tw_cull_instance *t, uint32_t node)
{
    const struct tw_bvh_node *n = &t->bvh->nodes[node];
    for (uint32_t k = 0; k < n->cluster_count; k++)
        h->render[h->render_count++] = t->bvh->cluster_order[n->first_cluster + k];
}

static uint32_t flush_render(struct tw_hzb *h, const struct tw_query_backend *be,
                             const struct tw_cull_instance *t)
{
    const uint32_t n = (uint32_t)h->render_count;
    if (n > 0)
        be->draw(be->ctx, t->cell, t->content, t->offset, h->render, n);
    h->render_count = 0;
    h->stats.clusters_drawn += n;
    return n;
}

static void pull_up(struct tw_hzb_node_state *state, const struct tw_bvh_node *nodes,
                    uint32_t node, uint64_t frame)
{
    while (node != TW_BVH_NONE && state[node].visible_frame != frame) {
        state[node].visible_frame = frame;
        node = nodes[node].parent;
    }
}

static bool tile_valid(const struct tw_cull_instance *t)
{
    return t && t->bvh && t->state && t->bvh->node_count > 0;
}

uint32_t tw_hzb_draw_last_visible(struct tw_hzb *h, const struct tw_view *v,
                                  const struct tw_query_backend *be,
                                  const struct tw_cull_instance *t)
{
    if (!tile_valid(t))
        return 0;
    struct tw_hzb_node_state *state = t->state;
    const uint64_t f = v->frame;
    /* visible_frame 0 means never: there is no frame 0 to have been seen in. */
    if (f < 2 || state[0].visible_frame + 1 != f)
        return 0;
    if (!reserve_tile(h, t))
        return 0;   /* out of memory: phase 2 tests and draws the tile instead */
    const struct tw_bvh_node *nodes = t->bvh->nodes;
    push_node(h, v, t, 0);
    while (h->heap_count > 0) {
        const uint32_t node = tw_distance_pop(h->heap, &h->heap_count);
        if (is_leaf(&nodes[node])) {
            queue_leaf(h, t, node);
            state[node].drawn_frame = f;
            continue;
        }
        for (int c = 0; c < 2; c++) {
            const uint32_t child = nodes[node].child[c];
            if (child != TW_BVH_NONE && state[child].visible_frame + 1 == f)
                push_node(h, v, t, child);
        }
    }
    return flush_render(h, be, t);
}

/* Out of memory: every leaf in view is taken for visible and drawn (unless
 * phase 1 drew it). Conservative, slow, never taken once warm. */
static uint32_t traverse_everything(struct tw_hzb *h, const struct tw_view *v,
                                    const struct tw_query_backend *be,
                                    const struct tw_cull_instance *t)
{
    struct tw_hzb_node_state *state = t->state;
    uint32_t drawn = 0;
    for (uint32_t i = 0; i < t->bvh->node_count; i++) {
        const struct tw_bvh_node *n = &t->bvh->nodes[i];
        if (!is_leaf(n) || !(tw_cull_box_distance(v, &n->box, t->offset) <= v->view_distance) ||
            tw_cull_frustum_box(&v->frustum, &n->box, t->offset) == TW_CULL_OUTSIDE)
            continue;
        pull_up(state, t->bvh->nodes, i, v->frame);
        if (state[i].drawn_frame == v->frame || n->cluster_count == 0)
            continue;
        state[i].drawn_frame = v->frame;
        be->draw(be->ctx, t->cell, t->content, t->offset,
                 &t->bvh->cluster_order[n->first_cluster], n->cluster_count);
        drawn += n->cluster_count;
    }
    h->stats.clusters_drawn += drawn;
    return drawn;
}

uint32_t tw_hzb_traverse(struct tw_hzb *h, const struct tw_view *v,
                         const struct tw_query_backend *be, const struct tw_cull_instance *t)
{
    if (!tile_valid(t))
        return 0;
    if (!reserve_tile(h, t))
        return traverse_everything(h, v, be, t);
    struct tw_hzb_node_state *state = t->state;
    const uint64_t f = v->frame;
    const struct tw_bvh_node *nodes = t->bvh->nodes;
    push_node(h, v, t, 0);
    while (h->heap_count > 0) {
        const uint32_t node = tw_distance_pop(h->heap, &h->heap_count);
        h->stats.boxes_tested++;
        if (!tw_hzb_visible(h, v, &nodes[node].box, t->offset)) {
            h->stats.boxes_hidden++;
            continue;
        }
        if (!is_leaf(&nodes[node])) {
            push_node(h, v, t, nodes[node].child[0]);
            if (nodes[node].child[1] != TW_BVH_NONE)
                push_node(h, v, t, nodes[node].child[1]);
            continue;
        }
        pull_up(state, nodes, node, f);
        if (state[node].drawn_frame != f) {
            state[node].drawn_frame = f;
            queue_leaf(h, t, node);
        }
    }
    return flush_render(h, be, t);
}

bool tw_hzb_retest(struct tw_hzb *h, const struct tw_view *v, const struct tw_cull_instance *t)
{
    if (!tile_valid(t))
        return false;
    struct tw_hzb_node_state *state = t->state;
    const uint64_t f = v->frame;
    const struct tw_bvh_node *nodes = t->bvh->nodes;
    for (uint32_t n = 0; n < t->bvh->node_count; n++)
        if (state[n].visible_frame == f)
            state[n].visible_frame = 0;
    if (!reserve_tile(h, t)) {
        /* Out of memory: every leaf drawn keeps its mark. */
        for (uint32_t n = 0; n < t->bvh->node_count; n++)
            if (is_leaf(&nodes[n]) && state[n].drawn_frame == f)
                pull_up(state, nodes, n, f);
        return state[0].visible_frame == f;
    }
    push_node(h, v, t, 0);
    while (h->heap_count > 0) {
        const uint32_t node = tw_distance_pop(h->heap, &h->heap_count);
        const bool leaf = is_leaf(&nodes[node]);
        /* A leaf not drawn was hidden by a part of this depth already. */
        if (leaf && state[node].drawn_frame != f)
            continue;
        h->stats.boxes_tested++;
        if (!tw_hzb_visible(h, v, &nodes[node].box, t->offset)) {
            h->stats.boxes_hidden++;
            continue;
        }
        if (leaf) {
            pull_up(state, nodes, node, f);
            continue;
        }
        push_node(h, v, t, nodes[node].child[0]);
        if (nodes[node].child[1] != TW_BVH_NONE)
            push_node(h, v, t, nodes[node].child[1]);
    }
    return state[0].visible_frame == f;
}
