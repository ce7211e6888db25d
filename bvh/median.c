/*
 * The median-split builder (tw_bvh_build_median): the stage tree
 * (bvh-private.h) split at the median cluster centre along the longest
 * axis, no SAH, no Embree; the reference SAH is compared against.
 */
#include "bvh/bvh-private.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>

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

int tw_bvh_stage_median(const struct tw_prototype *proto, struct stage *st)
{
    const uint32_t n = proto->cluster_count;
    int ret = tw_bvh_stage_init(st, n);
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
