/*
 * The depth pyramid and the two-phase HZB methods (cull/hzb.c, DESIGN §6)
 * against deterministic depth buffers made here, no GL: what the pyramid
 * proves hidden is hidden (walls, a pixel that peeks out, the near plane,
 * odd sizes, both depth conventions, random buffers against brute force),
 * the per-tile traversals and the method drivers over a fake backend whose
 * read_depth hands out such a buffer.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bvh/bvh.h"
#include "cull/cull-private.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

/* ---- depth buffers ------------------------------------------------------------------ */

/* Window depth at eye distance w (clip w) in a convention: reversed float
 * depth, or standard depth stored in 24 bits. */
static float window_depth(const struct tw_view *v, bool reversed, double w)
{
    if (reversed)
        return (float)(-(double)v->proj_rz[10] + (double)v->proj_rz[14] / w);
    const double d = 0.5 * (-(double)v->proj[10] + (double)v->proj[14] / w) + 0.5;
    return (float)(round(d * 16777215.0) / 16777215.0);
}

static float far_depth(bool reversed)
{
    return reversed ? 0.0f : 1.0f;
}

/* a is nearer than b in the convention. */
static bool nearer(bool reversed, float a, float b)
{
    return reversed ? a > b : a < b;
}

struct buffer {
    uint32_t w, h;
    bool reversed;
    float *depth;
};

static void fill(struct buffer *b, float d)
{
    for (size_t k = 0; k < (size_t)b->w * b->h; k++)
        b->depth[k] = d;
}

/* Draws the pixel rectangle [x0, x1) x [y0, y1) at depth d, depth-tested. */
static void draw_rect(struct buffer *b, int x0, int y0, int x1, int y1, float d)
{
    for (int y = y0 < 0 ? 0 : y0; y < y1 && y < (int)b->h; y++)
        for (int x = x0 < 0 ? 0 : x0; x < x1 && x < (int)b->w; x++) {
            float *p = &b->depth[(size_t)y * b->w + (size_t)x];
            if (nearer(b->reversed, d, *p))
                *p = d;
        }
}

/* A pyramid of b (copied, as a renderer reads its depth into it). */
static void build(struct tw_hzb *h, const struct buffer *b)
{
    float *dst = tw_hzb_depth_buffer(h, b->w, b->h);
    CHECK(dst != NULL);
    if (!dst)
        return;
    memcpy(dst, b->depth, sizeof(*dst) * b->w * b->h);
    tw_hzb_build(h, b->reversed);
}

/* A w x h buffer and a pyramid engine; false (logged) when out of memory. */
static bool setup(struct buffer *b, struct tw_hzb **h, uint32_t w, uint32_t hgt, bool reversed)
{
    *b = (struct buffer){w, hgt, reversed, malloc(sizeof(float) * w * hgt)};
    *h = NULL;
    CHECK(tw_hzb_create(h) == TW_OK && b->depth);
    return *h && b->depth;
}

/* The camera at the origin looking along +z, fov 60, the buffer's aspect. */
static struct tw_view view_for(const struct buffer *b)
{
    struct tw_view v;
    const float eye[3] = {0, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 60.0f,
                       (float)b->w / (float)b->h, 0.2f, 1000.0f);
    v.view_distance = 900.0f;
    v.frame = 1;
    return v;
}

/* The exact window rectangle of b's query box (x0, y0, x1, y1) and its
 * nearest eye distance; false if it reaches the near plane. */
static bool window_rect(const struct tw_view *v, const struct buffer *buf, const struct tw_box *b,
                        double r[4], double *wmin)
{
    const struct tw_box q = tw_cull_query_box(v->eye, b, NULL);
    r[0] = r[1] = INFINITY;
    r[2] = r[3] = -INFINITY;
    *wmin = INFINITY;
    for (int c = 0; c < 8; c++) {
        const double p[3] = {c & 1 ? q.max[0] : q.min[0], c & 2 ? q.max[1] : q.min[1],
                             c & 4 ? q.max[2] : q.min[2]};
        double clip[4];
        for (int row = 0; row < 4; row++)
            clip[row] = v->view_proj[row] * p[0] + v->view_proj[4 + row] * p[1] +
                        v->view_proj[8 + row] * p[2] + v->view_proj[12 + row];
        if (clip[3] <= v->near_plane)
            return false;
        const double x = (clip[0] / clip[3] * 0.5 + 0.5) * buf->w;
        const double y = (clip[1] / clip[3] * 0.5 + 0.5) * buf->h;
        r[0] = fmin(r[0], x);
        r[1] = fmin(r[1], y);
        r[2] = fmax(r[2], x);
        r[3] = fmax(r[3], y);
        *wmin = fmin(*wmin, clip[3]);
    }
    return true;
}

/* A box of half size s (x, y) and depth extent dz centred on the view axis
 * direction through window point (px, py) at eye distance z. */
static struct tw_box box_at(const struct tw_view *v, const struct buffer *buf, double px,
                            double py, float z, float s, float dz)
{
    /* Eye space: x right, y up, looking down -z; world x = -eye x here. */
    const double t = 1.0 / tan(30.0 * 3.14159265358979323846 / 180.0);
    const double aspect = (double)buf->w / buf->h;
    const double xn = px / buf->w * 2.0 - 1.0, yn = py / buf->h * 2.0 - 1.0;
    const double ex = xn * z * aspect / t, ey = yn * z / t;
    (void)v;
    const struct tw_box b = {{(float)-ex - s, (float)ey - s, z},
                             {(float)-ex + s, (float)ey + s, z + dz}};
    return b;
}

/* ---- the pyramid ---------------------------------------------------------------------- */

/* A box behind a full-screen wall is hidden; one in front of it, one that
 * crosses it, and one across the near plane are not. */
static void test_wall(uint32_t w, uint32_t hgt, bool reversed)
{
    struct buffer b;
    struct tw_hzb *h;
    if (!setup(&b, &h, w, hgt, reversed))
        goto out;
    const struct tw_view v = view_for(&b);
    const struct tw_box ahead = {{-1, -1, 30}, {1, 1, 31}};
    CHECK(tw_hzb_visible(h, &v, &ahead, NULL));     /* no pyramid yet */
    fill(&b, window_depth(&v, reversed, 20.0));
    build(h, &b);
    CHECK(tw_hzb_built(h));
    const struct tw_box behind = {{-3, -3, 25}, {3, 3, 30}};
    const struct tw_box far_behind = {{-100, -50, 400}, {100, 50, 500}};
    const struct tw_box front = {{-1, -1, 10}, {1, 1, 12}};
    const struct tw_box across = {{-1, -1, 15}, {1, 1, 25}};
    const struct tw_box just_behind = {{-1, -1, 20.2f}, {1, 1, 21}};
    CHECK(!tw_hzb_visible(h, &v, &behind, NULL));
    CHECK(!tw_hzb_visible(h, &v, &far_behind, NULL));
    CHECK(!tw_hzb_visible(h, &v, &just_behind, NULL));
    CHECK(tw_hzb_visible(h, &v, &front, NULL));
    CHECK(tw_hzb_visible(h, &v, &across, NULL));
    /* Moved by an offset: the same box 20 m nearer is in front. */
    CHECK(tw_hzb_visible(h, &v, &behind, (const float[3]){0, 0, -20}));
    /* Across the near plane: visible even behind a wall just past it. */
    fill(&b, window_depth(&v, reversed, 0.25));
    build(h, &b);
    const struct tw_box eye_inside = {{-1, -1, -1}, {1, 1, 30}};
    const struct tw_box near_cut = {{-0.01f, -0.01f, 0.1f}, {0.01f, 0.01f, 40}};
    const struct tw_box beside = {{5, -1, -2}, {6, 1, 30}};   /* reaches behind the eye */
    CHECK(tw_hzb_visible(h, &v, &eye_inside, NULL));
    CHECK(tw_hzb_visible(h, &v, &near_cut, NULL));
    CHECK(tw_hzb_visible(h, &v, &beside, NULL));
    CHECK(!tw_hzb_visible(h, &v, &behind, NULL));
    /* Cleared: nothing is hidden. */
    tw_hzb_clear(h);
    CHECK(!tw_hzb_built(h) && tw_hzb_levels(h) == 0);
    CHECK(tw_hzb_visible(h, &v, &behind, NULL));
out:
    tw_hzb_destroy(h);
    free(b.depth);
}

/* A small box behind a wall that ends at column edge (the rest far): visible
 * as long as its rectangle reaches a pixel centre past the edge, hidden once
 * two columns separate them (the pyramid's outward rounding); likewise for a
 * row edge. At each position along the odd buffer's right and top borders
 * too, where level texels cover partial blocks. */
static void test_peek(uint32_t w, uint32_t hgt, bool reversed)
{
    struct buffer b;
    struct tw_hzb *h;
    if (!setup(&b, &h, w, hgt, reversed))
        goto out;
    const struct tw_view v = view_for(&b);
    const float wall = window_depth(&v, reversed, 20.0);
    int visible_ok = 0, hidden_ok = 0, cases = 0;
    for (int axis = 0; axis < 2; axis++) {
        const uint32_t n = axis == 0 ? w : hgt;
        for (uint32_t pos = 3; pos < n; pos += pos < n - 12 ? 37 : 1) {
            /* A box ~3 px wide centred at pos along the axis, mid-screen on the other. */
            const double px = axis == 0 ? pos : w / 2.0, py = axis == 0 ? hgt / 2.0 : pos;
            const struct tw_box box = box_at(&v, &b, px, py, 30.0f, 0.05f, 1.0f);
            double r[4], wmin;
            if (!window_rect(&v, &b, &box, r, &wmin))
                continue;
            const double hi = axis == 0 ? r[2] : r[3];
            /* Last pixel whose centre the rectangle holds. */
            const int last = (int)floor(hi - 0.5);
            for (int gap = 0; gap < 2; gap++) {
                const int edge = gap == 0 ? last : last + 3;
                if (edge >= (int)n)
                    continue;
                fill(&b, far_depth(reversed));
                if (axis == 0)
                    draw_rect(&b, 0, 0, edge, (int)hgt, wall);
                else
                    draw_rect(&b, 0, 0, (int)w, edge, wall);
                build(h, &b);
                const bool vis = tw_hzb_visible(h, &v, &box, NULL);
                cases++;
                if (gap == 0) {
                    CHECK(vis);
                    visible_ok += vis;
                } else {
                    CHECK(!vis);
                    hidden_ok += !vis;
                }
            }
        }
    }
    CHECK(cases >= 8);
    /* The single far pixel in the top-right corner, the last texel of every
     * partial block: a large box over it is visible, and hidden once it is
     * covered. */
    const struct tw_box big = box_at(&v, &b, w - 1.0, hgt - 1.0, 30.0f, 9.0f, 5.0f);
    double r[4], wmin;
    CHECK(window_rect(&v, &b, &big, r, &wmin) && r[2] > w && r[3] > hgt);
    fill(&b, wall);
    b.depth[(size_t)(hgt - 1) * w + (w - 1)] = far_depth(reversed);
    build(h, &b);
    CHECK(tw_hzb_visible(h, &v, &big, NULL));
    CHECK(tw_hzb_levels(h) > 1 || (w == 1 && hgt == 1));
    b.depth[(size_t)(hgt - 1) * w + (w - 1)] = wall;
    build(h, &b);
    CHECK(!tw_hzb_visible(h, &v, &big, NULL));
    printf("peek %ux%u %s: %d visible, %d hidden of %d\n", w, hgt,
           reversed ? "reversed" : "standard", visible_ok, hidden_ok, cases);
out:
    tw_hzb_destroy(h);
    free(b.depth);
}

static uint64_t rng_state;
static double uniform(double lo, double hi)
{
    uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return lo + (hi - lo) * (double)(z >> 11) / 9007199254740992.0;
}

/* Random buffers of overlapping rectangles at random depths against random
 * boxes: whenever the pyramid says hidden, every pixel whose centre lies in
 * the box's exact rectangle is nearer than the box's nearest point. With
 * boxes shrunk (the mutation), the same check must catch violations: the
 * property is not vacuous. Returns the violations seen. */
static int random_property(uint32_t w, uint32_t hgt, bool reversed, float shrink, int *hidden)
{
    struct buffer b;
    struct tw_hzb *h;
    int violations = 0;
    *hidden = 0;
    if (!setup(&b, &h, w, hgt, reversed))
        goto out;
    tw_hzb_set_mutation(h, shrink);
    const struct tw_view v = view_for(&b);
    for (int scene = 0; scene < 12; scene++) {
        fill(&b, far_depth(reversed));
        for (int k = 0; k < 40; k++) {
            const int x0 = (int)uniform(-50, w), y0 = (int)uniform(-50, hgt);
            draw_rect(&b, x0, y0, x0 + (int)uniform(1, w / 2.0), y0 + (int)uniform(1, hgt / 2.0),
                      window_depth(&v, reversed, uniform(2.0, 300.0)));
        }
        build(h, &b);
        for (int k = 0; k < 400; k++) {
            const float z = (float)uniform(1.0, 400.0), s = (float)uniform(0.02, 0.1) * z;
            const double px = uniform(-20, w + 20.0), py = uniform(-20, hgt + 20.0);
            const struct tw_box box = box_at(&v, &b, px, py, z, s, (float)uniform(0.01, 2.0) * s);
            if (tw_hzb_visible(h, &v, &box, NULL))
                continue;
            (*hidden)++;
            double r[4], wmin;
            if (!window_rect(&v, &b, &box, r, &wmin)) {
                violations++;     /* hidden across the near plane */
                continue;
            }
            /* Against the unmutated box: the mutation must be caught. */
            const float dnear = window_depth(&v, reversed, wmin);
            bool bad = false;
            for (int y = (int)ceil(r[1] - 0.5); y <= (int)floor(r[3] - 0.5) && !bad; y++)
                for (int x = (int)ceil(r[0] - 0.5); x <= (int)floor(r[2] - 0.5) && !bad; x++)
                    if (x >= 0 && y >= 0 && x < (int)w && y < (int)hgt)
                        bad = !nearer(reversed, b.depth[(size_t)y * w + (size_t)x], dnear);
            violations += bad;
        }
    }
out:
    tw_hzb_destroy(h);
    free(b.depth);
    return violations;
}

static void test_random(void)
{
    static const uint32_t sizes[][2] = {{641, 361}, {640, 360}, {97, 33}, {3, 2}, {1, 1}};
    for (size_t s = 0; s < sizeof(sizes) / sizeof(sizes[0]); s++)
        for (int rev = 0; rev < 2; rev++) {
            rng_state = 7 + s;
            int hidden = 0;
            const int bad = random_property(sizes[s][0], sizes[s][1], rev != 0, 0.0f, &hidden);
            if (bad)
                fprintf(stderr, "random %ux%u %s: %d of %d hidden boxes are not\n", sizes[s][0],
                        sizes[s][1], rev ? "reversed" : "standard", bad, hidden);
            CHECK(bad == 0);
            if (sizes[s][0] > 90)
                CHECK(hidden > 100);    /* the check bites */
        }
    /* A culler that shrinks boxes by half culls what is visible, and the
     * same check says so. */
    rng_state = 7;
    int hidden = 0;
    CHECK(random_property(640, 360, true, 0.5f, &hidden) > 0);
}

/* Levels: ceil-halving down to 1 x 1. */
static void test_levels(void)
{
    struct tw_hzb *h = NULL;
    CHECK(tw_hzb_create(&h) == TW_OK);
    if (!h)
        return;
    CHECK(tw_hzb_depth_buffer(h, 0, 10) == NULL);
    static const uint32_t cases[][3] = {{1, 1, 1}, {2, 1, 2}, {641, 361, 11}, {640, 360, 11},
                                        {1280, 720, 12}, {3, 5, 4}};
    for (size_t k = 0; k < sizeof(cases) / sizeof(cases[0]); k++) {
        float *d = tw_hzb_depth_buffer(h, cases[k][0], cases[k][1]);
        CHECK(d != NULL);
        if (!d)
            continue;
        for (size_t p = 0; p < (size_t)cases[k][0] * cases[k][1]; p++)
            d[p] = 0.5f;
        CHECK(tw_hzb_levels(h) == 0);     /* not built yet */
        tw_hzb_build(h, true);
        CHECK(tw_hzb_levels(h) == cases[k][2]);
    }
    CHECK(tw_hzb_bytes(h) >= sizeof(float) * 1280 * 720);
    tw_hzb_destroy(h);
    tw_hzb_destroy(NULL);
}

/* ---- the per-tile traversals ---------------------------------------------------------- */

struct fake {
    struct buffer depth;       /* what read_depth hands out */
    bool has_depth;
    uint32_t reads;
    uint32_t drawn[4096];      /* cluster indices drawn this frame, per tile in turn */
    struct tw_cell drawn_cell[4096];
    uint32_t drawn_count;
    uint32_t draw_calls;
};

static uint32_t fake_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                           const float off[3])
{
    (void)ctx;
    (void)boxes;
    (void)count;
    (void)off;
    CHECK(!"the HZB methods issue no query");
    return TW_QUERY_VISIBLE;
}

static bool fake_ready(void *ctx, uint32_t q)
{
    (void)ctx;
    (void)q;
    return true;
}

static uint32_t fake_wait(void *ctx, uint32_t q)
{
    (void)ctx;
    (void)q;
    return UINT32_MAX;
}

static void fake_draw(void *ctx, struct tw_cell cell, uint32_t content, const float offset[3],
                      const uint32_t *clusters, uint32_t count)
{
    struct fake *fk = ctx;
    (void)content;
    (void)offset;
    fk->draw_calls++;
    for (uint32_t k = 0; k < count && fk->drawn_count < 4096; k++) {
        fk->drawn_cell[fk->drawn_count] = cell;
        fk->drawn[fk->drawn_count++] = clusters[k];
    }
}

static void fake_flush(void *ctx)
{
    (void)ctx;
}

static bool fake_read_depth(void *ctx, float *depth, uint32_t *width, uint32_t *height,
                            bool *reversed)
{
    struct fake *fk = ctx;
    if (!fk->has_depth)
        return false;
    *width = fk->depth.w;
    *height = fk->depth.h;
    *reversed = fk->depth.reversed;
    if (depth) {
        memcpy(depth, fk->depth.depth, sizeof(float) * fk->depth.w * fk->depth.h);
        fk->reads++;
    }
    return true;
}

static struct tw_query_backend fake_backend(struct fake *fk)
{
    const struct tw_query_backend be = {
        .ctx = fk, .issue = fake_issue, .ready = fake_ready, .wait = fake_wait,
        .draw = fake_draw, .flush = fake_flush, .read_depth = fake_read_depth,
    };
    return be;
}

/* A tileset of one 20 x 20 m prototype: a row of cubes 1 m wide at x = 10
 * (tile-local), z = 1.5, 3.5, ... 19.5: looking along +z from x = 10 they
 * stand one behind the other. */
static struct tw_tileset *make_tileset(void)
{
    static const float pos[8 * 3] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0,
                                     0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
    static const uint32_t idx[12 * 3] = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                                         2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
    struct tw_tileset *ts = NULL;
    if (tw_tileset_create("cubes", 20.0f, 20.0f, &ts) != TW_OK)
        return NULL;
    const float grey[4] = {0.5f, 0.5f, 0.5f, 1};
    const int mat = tw_tileset_add_material(ts, grey);
    const int mesh = tw_tileset_add_mesh(ts, pos, NULL, 8, idx, 12);
    const int p = tw_tileset_add_prototype(ts, "row", 1.0f);
    for (int k = 0; k < 10; k++) {
        const float m[12] = {1, 0, 0, 9.5f, 0, 1, 0, 0, 0, 0, 1, 1.0f + 2.0f * (float)k};
        tw_tileset_add_instance(ts, (uint32_t)p, (uint32_t)mesh, (uint32_t)mat, m);
    }
    if (mat < 0 || mesh < 0 || p < 0 || tw_tileset_finish(ts, 0) != TW_OK) {
        tw_tileset_destroy(ts);
        return NULL;
    }
    return ts;
}

/* The cluster whose cube starts at tile-local z. */
static bool drew_cube_at(const struct fake *fk, const struct tw_prototype *proto, float z)
{
    for (uint32_t k = 0; k < fk->drawn_count; k++)
        if (fabsf(proto->clusters[fk->drawn[k]].box.min[2] - z) < 0.01f)
            return true;
    return false;
}

/* Phase 2 draws what the pyramid cannot hide and marks it visible; the
 * next phase 1 draws exactly that; phase 2 draws nothing twice. */
static void test_traversal(void)
{
    struct tw_tileset *ts = make_tileset();
    struct tw_bvh *bvh = NULL;
    struct tw_hzb *h = NULL;
    struct fake *fk = calloc(1, sizeof(*fk));
    struct tw_hzb_node_state *state = NULL;
    CHECK(ts && fk && tw_hzb_create(&h) == TW_OK);
    if (!ts || !fk || !h)
        goto out;
    CHECK(tw_bvh_build_median(&ts->prototypes[0], NULL, &bvh) == TW_OK);
    if (!bvh)
        goto out;
    state = calloc(bvh->node_count, sizeof(*state));
    CHECK(tw_hzb_state_bytes(bvh) == bvh->node_count * sizeof(*state));
    fk->depth = (struct buffer){320, 180, true, malloc(sizeof(float) * 320 * 180)};
    const struct tw_query_backend be = fake_backend(fk);
    struct tw_view v = view_for(&fk->depth);
    /* The eye at (10, 0.5, 0) tile-local: the tile placed at offset (-10, -0.5, 0). */
    struct tw_cull_instance t = {.cell = {0, 0}, .content = 0, .proto = &ts->prototypes[0],
                                 .bvh = bvh, .state = state, .offset = {-10.0f, -0.5f, 0.0f}};
    /* Frame 1: a wall at 6 m covers the screen; the pyramid hides every cube
     * behind it, the three before it (the one at 5-6 m touches it) are drawn. */
    fill(&fk->depth, window_depth(&v, true, 6.0));
    build(h, &fk->depth);
    tw_hzb_begin_frame(h);
    CHECK(tw_hzb_draw_last_visible(h, &v, &be, &t) == 0);    /* nothing seen before */
    fk->drawn_count = fk->draw_calls = 0;
    CHECK(tw_hzb_traverse(h, &v, &be, &t) == 3);
    CHECK(fk->draw_calls == 1);
    CHECK(drew_cube_at(fk, t.proto, 1.0f) && drew_cube_at(fk, t.proto, 5.0f));
    CHECK(!drew_cube_at(fk, t.proto, 7.0f) && !drew_cube_at(fk, t.proto, 19.0f));
    CHECK(tw_hzb_stats(h)->boxes_tested > 0 && tw_hzb_stats(h)->boxes_hidden > 0);
    CHECK(tw_hzb_stats(h)->clusters_drawn == 3);
    CHECK(state[0].visible_frame == 1);
    /* Frame 2: phase 1 draws those three, in one call; no pyramid this time:
     * phase 2 draws the other seven and not those three again. */
    v.frame = 2;
    fk->drawn_count = fk->draw_calls = 0;
    CHECK(tw_hzb_draw_last_visible(h, &v, &be, &t) == 3);
    CHECK(fk->draw_calls == 1);
    CHECK(drew_cube_at(fk, t.proto, 1.0f) && drew_cube_at(fk, t.proto, 5.0f));
    tw_hzb_clear(h);
    fk->drawn_count = 0;
    CHECK(tw_hzb_traverse(h, &v, &be, &t) == 7);
    CHECK(!drew_cube_at(fk, t.proto, 1.0f) && drew_cube_at(fk, t.proto, 19.0f));
    /* The frame's final depth, a wall at 8 m: the re-test keeps the four
     * cubes before it, and the next phase 1 draws those. */
    fill(&fk->depth, window_depth(&v, true, 8.0));
    build(h, &fk->depth);
    CHECK(tw_hzb_retest(h, &v, &t));
    v.frame = 3;
    fk->drawn_count = 0;
    CHECK(tw_hzb_draw_last_visible(h, &v, &be, &t) == 4);
    CHECK(drew_cube_at(fk, t.proto, 7.0f) && !drew_cube_at(fk, t.proto, 9.0f));
    /* Out of the frustum (looking away): nothing drawn, nothing marked. */
    v.frame = 4;
    const float eye[3] = {0, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 180.0f, 0.0f, 60.0f, 16.0f / 9.0f, 0.2f,
                       1000.0f);
    v.view_distance = 900.0f;
    v.frame = 4;
    tw_hzb_clear(h);
    fk->drawn_count = 0;
    CHECK(tw_hzb_draw_last_visible(h, &v, &be, &t) == 0);
    CHECK(tw_hzb_traverse(h, &v, &be, &t) == 0 && fk->drawn_count == 0);
    CHECK(state[0].visible_frame != 4);
out:
    if (fk)
        free(fk->depth.depth);
    free(fk);
    free(state);
    tw_hzb_destroy(h);
    tw_bvh_destroy(bvh);
    tw_tileset_destroy(ts);
}

/* ---- the method drivers ------------------------------------------------------------------- */

struct world {
    struct tw_tileset *ts;
    struct tw_bvh *bvh;
    struct tw_selection sel;
    struct tw_cull_fixed fixed;
    struct tw_cull_grid grid;
};

static bool cell_drawn(const struct fake *fk, struct tw_cell c)
{
    for (uint32_t k = 0; k < fk->drawn_count; k++)
        if (fk->drawn_cell[k].i == c.i && fk->drawn_cell[k].j == c.j)
            return true;
    return false;
}

/* A grid of cube rows seen along +z from cell (0, 0): with the depth of a
 * wall 50 m ahead, both methods draw the cells before it and none beyond;
 * tilequery+hzb stops propagating at the wall and so tests fewer cells;
 * without depth every cell in view is drawn, as vfc would. The wall is the
 * fake's depth, not geometry: what is tested here is how the drivers use
 * the pyramid. */
static void test_drivers(void)
{
    struct world wd = {0};
    struct fake *fk = calloc(1, sizeof(*fk));
    struct tw_cull_driver *drv[3] = {NULL, NULL, NULL};
    struct tw_cull_cells cells = {0};
    wd.ts = make_tileset();
    CHECK(wd.ts && fk);
    if (!wd.ts || !fk)
        goto out;
    CHECK(tw_bvh_build_median(&wd.ts->prototypes[0], NULL, &wd.bvh) == TW_OK);
    wd.fixed = (struct tw_cull_fixed){wd.ts, &wd.sel, &wd.bvh, NULL};
    wd.grid = tw_cull_fixed_grid(&wd.fixed);
    fk->depth = (struct buffer){160, 90, true, malloc(sizeof(float) * 160 * 90)};
    fk->has_depth = true;
    const enum tw_cull_method methods[3] = {TW_CULL_HZB, TW_CULL_TILEQUERY_HZB, TW_CULL_VFC};
    for (int m = 0; m < 3; m++) {
        const struct tw_cull_driver_settings s = {.method = methods[m]};
        CHECK(tw_cull_driver_create(&s, &drv[m]) == TW_OK);
        if (!drv[m])
            goto out;
        CHECK(tw_cull_driver_method(drv[m]) == methods[m]);
        CHECK(tw_cull_driver_tilequery(drv[m]) == NULL);
    }
    const struct tw_query_backend be = fake_backend(fk);
    struct tw_view v;
    const float eye[3] = {10.0f, 0.5f, 0.5f};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 60.0f, 16.0f / 9.0f, 0.2f,
                       1000.0f);
    v.view_distance = 300.0f;
    fill(&fk->depth, window_depth(&v, true, 50.0));
    uint32_t queried[2] = {0, 0};
    for (uint64_t f = 1; f <= 4; f++) {
        v.frame = f;
        for (int m = 0; m < 3; m++) {
            struct tw_cull_frame_stats st;
            fk->drawn_count = 0;
            fk->reads = 0;
            CHECK(tw_cull_driver_frame(drv[m], &v, &wd.grid, &be, &cells, &st) == TW_OK);
            if (m == 2) {
                /* vfc: something beyond the wall is drawn. */
                CHECK(cell_drawn(fk, (struct tw_cell){0, 5}));
                continue;
            }
            CHECK(cell_drawn(fk, (struct tw_cell){0, 0}) && cell_drawn(fk, (struct tw_cell){0, 1}));
            /* Cells from z = 60 m on are behind the wall. */
            for (int j = 3; j < 16; j++)
                for (int i = -8; i <= 8; i++)
                    CHECK(!cell_drawn(fk, (struct tw_cell){i, j}) || f == 1);
            CHECK(st.hzb_boxes >= st.tiles_queried && st.tiles_queried > 0);
            queried[m] = st.tiles_queried;
            if (f == 1) {
                /* Nothing drawn last frame: no phase-1 depth, everything in
                 * view drawn; the second readback then decides what stays. */
                CHECK(fk->reads == 1);
                CHECK(cell_drawn(fk, (struct tw_cell){0, 5}));
            } else {
                CHECK(fk->reads == 1);
                CHECK(st.tiles_new == 0);
            }
            CHECK(st.tiles_cached > 0 && st.cache_bytes > 0);
        }
    }
    CHECK(queried[1] < queried[0]);
    CHECK(tw_cull_driver_bytes(drv[0]) > tw_cull_driver_bytes(drv[2]));
    /* Without depth to read: every cell in view is drawn, like vfc. */
    fk->has_depth = false;
    v.frame = 5;
    fk->drawn_count = 0;
    CHECK(tw_cull_driver_frame(drv[0], &v, &wd.grid, &be, &cells, NULL) == TW_OK);
    CHECK(cell_drawn(fk, (struct tw_cell){0, 5}));
    /* A forgotten cell is made afresh. */
    tw_cull_driver_forget(drv[0], (struct tw_cell){0, 0});
    struct tw_cull_frame_stats st;
    v.frame = 6;
    CHECK(tw_cull_driver_frame(drv[0], &v, &wd.grid, &be, &cells, &st) == TW_OK);
    CHECK(st.tiles_new == 1);
out:
    for (int m = 0; m < 3; m++)
        tw_cull_driver_destroy(drv[m]);
    tw_cull_cells_finish(&cells);
    if (fk)
        free(fk->depth.depth);
    free(fk);
    tw_bvh_destroy(wd.bvh);
    tw_tileset_destroy(wd.ts);
}

int main(void)
{
    test_levels();
    static const uint32_t sizes[][2] = {{641, 361}, {640, 360}, {97, 33}};
    for (size_t s = 0; s < sizeof(sizes) / sizeof(sizes[0]); s++)
        for (int rev = 0; rev < 2; rev++) {
            test_wall(sizes[s][0], sizes[s][1], rev != 0);
            test_peek(sizes[s][0], sizes[s][1], rev != 0);
        }
    test_random();
    test_traversal();
    test_drivers();
    return check_summary("test-hzb");
}
