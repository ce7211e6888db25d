/* Unit tests of the hierarchy of cells (cull/hierarchy.c): the cut is a
 * partition of the plane, the nodes in view cover every cell in view, a
 * node's neighbours are exactly the nodes next to its cells, tile
 * propagation over the cut reaches every node holding a cell that a chain
 * of visible cells joins to the camera's, and a 20 km view stays within
 * the bound of nodes a frame. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cull/cull-private.h"
#include "tests/check.h"
#include "tiles/neighbours.h"
#include "tiles/tiles-internal.h"

#define W 10.0f
#define D 10.0f

static struct tw_cull_grid grid(uint32_t levels, float first_radius)
{
    struct tw_cull_grid g = {
        .footprint = {W, D},
        .common_box = {{0.5f, 0.0f, 0.5f}, {9.5f, 20.0f, 9.5f}},
    };
    g.levels.count = levels;
    /* Each level refined out to twice the last's radius. */
    for (uint32_t k = 1; k < levels; k++)
        g.levels.refine[k] = first_radius * (float)(1u << (k - 1));
    return g;
}

static void view(struct tw_view *v, struct tw_cell cell, float x, float y, float z, float yaw,
                 float pitch, float distance)
{
    const float eye[3] = {x, y, z};
    tw_cull_view_setup(v, cell, eye, yaw, pitch, 60.0f, 16.0f / 9.0f, 0.1f, 100000.0f);
    v->view_distance = distance;
    v->frame = 1;
}

static int64_t side(uint32_t level)
{
    return (int64_t)1 << level;
}

static bool holds(struct tw_cell base, uint32_t level, struct tw_cell c)
{
    return c.i >= base.i && c.i < base.i + side(level) && c.j >= base.j &&
           c.j < base.j + side(level);
}

/* Every cell's node holds it, is aligned, and is the node of each of its
 * cells: the cut is a partition. Near the eye the cut is fine, far it is
 * coarse. */
static void test_cut_is_a_partition(void)
{
    const struct tw_cull_grid g = grid(5, 60.0f);
    struct tw_view v;
    view(&v, (struct tw_cell){-3, 5}, 3.0f, 2.0f, 7.0f, 30.0f, -5.0f, 2000.0f);
    uint32_t deepest = 0, coarsest = 5;
    for (int64_t i = -70; i <= 60; i++)
        for (int64_t j = -60; j <= 70; j++) {
            const struct tw_cell c = {i, j};
            struct tw_cell b;
            const uint32_t k = tw_cull_cover(&v, &g, c, &b);
            CHECK(k < 5 && holds(b, k, c));
            CHECK(b.i % side(k) == 0 && b.j % side(k) == 0);
            /* Its base, and its far corner cell, have the same node. */
            struct tw_cell b2;
            CHECK(tw_cull_cover(&v, &g, b, &b2) == k && b2.i == b.i && b2.j == b.j);
            const struct tw_cell corner = {b.i + side(k) - 1, b.j + side(k) - 1};
            CHECK(tw_cull_cover(&v, &g, corner, &b2) == k && b2.i == b.i && b2.j == b.j);
            if (k > deepest)
                deepest = k;
            if (k < coarsest)
                coarsest = k;
        }
    CHECK(coarsest == 0);       /* the camera's cell is a cell */
    CHECK(deepest == 4);        /* 700 m away, the top level */
    /* The camera's cell, and far out along negative coordinates. */
    struct tw_cell b;
    CHECK(tw_cull_cover(&v, &g, v.cell, &b) == 0 && b.i == -3 && b.j == 5);
    CHECK(tw_cull_cover(&v, &g, (struct tw_cell){-1000, -1000}, &b) == 4 && b.i == -1008 &&
          b.j == -1008);
    /* No hierarchy: every cell is its own node. */
    const struct tw_cull_grid flat = grid(0, 60.0f);
    CHECK(tw_cull_cover(&v, &flat, (struct tw_cell){-1000, 7}, &b) == 0 && b.i == -1000 &&
          b.j == 7);
    /* A node's box holds the common box placed at each of its cells. */
    const struct tw_box nb = tw_cull_node_box(&g, 3);
    CHECK(nb.min[0] == 0.5f && nb.max[0] == 7 * W + 9.5f && nb.max[2] == 7 * D + 9.5f &&
          nb.max[1] == 20.0f);
}

/* The nodes in view: distinct nodes of the cut, front to back, together
 * holding every cell whose common box is in view. */
static void test_nodes_in_view_cover_cells_in_view(void)
{
    static struct tw_cull_cell nodes[TW_TILES_MAX_CELLS_IN_VIEW];
    static struct tw_cull_cell cells[TW_TILES_MAX_CELLS_IN_VIEW];
    const float yaws[] = {0.0f, 45.0f, 133.0f, 260.0f};
    for (size_t t = 0; t < sizeof(yaws) / sizeof(yaws[0]); t++) {
        const struct tw_cull_grid g = grid(5, 40.0f);
        struct tw_view v;
        view(&v, (struct tw_cell){1000, -77}, 4.0f, 3.0f, 6.0f, yaws[t], -10.0f, 600.0f);
        struct tw_cull_scan scan;
        const size_t n = tw_cull_nodes_in_view(&v, &g, nodes, TW_TILES_MAX_CELLS_IN_VIEW, &scan);
        const size_t m = tw_cull_cells_in_view(&v, &g.common_box, W, D, cells,
                                               TW_TILES_MAX_CELLS_IN_VIEW);
        CHECK(n > 0 && !scan.truncated && n < m / 4);
        for (size_t k = 0; k < n; k++) {
            struct tw_cell b;
            CHECK(tw_cull_cover(&v, &g, nodes[k].cell, &b) == nodes[k].level &&
                  b.i == nodes[k].cell.i && b.j == nodes[k].cell.j);
            if (k > 0)
                CHECK(nodes[k - 1].distance <= nodes[k].distance);
            for (size_t q = 0; q < k; q++)
                CHECK(nodes[q].cell.i != nodes[k].cell.i || nodes[q].cell.j != nodes[k].cell.j);
        }
        size_t missing = 0;
        for (size_t c = 0; c < m; c++) {
            struct tw_cell b;
            const uint32_t level = tw_cull_cover(&v, &g, cells[c].cell, &b);
            bool found = false;
            for (size_t k = 0; k < n && !found; k++)
                found = nodes[k].cell.i == b.i && nodes[k].cell.j == b.j &&
                        nodes[k].level == level;
            missing += !found;
        }
        CHECK(missing == 0);
    }
    /* Without a hierarchy it is the cell enumeration itself. */
    const struct tw_cull_grid flat = grid(1, 40.0f);
    struct tw_view v;
    view(&v, (struct tw_cell){0, 0}, 4.0f, 3.0f, 6.0f, 10.0f, -10.0f, 300.0f);
    const size_t n = tw_cull_nodes_in_view(&v, &flat, nodes, TW_TILES_MAX_CELLS_IN_VIEW, NULL);
    const size_t m =
        tw_cull_cells_in_view(&v, &flat.common_box, W, D, cells, TW_TILES_MAX_CELLS_IN_VIEW);
    CHECK(n == m && memcmp(nodes, cells, n * sizeof(*cells)) == 0);
}

/* A node's neighbours are the nodes holding a cell next to one of its
 * cells (4: by an edge; 8: or a corner), each once, and only those. */
static void test_neighbours_are_the_adjacent_nodes(void)
{
    const struct tw_cull_grid g = grid(4, 50.0f);
    struct tw_view v;
    view(&v, (struct tw_cell){2, 3}, 5.0f, 2.0f, 5.0f, 0.0f, 0.0f, 2000.0f);
    struct tw_cull_cell out[256];
    for (int64_t i = -40; i <= 40; i += 3)
        for (int64_t j = -40; j <= 40; j += 5) {
            struct tw_cell b;
            const uint32_t k = tw_cull_cover(&v, &g, (struct tw_cell){i, j}, &b);
            for (uint32_t nb = 4; nb <= 8; nb += 4) {
                const size_t n = tw_cull_node_neighbours(&v, &g, b, k, nb, out, 256);
                CHECK(n <= 256);
                /* Brute force: the nodes of the cells around the node. */
                struct tw_cull_cell want[256];
                size_t w = 0;
                for (int64_t ci = b.i - 1; ci <= b.i + side(k); ci++)
                    for (int64_t cj = b.j - 1; cj <= b.j + side(k); cj++) {
                        const struct tw_cell c = {ci, cj};
                        if (holds(b, k, c))
                            continue;
                        const bool corner = (ci == b.i - 1 || ci == b.i + side(k)) &&
                                            (cj == b.j - 1 || cj == b.j + side(k));
                        if (corner && nb == 4)
                            continue;
                        struct tw_cell cb;
                        const uint32_t cl = tw_cull_cover(&v, &g, c, &cb);
                        bool dup = false;
                        for (size_t q = 0; q < w && !dup; q++)
                            dup = want[q].cell.i == cb.i && want[q].cell.j == cb.j;
                        if (!dup)
                            want[w++] = (struct tw_cull_cell){cb, 0.0f, cl};
                    }
                CHECK(n == w);
                for (size_t q = 0; q < w; q++) {
                    bool found = false;
                    for (size_t r = 0; r < n && !found; r++)
                        found = out[r].cell.i == want[q].cell.i &&
                                out[r].cell.j == want[q].cell.j && out[r].level == want[q].level;
                    CHECK(found);
                }
            }
        }
    /* Too little room: the count says how much to ask for. */
    struct tw_cell b;
    const uint32_t k = tw_cull_cover(&v, &g, (struct tw_cell){40, 40}, &b);
    CHECK(k > 0 && tw_cull_node_neighbours(&v, &g, b, k, 8, out, 1) >= 2);
}

/* ---- propagation over the cut, on a fake backend ------------------------------------ */

/* Which cells hold something visible: a query passes when its box (placed)
 * meets the common box of one of them. An occlusion query on a larger box
 * passes wherever one on a box inside it would, as this one does. */
struct fake {
    const struct tw_view *v;
    const struct tw_cull_grid *g;
    bool *seen;                 /* (i + R) * (2R + 1) + (j + R), R = RANGE */
    struct tw_cell *rendered;
    uint32_t *rendered_level;
    size_t rendered_count;
    uint32_t next_query;
    bool *answers;
    size_t answers_cap;
};
#define RANGE 80

static bool *seen_at(struct fake *fk, struct tw_cell c)
{
    if (c.i < -RANGE || c.i > RANGE || c.j < -RANGE || c.j > RANGE)
        return NULL;
    return &fk->seen[(c.i + RANGE) * (2 * RANGE + 1) + (c.j + RANGE)];
}

static uint32_t fake_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                           const float offset[3])
{
    struct fake *fk = ctx;
    bool passed = false;
    for (uint32_t b = 0; b < count && !passed; b++) {
        /* The cells under the box. */
        const double x0 = boxes[b].min[0] + offset[0], x1 = boxes[b].max[0] + offset[0];
        const double z0 = boxes[b].min[2] + offset[2], z1 = boxes[b].max[2] + offset[2];
        for (int64_t i = (int64_t)floor(x0 / W) - 1; i <= (int64_t)floor(x1 / W) && !passed; i++)
            for (int64_t j = (int64_t)floor(z0 / D) - 1; j <= (int64_t)floor(z1 / D) && !passed;
                 j++) {
                const struct tw_cell c = {fk->v->cell.i + i, fk->v->cell.j + j};
                const bool *s = seen_at(fk, c);
                if (!s || !*s)
                    continue;
                const double cx0 = i * W + fk->g->common_box.min[0];
                const double cx1 = i * W + fk->g->common_box.max[0];
                const double cz0 = j * D + fk->g->common_box.min[2];
                const double cz1 = j * D + fk->g->common_box.max[2];
                passed = cx0 <= x1 && x0 <= cx1 && cz0 <= z1 && z0 <= cz1;
            }
    }
    const uint32_t q = ++fk->next_query;
    if (q >= fk->answers_cap) {
        fk->answers_cap = 2 * q + 64;
        fk->answers = realloc(fk->answers, fk->answers_cap * sizeof(*fk->answers));
    }
    fk->answers[q] = passed;
    return q;
}

static bool fake_ready(void *ctx, uint32_t q)
{
    return false;
}

static uint32_t fake_wait(void *ctx, uint32_t q)
{
    return ((struct fake *)ctx)->answers[q] ? 1 : 0;
}

static void fake_draw(void *ctx, struct tw_cell cell, uint32_t content, const float offset[3],
                      const uint32_t *clusters, uint32_t count)
{
}

static void fake_flush(void *ctx)
{
}

static void render(void *user, struct tw_cell cell, uint32_t level, const float off[3],
                   uint32_t condition)
{
    struct fake *fk = user;
    fk->rendered = realloc(fk->rendered, (fk->rendered_count + 1) * sizeof(*fk->rendered));
    fk->rendered_level =
        realloc(fk->rendered_level, (fk->rendered_count + 1) * sizeof(*fk->rendered_level));
    fk->rendered[fk->rendered_count] = cell;
    fk->rendered_level[fk->rendered_count++] = level;
}

static uint64_t rng(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s;
}

/* Visible cells as random walks from the camera's cell (so a chain of
 * visible cells joins each to it); every node holding one must be rendered,
 * and the walk reaches far cells where the cut is coarse. */
static void test_propagation_reaches_every_visible_cell(void)
{
    const uint32_t neighbours[] = {4, 8};
    for (size_t t = 0; t < 2; t++)
        for (uint64_t seed = 1; seed <= 12; seed++) {
            const struct tw_cull_grid g = grid(5, 30.0f);
            struct tw_view v;
            /* Looking down from high up: the whole square is in the frustum. */
            view(&v, (struct tw_cell){0, 0}, 5.0f, 3000.0f, 5.0f, 0.0f, -89.0f, 5000.0f);
            struct fake fk = {.v = &v, .g = &g};
            fk.seen = calloc((2 * RANGE + 1) * (2 * RANGE + 1), sizeof(*fk.seen));
            uint64_t s = seed * 0x9e3779b97f4a7c15ull;
            for (int walk = 0; walk < 6; walk++) {
                struct tw_cell c = v.cell;
                for (int step = 0; step < 150; step++) {
                    *seen_at(&fk, c) = true;
                    const struct tw_cell nc = tw_cell_neighbour(c, (uint32_t)(rng(&s) % 4));
                    if (seen_at(&fk, nc))
                        c = nc;
                }
            }
            const struct tw_tilequery_settings set = {.neighbours = neighbours[t]};
            struct tw_tilequery *tq;
            CHECK(tw_tilequery_create(&set, &tq) == TW_OK);
            const struct tw_query_backend be = {.ctx = &fk, .issue = fake_issue,
                                                .ready = fake_ready, .wait = fake_wait,
                                                .draw = fake_draw, .flush = fake_flush};
            struct tw_tilequery_stats st;
            CHECK(tw_tilequery_frame(tq, &v, &be, &g, render, NULL, &fk, &st) == TW_OK);
            size_t missed = 0, coarse = 0;
            for (int64_t i = -RANGE; i <= RANGE; i++)
                for (int64_t j = -RANGE; j <= RANGE; j++) {
                    const struct tw_cell c = {i, j};
                    if (!*seen_at(&fk, c))
                        continue;
                    struct tw_cell b;
                    const uint32_t level = tw_cull_cover(&v, &g, c, &b);
                    coarse += level > 0;
                    bool found = false;
                    for (size_t r = 0; r < fk.rendered_count && !found; r++)
                        found = fk.rendered[r].i == b.i && fk.rendered[r].j == b.j &&
                                fk.rendered_level[r] == level;
                    missed += !found;
                }
            CHECK(missed == 0);
            CHECK(coarse > 0);
            /* Rendered nodes are distinct nodes of the cut. */
            for (size_t r = 0; r < fk.rendered_count; r++) {
                struct tw_cell b;
                CHECK(tw_cull_cover(&v, &g, fk.rendered[r], &b) == fk.rendered_level[r] &&
                      b.i == fk.rendered[r].i && b.j == fk.rendered[r].j);
                for (size_t q = 0; q < r; q++)
                    CHECK(fk.rendered[q].i != fk.rendered[r].i ||
                          fk.rendered[q].j != fk.rendered[r].j);
            }
            tw_tilequery_destroy(tq);
            free(fk.seen);
            free(fk.rendered);
            free(fk.rendered_level);
            free(fk.answers);
        }
}

/* A 20 km view of 64 m cells: far beyond the bound as cells, a few
 * thousand nodes at most as a hierarchy whose radii grow with the level. */
static void test_twenty_km_within_the_bound(void)
{
    struct tw_cull_grid g = {
        .footprint = {64.0f, 64.0f},
        .common_box = {{0.0f, 0.0f, 0.0f}, {64.0f, 120.0f, 64.0f}},
    };
    g.levels.count = 9;
    for (uint32_t k = 1; k < 9; k++)
        g.levels.refine[k] = 400.0f * (float)(1u << (k - 1));
    struct tw_view v;
    view(&v, (struct tw_cell){123456789, -987654321}, 30.0f, 40.0f, 20.0f, 20.0f, -2.0f,
         20000.0f);
    struct tw_cull_scan scan;
    const size_t cells = tw_cull_cells_in_view_scan(&v, &g.common_box, 64.0f, 64.0f, NULL, 0, &scan);
    CHECK(scan.truncated);
    struct tw_cull_cell *nodes = calloc(TW_TILES_MAX_CELLS_IN_VIEW, sizeof(*nodes));
    const size_t n = tw_cull_nodes_in_view(&v, &g, nodes, TW_TILES_MAX_CELLS_IN_VIEW, &scan);
    CHECK(!scan.truncated && n > 0 && n < 4000 && scan.cells_tested < 20000);
    uint32_t top = 0;
    float farthest = 0.0f;
    for (size_t k = 0; k < n; k++) {
        if (nodes[k].level > top)
            top = nodes[k].level;
        if (nodes[k].distance > farthest)
            farthest = nodes[k].distance;
    }
    CHECK(top >= 6 && farthest > 15000.0f);
    printf("20 km: %zu nodes (levels up to %u), %llu tested; as cells: %zu in the bound's "
           "square\n",
           n, top, (unsigned long long)scan.cells_tested, cells);
    free(nodes);
}

int main(void)
{
    test_cut_is_a_partition();
    test_nodes_in_view_cover_cells_in_view();
    test_neighbours_are_the_adjacent_nodes();
    test_propagation_reaches_every_visible_cell();
    test_twenty_km_within_the_bound();
    return check_summary("hierarchy");
}
