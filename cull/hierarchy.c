/*
 * The hierarchy of cells (cull.h, DESIGN §17): nodes of 2^k x 2^k cells, the
 * cut a frame culls (refined from the top down while the eye is nearer a
 * node's box than its level's radius), a node's neighbours in the cut, and
 * the nodes of the cut in view.
 *
 * Why tile-query propagation stays conservative over a cut (every node's
 * box holds the common box placed at each of its cells; a node's
 * neighbours are the nodes holding a cell next to one of its cells): a
 * chain of cells from the camera's to a visible one, each next to the last,
 * becomes a chain of nodes, each next to the last, by replacing every cell
 * with its node (and merging repeats); a node's box holds each of its
 * cells' boxes, so a query on it passes wherever one on any of its cells'
 * boxes would (the ray to a passing fragment of the smaller box enters the
 * larger one no later). So a node holding a visible cell is reached, as a
 * cell is without the hierarchy.
 */
#include "cull/cull-private.h"
#include "tiles/neighbours.h"
#include "tiles/tiles-internal.h"

#include <math.h>

struct tw_box tw_cull_node_box(const struct tw_cull_grid *g, uint32_t level)
{
    struct tw_box b = g->common_box;
    if (level == 0)
        return b;
    const double span = (double)(((uint64_t)1 << level) - 1);
    b.max[0] = (float)((double)b.max[0] + span * g->footprint[0]);
    b.max[2] = (float)((double)b.max[2] + span * g->footprint[1]);
    return b;
}

/* The base of the node of level holding cell: i and j rounded down to a
 * multiple of 2^level (two's complement masking rounds towards -inf). */
static struct tw_cell align(struct tw_cell cell, uint32_t level)
{
    const uint64_t mask = ~(((uint64_t)1 << level) - 1);
    return (struct tw_cell){(int64_t)((uint64_t)cell.i & mask), (int64_t)((uint64_t)cell.j & mask)};
}

static struct tw_cell moved(struct tw_cell c, int64_t di, int64_t dj)
{
    return (struct tw_cell){(int64_t)((uint64_t)c.i + (uint64_t)di),
                            (int64_t)((uint64_t)c.j + (uint64_t)dj)};
}

static uint32_t top_level(const struct tw_cull_grid *g)
{
    const uint32_t n = g->levels.count;
    return n == 0 ? 0 : (n > TW_CULL_MAX_LEVELS ? TW_CULL_MAX_LEVELS : n) - 1;
}

/* The eye's distance to the box of node (base, level). */
static float node_distance(const struct tw_view *v, const struct tw_cull_grid *g,
                           struct tw_cell base, uint32_t level, const struct tw_box *box)
{
    float off[3];
    tw_tiles_cell_offset(base, v->cell, g->footprint[0], g->footprint[1], off);
    return tw_cull_box_distance(v, box, off);
}

/* Whether node (base, level >= 1) is refined: the eye nearer its box than
 * its level's radius (a radius that is not a number refines nothing). */
static bool refined(const struct tw_view *v, const struct tw_cull_grid *g, struct tw_cell base,
                    uint32_t level, const struct tw_box *box)
{
    return node_distance(v, g, base, level, box) < g->levels.refine[level];
}

uint32_t tw_cull_cover(const struct tw_view *v, const struct tw_cull_grid *g, struct tw_cell cell,
                       struct tw_cell *base)
{
    for (uint32_t k = top_level(g); k > 0; k--) {
        const struct tw_cell b = align(cell, k);
        const struct tw_box box = tw_cull_node_box(g, k);
        if (!refined(v, g, b, k, &box)) {
            if (base)
                *base = b;
            return k;
        }
    }
    if (base)
        *base = cell;
    return 0;
}

/* Adds node (base, level) to out unless it is there already. */
static void add_node(struct tw_cull_cell *out, size_t cap, size_t *n, struct tw_cell base,
                     uint32_t level)
{
    for (size_t k = 0; k < *n && k < cap; k++)
        if (out[k].cell.i == base.i && out[k].cell.j == base.j)
            return;     /* a base names one node of the cut */
    if (*n < cap)
        out[*n] = (struct tw_cull_cell){base, 0.0f, level};
    (*n)++;
}

/* The nodes holding the cells of a side of a node: from cell first, count
 * cells along (di, dj), one node each, skipping the cells of a node found. */
static void walk_side(const struct tw_view *v, const struct tw_cull_grid *g, struct tw_cell first,
                      int64_t di, int64_t dj, uint64_t count, struct tw_cull_cell *out, size_t cap,
                      size_t *n)
{
    uint64_t at = 0;
    while (at < count) {
        const struct tw_cell c = moved(first, di * (int64_t)at, dj * (int64_t)at);
        struct tw_cell base;
        const uint32_t level = tw_cull_cover(v, g, c, &base);
        add_node(out, cap, n, base, level);
        /* The next cell along that this node does not hold. */
        const uint64_t side = (uint64_t)1 << level;
        const uint64_t into = di ? (uint64_t)c.i - (uint64_t)base.i : (uint64_t)c.j - (uint64_t)base.j;
        at += side - into;
    }
}

size_t tw_cull_node_neighbours(const struct tw_view *v, const struct tw_cull_grid *g,
                               struct tw_cell base, uint32_t level, uint32_t neighbours,
                               struct tw_cull_cell *out, size_t cap)
{
    if (neighbours > TW_CELL_NEIGHBOURS)
        neighbours = TW_CELL_NEIGHBOURS;
    size_t n = 0;
    if (!tw_cull_grid_hierarchical(g)) {
        for (uint32_t k = 0; k < neighbours; k++) {
            if (n < cap)
                out[n] = (struct tw_cull_cell){tw_cell_neighbour(base, k), 0.0f, 0};
            n++;
        }
        return n;
    }
    const int64_t s = (int64_t)((uint64_t)1 << level);
    /* The order of tw_cell_neighbour(): +i, -i, +j, -j, then the corners. */
    walk_side(v, g, moved(base, s, 0), 0, 1, (uint64_t)s, out, cap, &n);
    walk_side(v, g, moved(base, -1, 0), 0, 1, (uint64_t)s, out, cap, &n);
    walk_side(v, g, moved(base, 0, s), 1, 0, (uint64_t)s, out, cap, &n);
    walk_side(v, g, moved(base, 0, -1), 1, 0, (uint64_t)s, out, cap, &n);
    if (neighbours > 4) {
        const struct tw_cell corner[4] = {moved(base, s, s), moved(base, s, -1),
                                          moved(base, -1, s), moved(base, -1, -1)};
        for (int k = 0; k < 4; k++) {
            struct tw_cell b;
            const uint32_t l = tw_cull_cover(v, g, corner[k], &b);
            add_node(out, cap, &n, b, l);
        }
    }
    return n;
}

int tw_cull_neighbours_into(const struct tw_view *v, const struct tw_cull_grid *g,
                            struct tw_cell base, uint32_t level, uint32_t neighbours,
                            struct tw_cull_cell **buf, size_t *cap, size_t *count)
{
    for (;;) {
        const size_t n = tw_cull_node_neighbours(v, g, base, level, neighbours, *buf, *cap);
        if (n <= *cap) {
            *count = n;
            return TW_OK;
        }
        if (!tw_cull_reserve((void **)buf, cap, n, sizeof(**buf))) {
            *count = 0;
            return TW_ERR_NOMEM;
        }
    }
}

void tw_cull_nodes_in_view_prefetch(const struct tw_view *v, const struct tw_cull_grid *g,
                                    struct tw_cull_cell *nodes, size_t n)
{
    for (size_t k = 0; k < n; k++) {
        struct tw_cull_cell *c = &nodes[k];
        const struct tw_box box = tw_cull_node_box(g, c->level);
        float off[3];
        tw_tiles_cell_offset(c->cell, v->cell, g->footprint[0], g->footprint[1], off);
        const float d = tw_cull_box_distance(v, &box, off);
        c->distance = d <= v->view_distance &&
                              tw_cull_frustum_box(&v->frustum, &box, off) != TW_CULL_OUTSIDE
                          ? d
                          : INFINITY;
        if (g->source.prefetch && c->distance != INFINITY)
            g->source.prefetch(g->source.ctx, c->cell, c->level, c->distance);
    }
}

/* ---- the nodes of the cut in view --------------------------------------------------- */

struct scan {
    const struct tw_view *v;
    const struct tw_cull_grid *g;
    struct tw_box box[TW_CULL_MAX_LEVELS];
    struct tw_cull_cell *out;
    size_t cap, n;
    uint64_t tested, budget;
    bool truncated;
};

static void visit(struct scan *sc, struct tw_cell base, uint32_t level)
{
    if (sc->tested >= sc->budget) {
        sc->truncated = true;
        return;
    }
    sc->tested++;
    const struct tw_view *v = sc->v;
    float off[3];
    tw_tiles_cell_offset(base, v->cell, sc->g->footprint[0], sc->g->footprint[1], off);
    const float dist = tw_cull_box_distance(v, &sc->box[level], off);
    if (!(dist <= v->view_distance) ||
        tw_cull_frustum_box(&v->frustum, &sc->box[level], off) == TW_CULL_OUTSIDE)
        return;
    if (level > 0 && dist < sc->g->levels.refine[level]) {
        const int64_t h = (int64_t)((uint64_t)1 << (level - 1));
        visit(sc, base, level - 1);
        visit(sc, moved(base, h, 0), level - 1);
        visit(sc, moved(base, 0, h), level - 1);
        visit(sc, moved(base, h, h), level - 1);
        return;
    }
    if (sc->n < sc->cap)
        sc->out[sc->n] = (struct tw_cull_cell){base, dist, level};
    sc->n++;
}

static int compare_nodes(const void *a, const void *b)
{
    return tw_cull_cell_order(a, b);
}

size_t tw_cull_nodes_in_view(const struct tw_view *v, const struct tw_cull_grid *g,
                             struct tw_cull_cell *out, size_t cap, struct tw_cull_scan *scan)
{
    if (!tw_cull_grid_hierarchical(g))
        return tw_cull_cells_in_view_scan(v, &g->common_box, g->footprint[0], g->footprint[1],
                                          out, cap, scan);
    struct scan sc = {.v = v, .g = g, .out = out, .cap = cap,
                      .budget = TW_TILES_MAX_CELLS_IN_VIEW};
    const uint32_t top = top_level(g);
    for (uint32_t k = 0; k <= top; k++)
        sc.box[k] = tw_cull_node_box(g, k);
    const float R = v->view_distance;
    const double W = g->footprint[0], D = g->footprint[1];
    const double S = (double)((uint64_t)1 << top);
    if (!isfinite(W) || !isfinite(D) || !(W > 0.0) || !(D > 0.0) || !(R >= 0.0f) ||
        !isfinite(R) || tw_box_is_empty(&g->common_box))
        goto done;
    /* The top nodes within reach, counted from the one holding the camera's
     * cell: the eye placed relative to that node's base. */
    const struct tw_cell home = align(v->cell, top);
    const double ex = v->eye[0] + (double)((uint64_t)v->cell.i - (uint64_t)home.i) * W;
    const double ez = v->eye[2] + (double)((uint64_t)v->cell.j - (uint64_t)home.j) * D;
    const struct tw_box *tb = &sc.box[top];
    const double i0 = floor((ex - R - tb->max[0]) / (S * W)), i1 = floor((ex + R - tb->min[0]) / (S * W));
    const double j0 = floor((ez - R - tb->max[2]) / (S * D)), j1 = floor((ez + R - tb->min[2]) / (S * D));
    if (!isfinite(i0) || !isfinite(i1) || !isfinite(j0) || !isfinite(j1) || i0 > i1 || j0 > j1)
        goto done;
    /* At most the budget's square of top nodes around the camera's. */
    const double half = floor(sqrt((double)sc.budget) / 2);
    const double lo_i = fmax(i0, -half), hi_i = fmin(i1, half);
    const double lo_j = fmax(j0, -half), hi_j = fmin(j1, half);
    if (lo_i != i0 || hi_i != i1 || lo_j != j0 || hi_j != j1)
        sc.truncated = true;
    /* Ring by ring around the camera's, so that a scan cut short by the
     * budget keeps what is near. */
    const double rings = fmax(fmax(-lo_i, hi_i), fmax(-lo_j, hi_j));
    for (int64_t r = 0; r <= (int64_t)rings && sc.tested < sc.budget; r++)
        for (int64_t k = 0; k < (r == 0 ? 1 : 8 * r); k++) {
            /* The ring's k-th cell: its bottom and top rows, then the sides. */
            int64_t di, dj;
            if (r == 0)
                di = dj = 0;
            else if (k < 2 * r + 1)
                di = k - r, dj = -r;
            else if (k < 4 * r + 2)
                di = k - (2 * r + 1) - r, dj = r;
            else if (k < 6 * r + 1)
                di = -r, dj = k - (4 * r + 2) - r + 1;
            else
                di = r, dj = k - (6 * r + 1) - r + 1;
            if (di < lo_i || di > hi_i || dj < lo_j || dj > hi_j)
                continue;
            visit(&sc, moved(home, (int64_t)((uint64_t)di << top), (int64_t)((uint64_t)dj << top)),
                  top);
        }
    if (sc.n > 1 && sc.n <= cap)
        qsort(out, sc.n, sizeof(*out), compare_nodes);
done:
    if (scan)
        *scan = (struct tw_cull_scan){sc.tested, sc.truncated};
    return sc.n;
}
