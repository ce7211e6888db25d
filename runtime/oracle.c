/*
 * The accuracy oracle (DESIGN §8): every cluster that vfc would draw,
 * rendered into an object-ID buffer with the normal pass's transform, then
 * each cluster's visible pixels counted. The ID pass is vfc's own driver
 * drawing through a backend whose draw renders ids.
 */
#include "runtime/world-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Per id of a pass: whether its cluster's box shows (box_shows), once tested. */
enum { BOX_UNKNOWN, BOX_HIDDEN, BOX_SHOWS };

int tw_oracle_init(struct tw_world *w)
{
    struct tw_oracle *o = &w->oracle;
    /* The oracle sees every tile in view, whatever the streaming policy,
     * and what it draws does not count as drawn for the cache. */
    const struct tw_cull_driver_settings vfc = {
        .method = TW_CULL_VFC,
        .source_flags = TW_TILE_SOURCE_WAIT | TW_TILE_SOURCE_QUIET,
    };
    const size_t npix = (size_t)w->s.width * w->s.height;
    o->ids = malloc(sizeof(*o->ids) * npix);
    o->id_depth = malloc(sizeof(*o->id_depth) * npix);
    o->depth = malloc(sizeof(*o->depth) * npix);
    o->blocks_x = (w->s.width + TW_ORACLE_BLOCK - 1) / TW_ORACLE_BLOCK;
    o->blocks_y = (w->s.height + TW_ORACLE_BLOCK - 1) / TW_ORACLE_BLOCK;
    o->block_far = malloc(sizeof(*o->block_far) * o->blocks_x * o->blocks_y);
    if (!o->ids || !o->id_depth || !o->depth || !o->block_far)
        return TW_ERR_NOMEM;
    int err = tw_cell_map_create(&o->tiles);
    if (!err)
        err = tw_cell_map_create(&o->ranks);
    if (!err)
        err = tw_cull_driver_create(&vfc, &o->vfc);
    return err;
}

void tw_oracle_finish(struct tw_oracle *o)
{
    tw_cull_driver_destroy(o->vfc);
    free(o->entries);
    free(o->visible);
    free(o->box_visible);
    free(o->order);
    free(o->pixels);
    free(o->drawn);
    free(o->ids);
    free(o->id_depth);
    free(o->depth);
    free(o->block_far);
    free(o->missed_per_id);
    free(o->box_state);
    tw_cell_map_destroy(o->tiles);
    tw_cell_map_destroy(o->ranks);
    memset(o, 0, sizeof(*o));
}

static int grow(void **array, size_t *cap, size_t need, size_t elem)
{
    return tw_array_reserve(array, cap, need, elem, 4096);
}

struct id_backend {
    struct tw_world *w;
};

/* Draws a tile's clusters with ids o->count, o->count + 1, ... */
static void id_draw(void *ctx, struct tw_cell cell, uint32_t content, const float offset[3],
                    const uint32_t *clusters, uint32_t count)
{
    struct tw_world *w = ((struct id_backend *)ctx)->w;
    struct tw_oracle *o = &w->oracle;
    if (o->err)
        return;
    o->err = grow((void **)&o->entries, &o->cap, o->count + count, sizeof(*o->entries));
    if (!o->err)
        o->err = tw_cell_map_set(o->tiles, cell, ((uint64_t)o->count << 32) | count);
    if (o->err)
        return;
    tw_renderer_id_draw(w->renderer, content, offset, clusters, count, (uint32_t)o->count);
    for (uint32_t c = 0; c < count; c++)
        o->entries[o->count++] = (struct tw_drawn_cluster){
            .cell = cell, .prototype = content, .cluster = clusters[c]};
}

/* vfc issues no query; these are never called. */
static uint32_t id_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                         const float offset[3])
{
    struct tw_world *w = ((struct id_backend *)ctx)->w;
    w->oracle.err = TW_ERR_STATE;
    return 1;
}

static bool id_ready(void *ctx, uint32_t query)
{
    return true;
}

static uint32_t id_wait(void *ctx, uint32_t query)
{
    return 1;
}

static void id_flush(void *ctx)
{
}

/* A cluster of a set, its tile's rank, its distance from the eye (or 0)
 * and what breaks ties (its cluster index, or its place in the set). */
struct oracle_order {
    uint32_t rank;
    float distance;
    uint32_t tie;
    struct tw_drawn_cluster cluster;
};

static int compare_order(const void *a, const void *b)
{
    const struct oracle_order *x = a, *y = b;
    if (x->rank != y->rank)
        return x->rank < y->rank ? -1 : 1;
    if (x->cluster.prototype != y->cluster.prototype)
        return x->cluster.prototype < y->cluster.prototype ? -1 : 1;
    if (x->distance != y->distance)
        return x->distance < y->distance ? -1 : 1;
    return (x->tie > y->tie) - (x->tie < y->tie);
}

int tw_oracle_order(struct tw_world *w, const struct tw_view *v, struct tw_drawn_cluster *set,
                    size_t count, bool front_to_back)
{
    struct tw_oracle *o = &w->oracle;
    if (count == 0)
        return TW_OK;
    int err = grow((void **)&o->order, &o->order_cap, count, sizeof(*o->order));
    if (err)
        return err;
    tw_cell_map_clear(o->ranks);
    uint32_t tiles = 0;
    for (size_t k = 0; k < count; k++) {
        struct oracle_order *e = &o->order[k];
        e->cluster = set[k];
        const uint64_t *rank = tw_cell_map_find(o->ranks, set[k].cell);
        if (rank) {
            e->rank = (uint32_t)*rank;
        } else {
            e->rank = tiles++;
            err = tw_cell_map_set(o->ranks, set[k].cell, e->rank);
            if (err)
                return err;
        }
        e->distance = 0.0f;
        e->tie = front_to_back ? set[k].cluster : (uint32_t)k;
        if (!front_to_back)
            continue;
        /* Each tile's content through the renderer: a shared prototype or a
         * generated tile's own (always live within the frame that drew it). */
        const struct tw_prototype *proto = tw_renderer_content(w->renderer, set[k].prototype, NULL);
        if (proto && set[k].cluster < proto->cluster_count) {
            float offset[3];
            tw_tiles_cell_offset(set[k].cell, v->cell, w->grid.footprint[0], w->grid.footprint[1],
                                 offset);
            e->distance = tw_cull_box_distance(v, &proto->clusters[set[k].cluster].box, offset);
        }
    }
    qsort(o->order, count, sizeof(*o->order), compare_order);
    for (size_t k = 0; k < count; k++)
        set[k] = o->order[k].cluster;
    return TW_OK;
}

double tw_eye_distance(double d, double n, double f, bool reversed)
{
    if (reversed)   /* d = n (f / z - 1) / (f - n) */
        return f * n / (d * (f - n) + n);
    const double z_ndc = 2.0 * d - 1.0;
    return 2.0 * f * n / ((f + n) - z_ndc * (f - n));
}

/* The farthest eye distance of the pass's depth in each block of pixels:
 * the eye distance of the block's farthest depth (eye distance grows with
 * window depth, or shrinks with it when depth is reversed). */
static void block_distances(struct tw_world *w, const struct tw_view *v)
{
    struct tw_oracle *o = &w->oracle;
    const uint32_t width = w->s.width, height = w->s.height;
    const bool reversed = tw_renderer_reversed_z(w->renderer);
    for (uint32_t by = 0; by < o->blocks_y; by++)
        for (uint32_t bx = 0; bx < o->blocks_x; bx++) {
            float far = reversed ? 1.0f : 0.0f;
            const uint32_t x1 = bx * TW_ORACLE_BLOCK + TW_ORACLE_BLOCK;
            const uint32_t y1 = by * TW_ORACLE_BLOCK + TW_ORACLE_BLOCK;
            for (uint32_t y = by * TW_ORACLE_BLOCK; y < y1 && y < height; y++)
                for (uint32_t x = bx * TW_ORACLE_BLOCK; x < x1 && x < width; x++) {
                    const float d = o->id_depth[(size_t)y * width + x];
                    far = reversed ? fminf(far, d) : fmaxf(far, d);
                }
            o->block_far[(size_t)by * o->blocks_x + bx] =
                (float)tw_eye_distance(far, v->near_plane, v->far_plane, reversed);
        }
}

int tw_oracle_pass(struct tw_world *w, const struct tw_view *v)
{
    struct tw_oracle *o = &w->oracle;
    o->count = 0;
    o->err = TW_OK;
    tw_cell_map_clear(o->tiles);
    tw_renderer_id_begin(w->renderer, v);
    struct id_backend ib = {w};
    const struct tw_query_backend be = {.ctx = &ib, .issue = id_issue, .ready = id_ready,
                                        .wait = id_wait, .draw = id_draw, .flush = id_flush};
    int err = tw_cull_driver_frame(o->vfc, v, &w->grid, &be, &w->cur->cells, NULL);
    if (!err)
        err = o->err;
    if (err)
        return err;
    if (o->count > o->per_id_cap) {
        free(o->pixels);
        free(o->drawn);
        free(o->missed_per_id);
        free(o->box_state);
        o->pixels = malloc(sizeof(*o->pixels) * o->count);
        o->drawn = malloc(o->count);
        o->missed_per_id = malloc(sizeof(*o->missed_per_id) * o->count);
        o->box_state = malloc(o->count);
        o->per_id_cap =
            o->pixels && o->drawn && o->missed_per_id && o->box_state ? o->count : 0;
        if (!o->per_id_cap)
            return TW_ERR_NOMEM;
    }
    if (o->count > 0) {     /* a frame with nothing to draw has no arrays yet */
        memset(o->pixels, 0, sizeof(*o->pixels) * o->count);
        memset(o->box_state, BOX_UNKNOWN, o->count);
    }
    tw_renderer_id_read(w->renderer, o->ids, o->id_depth);
    block_distances(w, v);
    const size_t npix = (size_t)w->s.width * w->s.height;
    for (size_t k = 0; k < npix; k++)
        if (o->ids[k] < o->count)
            o->pixels[o->ids[k]]++;
    /* The oracle method's set: the clusters with visible pixels, tile by tile. */
    o->visible_count = 0;
    err = grow((void **)&o->visible, &o->visible_cap, o->count, sizeof(*o->visible));
    if (err)
        return err;
    for (size_t k = 0; k < o->count; k++)
        if (o->pixels[k] > 0)
            o->visible[o->visible_count++] = o->entries[k];
    return tw_oracle_order(w, v, o->visible, o->visible_count, true);
}

/* Whether depths a and b name one surface for a user: their eye distances
 * differ by at most tol of the nearer one, or (fixed-point depth) by two
 * steps of the buffer at most. */
static bool same_surface(float a, float b, const struct tw_oracle_depth *dm)
{
    if (a == b)
        return true;
    const double za = tw_eye_distance(a, dm->n, dm->f, dm->reversed);
    const double zb = tw_eye_distance(b, dm->n, dm->f, dm->reversed);
    const double near = za < zb ? za : zb;
    double slack = dm->tol * near;
    if (!dm->reversed) {
        /* 24-bit depth: two steps of 2^-24, in metres at this distance. */
        const double step = 2.0 / 16777216.0;
        slack += fabs(tw_eye_distance(a + step, dm->n, dm->f, false) - za);
    }
    return fabs(za - zb) <= slack;
}

/* Whether the ray through the centre of pixel (x, y) meets box q at an eye
 * distance within the verify tolerance of the true depth's or nearer. The
 * ray is parametrised by eye-space depth: its eye-space direction is
 * (x, y, -1), turned into view-relative space by the view's rotation,
 * transposed (view is rigid). */
static bool pixel_shows(const struct tw_view *v, const struct tw_box *q, uint32_t x, uint32_t y,
                        double depth, uint32_t width, uint32_t height,
                        const struct tw_oracle_depth *dm)
{
    const float *m = v->view, *p = v->proj;
    const double ndc[2] = {2.0 * (x + 0.5) / width - 1.0, 2.0 * (y + 0.5) / height - 1.0};
    const double e[3] = {(ndc[0] + p[8]) / p[0], (ndc[1] + p[9]) / p[5], -1.0};
    double t0 = 0.0, t1 = INFINITY;
    for (int a = 0; a < 3 && t0 <= t1; a++) {
        const double d = m[4 * a] * e[0] + m[4 * a + 1] * e[1] + m[4 * a + 2] * e[2];
        const double o = v->eye[a];
        if (fabs(d) < 1e-12) {
            if (o < q->min[a] || o > q->max[a])
                t0 = INFINITY;
            continue;
        }
        double ta = (q->min[a] - o) / d, tb = (q->max[a] - o) / d;
        if (ta > tb) {
            const double t = ta;
            ta = tb;
            tb = t;
        }
        t0 = fmax(t0, ta);
        t1 = fmin(t1, tb);
    }
    return t0 <= t1 && t0 <= tw_eye_distance(depth, dm->n, dm->f, dm->reversed) * (1.0 + dm->tol);
}

/* Whether an occlusion query of box b (tile-local, moved by offset), or of
 * any box containing it, must find it visible: whether at some pixel
 * centre b lies in front of the frame's true depth (the ID pass's, of every
 * cluster vfc draws), its eye distance within the verify tolerance of that
 * depth's or nearer. The box is b itself, not the larger box a query draws
 * (tw_cull_query_box): the margin grows with distance, so the query box of a
 * node containing b, being nearer, may not contain b's own query box. A box
 * within reach of the near plane (tw_cull_near_box's radius) counts as
 * showing: no box containing it is ever queried. Otherwise every point of
 * it in view lies beyond the near plane, and blocks of pixels whose
 * farthest true depth lies nearer than the box's nearest point in view are
 * passed over whole. */
static bool box_shows(const struct tw_view *v, const struct tw_box *b, const float offset[3],
                      const struct tw_oracle *o, uint32_t width, uint32_t height,
                      const struct tw_oracle_depth *dm)
{
    struct tw_box q;
    for (int a = 0; a < 3; a++) {
        q.min[a] = b->min[a] + offset[a];
        q.max[a] = b->max[a] + offset[a];
    }
    if (tw_cull_box_distance(v, &q, NULL) <= tw_cull_near_reach(v))
        return true;
    float lo[2], hi[2], w_min;
    double x0 = 0.0, x1 = width, y0 = 0.0, y1 = height;
    if (tw_cull_box_screen_rect(v, &q, NULL, lo, hi, &w_min)) {
        x0 = fmax(0.0, floor((lo[0] * 0.5 + 0.5) * width));
        x1 = fmin(width, ceil((hi[0] * 0.5 + 0.5) * width));
        y0 = fmax(0.0, floor((lo[1] * 0.5 + 0.5) * height));
        y1 = fmin(height, ceil((hi[1] * 0.5 + 0.5) * height));
    } else {
        /* A corner behind the near plane, but the box out of its reach:
         * what of it is in view lies beyond the near plane. Every pixel. */
        w_min = v->near_plane;
    }
    if (!(x0 < x1 && y0 < y1))
        return false;
    /* A block is passed over when even its farthest depth, with the
     * tolerance and a margin for the float distances, is nearer than the
     * box's nearest corner (an eye-space depth, as the rays' are). */
    const double slack = (1.0 + dm->tol) * (1.0 + 1e-5);
    const uint32_t px0 = (uint32_t)x0, px1 = (uint32_t)x1, py0 = (uint32_t)y0, py1 = (uint32_t)y1;
    for (uint32_t by = py0 / TW_ORACLE_BLOCK; by <= (py1 - 1) / TW_ORACLE_BLOCK; by++) {
        for (uint32_t bx = px0 / TW_ORACLE_BLOCK; bx <= (px1 - 1) / TW_ORACLE_BLOCK; bx++) {
            if ((double)w_min > o->block_far[(size_t)by * o->blocks_x + bx] * slack)
                continue;
            const uint32_t ya = by * TW_ORACLE_BLOCK > py0 ? by * TW_ORACLE_BLOCK : py0;
            const uint32_t yb = (by + 1) * TW_ORACLE_BLOCK < py1 ? (by + 1) * TW_ORACLE_BLOCK : py1;
            const uint32_t xa = bx * TW_ORACLE_BLOCK > px0 ? bx * TW_ORACLE_BLOCK : px0;
            const uint32_t xb = (bx + 1) * TW_ORACLE_BLOCK < px1 ? (bx + 1) * TW_ORACLE_BLOCK : px1;
            for (uint32_t y = ya; y < yb; y++)
                for (uint32_t x = xa; x < xb; x++)
                    if (pixel_shows(v, &q, x, y, o->id_depth[(size_t)y * width + x], width,
                                    height, dm))
                        return true;
        }
    }
    return false;
}

/* Whether drawn cluster d's box shows (box_shows) in view v of the pass;
 * id is its id in the pass, or UINT32_MAX for a cluster vfc does not draw.
 * A cluster's answer is kept for the pass: the box oracle's set and the
 * comparison ask about the same clusters. */
static bool cluster_box_shows(struct tw_world *w, const struct tw_view *v,
                              const struct tw_drawn_cluster *d, uint32_t id,
                              const struct tw_oracle_depth *dm)
{
    struct tw_oracle *o = &w->oracle;
    if (id != UINT32_MAX && o->box_state[id] != BOX_UNKNOWN)
        return o->box_state[id] == BOX_SHOWS;
    const struct tw_cluster *cl =
        &tw_renderer_content(w->renderer, d->prototype, NULL)->clusters[d->cluster];
    float offset[3];
    tw_tiles_cell_offset(d->cell, v->cell, w->grid.footprint[0], w->grid.footprint[1], offset);
    const bool shows = box_shows(v, &cl->box, offset, o, w->s.width, w->s.height, dm);
    if (id != UINT32_MAX)
        o->box_state[id] = shows ? BOX_SHOWS : BOX_HIDDEN;
    return shows;
}

/* A drawn cluster with no visible pixel (id as for cluster_box_shows):
 * overdraw, and whether its box would have shown to a query all the same. */
static void count_overdraw(struct tw_world *w, const struct tw_drawn_cluster *d,
                           const struct tw_cluster *cl, uint32_t id,
                           const struct tw_oracle_depth *dm, struct tw_frame_stats *st)
{
    st->overdraw_triangles += cl->triangle_count;
    if (cluster_box_shows(w, &w->cur->last_view, d, id, dm))
        st->overdraw_box_triangles += cl->triangle_count;
}

static struct tw_oracle_depth depth_model(const struct tw_world *w, const struct tw_view *v)
{
    return (struct tw_oracle_depth){
        .n = v->near_plane,
        .f = v->far_plane,
        .reversed = tw_renderer_reversed_z(w->renderer),
        .tol = w->s.verify_tolerance,
    };
}

int tw_oracle_box_set(struct tw_world *w, const struct tw_view *v)
{
    struct tw_oracle *o = &w->oracle;
    o->box_visible_count = 0;
    int err = grow((void **)&o->box_visible, &o->box_visible_cap, o->count,
                   sizeof(*o->box_visible));
    if (err)
        return err;
    const struct tw_oracle_depth dm = depth_model(w, v);
    for (size_t k = 0; k < o->count; k++)
        if (o->pixels[k] > 0 || cluster_box_shows(w, v, &o->entries[k], (uint32_t)k, &dm))
            o->box_visible[o->box_visible_count++] = o->entries[k];
    return tw_oracle_order(w, v, o->box_visible, o->box_visible_count, true);
}

void tw_oracle_compare(struct tw_world *w, struct tw_frame_stats *st)
{
    struct tw_oracle *o = &w->oracle;
    if (o->count > 0) {     /* a frame with nothing to draw has no arrays yet */
        memset(o->drawn, 0, o->count);
        memset(o->missed_per_id, 0, sizeof(*o->missed_per_id) * o->count);
    }
    const struct tw_view *v = &w->cur->last_view;
    const struct tw_oracle_depth dm = depth_model(w, v);
    size_t n = 0;
    const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
    for (size_t k = 0; k < n; k++) {
        const uint64_t *range = tw_cell_map_find(o->tiles, d[k].cell);
        const struct tw_cluster *cl =
            &tw_renderer_content(w->renderer, d[k].prototype, NULL)->clusters[d[k].cluster];
        if (!range) {
            /* Drawn where vfc would draw nothing: wasted. */
            count_overdraw(w, &d[k], cl, UINT32_MAX, &dm, st);
            continue;
        }
        /* Ids of a tile are its clusters in ascending order: binary search. */
        const uint32_t first = (uint32_t)(*range >> 32), end = first + (uint32_t)*range;
        uint32_t lo = first, hi = end;
        while (lo < hi) {
            const uint32_t mid = lo + (hi - lo) / 2;
            if (o->entries[mid].cluster < d[k].cluster)
                lo = mid + 1;
            else
                hi = mid;
        }
        if (lo < end && o->entries[lo].cluster == d[k].cluster) {
            if (!o->drawn[lo] && o->pixels[lo] == 0)
                count_overdraw(w, &d[k], cl, lo, &dm, st);
            o->drawn[lo] = 1;
        } else {
            count_overdraw(w, &d[k], cl, UINT32_MAX, &dm, st);
        }
    }
    /* Pixel by pixel: an undrawn visible cluster is an error only where what
     * the method shows instead lies farther; where the two surfaces touch
     * (a depth tie), the user sees the same thing. */
    tw_renderer_read_depth(w->renderer, o->depth);
    const size_t npix = (size_t)w->s.width * w->s.height;
    for (size_t k = 0; k < npix; k++) {
        const bool same = same_surface(o->depth[k], o->id_depth[k], &dm);
        st->depth_errors += !same;
        const uint32_t id = o->ids[k];
        if (id >= o->count || o->drawn[id] || same)
            continue;
        /* Reversed depth grows towards the eye; standard depth away from it. */
        const bool farther = dm.reversed ? o->depth[k] < o->id_depth[k]
                                         : o->depth[k] > o->id_depth[k];
        if (farther)
            o->missed_per_id[id]++;
    }
    for (size_t id = 0; id < o->count; id++) {
        if (o->missed_per_id[id] == 0)
            continue;
        st->missed_pixels += o->missed_per_id[id];
        st->missed_clusters++;
    }
}
