/*
 * Unit tests of CHC++ inside one tile (cull/chc.c, DESIGN.md §7), against a
 * deterministic fake query backend.
 *
 * The fake decides visibility from a set of points (view-relative): a query
 * passes one sample per (box, point) pair with the point inside the box. A
 * point inside a leaf's box is therefore inside every ancestor's box too, as
 * real geometry would be. Results become ready after a configurable number of
 * ready() polls, or only on wait(). Every issue, draw, poll and wait is
 * logged, in order, and the tests compare the log with expectations written
 * out by hand.
 *
 * Trees are built by hand: leaf k of a "column" lies at x in [-1, 1],
 * y in [0, 1], z in [10 + 2k, 11 + 2k], in front of an eye at (0, 0.5, 0)
 * looking along +z, so leaf order is front-to-back order.
 */
#include "cull/cull-private.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- checks ------------------------------------------------------------------ */

static int failures;
static const char *test_name = "";

static void fail(int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "test-chc.c:%d: %s: ", line, test_name);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    failures++;
}

#define CHECK(cond)                                                                  \
    do {                                                                             \
        if (!(cond))                                                                 \
            fail(__LINE__, "check failed: %s", #cond);                               \
    } while (0)

#define CHECK_U(a, b)                                                                \
    do {                                                                             \
        const unsigned long long a_ = (a), b_ = (b);                                 \
        if (a_ != b_)                                                                \
            fail(__LINE__, "%s == %llu, expected %s == %llu", #a, a_, #b, b_);       \
    } while (0)

#define CHECK_STR(a, b)                                                              \
    do {                                                                             \
        const char *a_ = (a), *b_ = (b);                                             \
        if (strcmp(a_, b_) != 0)                                                     \
            fail(__LINE__, "%s:\n    got      \"%s\"\n    expected \"%s\"", #a, a_, b_); \
    } while (0)

static void *xcalloc(size_t n, size_t size)
{
    void *p = calloc(n, size);
    if (!p) {
        fprintf(stderr, "test-chc: out of memory\n");
        exit(2);
    }
    return p;
}

static void *xgrow(void *p, size_t *cap, size_t need, size_t elem)
{
    if (need <= *cap)
        return p;
    size_t n = *cap ? *cap : 64;
    while (n < need)
        n *= 2;
    void *q = realloc(p, n * elem);
    if (!q) {
        fprintf(stderr, "test-chc: out of memory\n");
        exit(2);
    }
    *cap = n;
    return q;
}

/* ---- the fake backend ---------------------------------------------------------- */

#define FAKE_NEVER UINT32_MAX
#define MAX_POINTS 512

enum ev_type { EV_ISSUE, EV_READY, EV_WAIT, EV_DRAW, EV_FLUSH };

struct event {
    enum ev_type type;
    uint32_t query;         /* ISSUE, READY, WAIT */
    bool blocked;           /* WAIT: the result was not ready (a blocking wait) */
    bool answer;            /* READY */
    size_t first, count;    /* ISSUE: into boxes; DRAW: into clusters */
    float offset[3];
    struct tw_cell cell;    /* DRAW */
    uint32_t prototype;     /* DRAW */
};

struct fake_query {
    uint32_t samples;
    uint32_t polls;
    bool released;
};

struct fake {
    float points[MAX_POINTS][3];    /* view-relative */
    uint32_t point_count;
    uint32_t ready_after;           /* ready() says yes from poll ready_after + 1 on */
    struct fake_query *queries;     /* handle h is queries[h - 1] */
    size_t query_count, query_cap;
    struct event *events;
    size_t event_count, event_cap;
    struct tw_box *boxes;           /* tile-local, as issued */
    size_t box_count, box_cap;
    uint32_t *clusters;
    size_t cluster_count, cluster_cap;
    int errors;
};

static struct event *log_event(struct fake *f, enum ev_type type)
{
    f->events = xgrow(f->events, &f->event_cap, f->event_count + 1, sizeof(*f->events));
    struct event *e = &f->events[f->event_count++];
    memset(e, 0, sizeof(*e));
    e->type = type;
    return e;
}

static bool box_holds(const struct tw_box *b, const float off[3], const float p[3])
{
    for (int k = 0; k < 3; k++)
        if (p[k] < b->min[k] + off[k] || p[k] > b->max[k] + off[k])
            return false;
    return true;
}

static uint32_t fake_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                           const float offset[3])
{
    struct fake *f = ctx;
    uint32_t samples = 0;
    for (uint32_t b = 0; b < count; b++)
        for (uint32_t p = 0; p < f->point_count; p++)
            samples += box_holds(&boxes[b], offset, f->points[p]);
    f->queries = xgrow(f->queries, &f->query_cap, f->query_count + 1, sizeof(*f->queries));
    f->queries[f->query_count++] = (struct fake_query){samples, 0, false};
    f->boxes = xgrow(f->boxes, &f->box_cap, f->box_count + count, sizeof(*f->boxes));
    memcpy(&f->boxes[f->box_count], boxes, count * sizeof(*boxes));
    struct event *e = log_event(f, EV_ISSUE);
    e->query = (uint32_t)f->query_count;
    e->first = f->box_count;
    e->count = count;
    memcpy(e->offset, offset, sizeof(e->offset));
    f->box_count += count;
    return (uint32_t)f->query_count;
}

static struct fake_query *fake_lookup(struct fake *f, uint32_t q)
{
    if (q == 0 || q > f->query_count || f->queries[q - 1].released) {
        fprintf(stderr, "fake backend: query %u is not in flight\n", q);
        f->errors++;
        return NULL;
    }
    return &f->queries[q - 1];
}

static bool fake_is_ready(const struct fake *f, const struct fake_query *q)
{
    return f->ready_after != FAKE_NEVER && q->polls > f->ready_after;
}

static bool fake_ready(void *ctx, uint32_t query)
{
    struct fake *f = ctx;
    struct fake_query *q = fake_lookup(f, query);
    if (!q)
        return false;
    q->polls++;
    struct event *e = log_event(f, EV_READY);
    e->query = query;
    e->answer = fake_is_ready(f, q);
    return e->answer;
}

static uint32_t fake_wait(void *ctx, uint32_t query)
{
    struct fake *f = ctx;
    struct fake_query *q = fake_lookup(f, query);
    if (!q)
        return 0;
    struct event *e = log_event(f, EV_WAIT);
    e->query = query;
    e->blocked = !fake_is_ready(f, q);
    q->released = true;
    return q->samples;
}

static void fake_draw(void *ctx, struct tw_cell cell, uint32_t prototype, const float offset[3],
                      const uint32_t *clusters, uint32_t count)
{
    struct fake *f = ctx;
    f->clusters = xgrow(f->clusters, &f->cluster_cap, f->cluster_count + count,
                        sizeof(*f->clusters));
    memcpy(&f->clusters[f->cluster_count], clusters, count * sizeof(*clusters));
    struct event *e = log_event(f, EV_DRAW);
    e->first = f->cluster_count;
    e->count = count;
    e->cell = cell;
    e->prototype = prototype;
    memcpy(e->offset, offset, sizeof(e->offset));
    f->cluster_count += count;
}

static void fake_flush(void *ctx)
{
    log_event(ctx, EV_FLUSH);
}

static void fake_finish(struct fake *f)
{
    free(f->queries);
    free(f->events);
    free(f->boxes);
    free(f->clusters);
    memset(f, 0, sizeof(*f));
}

static size_t fake_in_flight(const struct fake *f)
{
    size_t n = 0;
    for (size_t q = 0; q < f->query_count; q++)
        n += !f->queries[q].released;
    return n;
}

static void fake_add_point(struct fake *f, float x, float y, float z)
{
    if (f->point_count < MAX_POINTS) {
        f->points[f->point_count][0] = x;
        f->points[f->point_count][1] = y;
        f->points[f->point_count][2] = z;
        f->point_count++;
    }
}

/* ---- hand-built trees -------------------------------------------------------------- */

#define MAX_NODES 512

struct tree {
    struct tw_bvh bvh;
    struct tw_bvh_node nodes[MAX_NODES];
    uint32_t cluster_order[MAX_NODES];
    struct tw_box tight[2 * MAX_NODES];
    uint32_t leaf_node[MAX_NODES];      /* leaf k -> node index */
    struct tw_box leaf_box[MAX_NODES];
    uint32_t leaf_count;
    struct tw_cluster clusters[MAX_NODES];
    struct tw_prototype proto;
};

static struct tw_box make_box(float x0, float y0, float z0, float x1, float y1, float z1)
{
    return (struct tw_box){{x0, y0, z0}, {x1, y1, z1}};
}

static struct tw_box box_union(const struct tw_box *a, const struct tw_box *b)
{
    struct tw_box r;
    for (int k = 0; k < 3; k++) {
        r.min[k] = fminf(a->min[k], b->min[k]);
        r.max[k] = fmaxf(a->max[k], b->max[k]);
    }
    return r;
}

/* Balanced tree over leaves [lo, hi), numbered in preorder. */
static uint32_t build_range(struct tree *t, uint32_t lo, uint32_t hi, uint32_t parent,
                            uint32_t depth)
{
    const uint32_t n = t->bvh.node_count++;
    struct tw_bvh_node *node = &t->nodes[n];
    node->parent = parent;
    node->depth = depth;
    node->first_tight = n;
    node->tight_count = 1;
    if (depth > t->bvh.depth)
        t->bvh.depth = depth;
    if (hi - lo == 1) {
        node->box = t->leaf_box[lo];
        node->child[0] = node->child[1] = TW_BVH_NONE;
        node->first_cluster = lo;
        node->cluster_count = 1;
        node->triangle_count = 10;
        node->cluster_total = 1;
        t->cluster_order[lo] = lo;
        t->leaf_node[lo] = n;
        t->bvh.leaf_count++;
    } else {
        const uint32_t mid = (lo + hi) / 2;
        const uint32_t a = build_range(t, lo, mid, n, depth + 1);
        const uint32_t b = build_range(t, mid, hi, n, depth + 1);
        node = &t->nodes[n];
        node->child[0] = a;
        node->child[1] = b;
        node->box = box_union(&t->nodes[a].box, &t->nodes[b].box);
        node->triangle_count = t->nodes[a].triangle_count + t->nodes[b].triangle_count;
        node->cluster_total = t->nodes[a].cluster_total + t->nodes[b].cluster_total;
    }
    t->tight[n] = t->nodes[n].box;
    return n;
}

static struct tree *tree_build(const struct tw_box *leaves, uint32_t count)
{
    struct tree *t = xcalloc(1, sizeof(*t));
    t->leaf_count = count;
    memcpy(t->leaf_box, leaves, count * sizeof(*leaves));
    t->bvh.nodes = t->nodes;
    t->bvh.cluster_order = t->cluster_order;
    t->bvh.cluster_count = count;
    t->bvh.tight_boxes = t->tight;
    build_range(t, 0, count, TW_BVH_NONE, 0);
    t->bvh.tight_box_count = t->bvh.node_count;
    for (uint32_t k = 0; k < count; k++) {
        t->clusters[k].box = leaves[k];
        t->clusters[k].triangle_count = 10;
    }
    snprintf(t->proto.name, sizeof(t->proto.name), "test");
    t->proto.weight = 1.0f;
    t->proto.clusters = t->clusters;
    t->proto.cluster_count = count;
    return t;
}

static struct tw_box column_box(uint32_t k)
{
    return make_box(-1, 0, 10.0f + 2.0f * (float)k, 1, 1, 11.0f + 2.0f * (float)k);
}

static struct tree *column_tree(uint32_t count)
{
    struct tw_box leaves[MAX_NODES];
    for (uint32_t k = 0; k < count; k++)
        leaves[k] = column_box(k);
    return tree_build(leaves, count);
}

static bool box_equal(const struct tw_box *a, const struct tw_box *b)
{
    for (int k = 0; k < 3; k++)
        if (a->min[k] != b->min[k] || a->max[k] != b->max[k])
            return false;
    return true;
}

/* "L<k>" for leaf k's box, "N<n>" for interior node n's, "?" otherwise. */
static void box_name(const struct tree *t, const struct tw_box *b, char *out, size_t size)
{
    for (uint32_t k = 0; k < t->leaf_count; k++)
        if (box_equal(b, &t->leaf_box[k])) {
            snprintf(out, size, "L%u", k);
            return;
        }
    for (uint32_t n = 0; n < t->bvh.node_count; n++)
        if (box_equal(b, &t->nodes[n].box)) {
            snprintf(out, size, "N%u", n);
            return;
        }
    snprintf(out, size, "?");
}

/* ---- a world: engine, fake, one or two tiles ---------------------------------------- */

#define MAX_TILES 6
#define TAG_A 0x1234
#define TAG_B 0x5678

struct world {
    struct tw_chc *chc;
    struct fake fake;
    struct tw_query_backend be;
    struct tree *tree;
    struct tw_chc_node_state state[MAX_TILES][MAX_NODES];
    struct tw_cull_instance tile[MAX_TILES];  /* tile t at cell (0, t) */
    uint32_t tile_count;
    float eye[3];
    float yaw;
    uint64_t frame;
    bool resolve_nothing;
    bool async;                           /* tw_chc_traverse_async, then tw_chc_finish */
    bool wavefront;                       /* with async: wavefront mode, the world
                                             flushing and resuming as tile-query
                                             propagation does */
    uint32_t rounds;                      /* wavefront: this frame's flushes */
};

static struct tw_chc_node_state *resolve(void *user, uint64_t tag, const struct tw_bvh **bvh)
{
    struct world *w = user;
    if (w->resolve_nothing)
        return NULL;
    for (uint32_t t = 0; t < w->tile_count; t++)
        if (w->tile[t].tag == tag) {
            *bvh = w->tile[t].bvh;
            return w->tile[t].state;
        }
    return NULL;
}

/* The cost model every world_create() hands its engine (NULL: none). */
static const struct tw_cost_model *world_costs;
/* Most tests follow DESIGN §7 as written, where a new tile's leaves are
 * drawn before they are queried (first_sight_draws); the tests of the
 * default, where they are queried first, set this. */
static bool world_queries_first;

static struct world *world_create(struct tree *t, const struct tw_chc_settings *settings,
                                  uint32_t ready_after)
{
    struct world *w = xcalloc(1, sizeof(*w));
    struct tw_chc_settings s = settings ? *settings : (struct tw_chc_settings){0};
    s.first_sight_draws = !world_queries_first;
    if (tw_chc_create(&s, &w->chc) != TW_OK) {
        fprintf(stderr, "tw_chc_create failed\n");
        exit(2);
    }
    tw_chc_set_costs(w->chc, world_costs);
    w->fake.ready_after = ready_after;
    w->be = (struct tw_query_backend){.ctx = &w->fake, .issue = fake_issue, .ready = fake_ready,
                                      .wait = fake_wait, .draw = fake_draw, .flush = fake_flush};
    w->tree = t;
    w->tile_count = 1;
    w->tile[0] = (struct tw_cull_instance){
        .cell = {0, 0}, .content = 3, .proto = &t->proto, .bvh = &t->bvh,
        .state = w->state[0], .offset = {0, 0, 0}, .tag = TAG_A,
    };
    w->eye[0] = 0.0f;
    w->eye[1] = 0.5f;
    w->eye[2] = 0.0f;
    return w;
}

static void world_destroy(struct world *w)
{
    if (!w)
        return;
    tw_chc_destroy(w->chc);
    fake_finish(&w->fake);
    free(w->tree);
    free(w);
}

static void world_view(const struct world *w, struct tw_view *v, uint64_t frame)
{
    tw_cull_view_setup(v, (struct tw_cell){0, 0}, w->eye, w->yaw, 0.0f, 90.0f, 1.0f, 0.1f,
                       1000.0f);
    v->view_distance = 500.0f;
    v->frame = frame;
}

/* Every cluster of a tile drawn at most once between log index mark and now. */
static void check_no_double_draw(const struct world *w, size_t mark, int line)
{
    static unsigned char seen[MAX_TILES][MAX_NODES];
    memset(seen, 0, sizeof(seen));
    for (size_t e = mark; e < w->fake.event_count; e++) {
        const struct event *ev = &w->fake.events[e];
        if (ev->type != EV_DRAW)
            continue;
        const uint32_t t = (uint32_t)ev->cell.j;
        if (ev->cell.j < 0 || t >= MAX_TILES) {
            fail(line, "a draw in cell (%lld, %lld), no tile's", (long long)ev->cell.i,
                 (long long)ev->cell.j);
            continue;
        }
        for (size_t k = 0; k < ev->count; k++) {
            const uint32_t c = w->fake.clusters[ev->first + k];
            if (c >= MAX_NODES) {
                fail(line, "cluster %u out of range", c);
                continue;
            }
            if (seen[t][c]++)
                fail(line, "frame %llu: cluster %u of tile %u drawn twice",
                     (unsigned long long)w->frame, c, t);
        }
    }
}

/* begin_frame + traverse every tile; returns the log index where the frame's
 * traversal (after begin_frame) started. */
static size_t run_frame_at(struct world *w, uint64_t frame, size_t *begin_mark, int line)
{
    struct tw_view v;
    w->frame = frame;
    world_view(w, &v, frame);
    const size_t b = w->fake.event_count;
    if (begin_mark)
        *begin_mark = b;
    tw_chc_begin_frame(w->chc, &v, &w->be, resolve, w);
    const size_t mark = w->fake.event_count;
    for (uint32_t t = 0; t < w->tile_count; t++) {
        if (w->async)
            tw_chc_traverse_async(w->chc, &v, &w->be, &w->tile[t]);
        else
            tw_chc_traverse(w->chc, &v, &w->be, &w->tile[t]);
    }
    w->rounds = 0;
    if (w->async && w->wavefront) {
        /* As tilequery.c: one flush per wavefront, then the passes go on. */
        bool more = true;
        while (more) {
            fake_flush(&w->fake);
            w->rounds++;
            more = tw_chc_resume_flushed(w->chc);
        }
    }
    if (w->async)
        tw_chc_finish(w->chc);
    check_no_double_draw(w, mark, line);
    if (w->fake.errors) {
        fail(line, "the fake backend saw %d protocol errors", w->fake.errors);
        w->fake.errors = 0;
    }
    return mark;
}
#define run_frame(w, frame) run_frame_at((w), (frame), NULL, __LINE__)

/* The log from mark on, as text: "D(c,c)" a draw, "Q(L0,L1)" an issue (box
 * names), "W" a blocking wait, "w" reading a ready result. Polls and flushes
 * are left out. */
static const char *describe(const struct world *w, size_t mark)
{
    static char buf[16384];
    size_t len = 0;
    buf[0] = 0;
    for (size_t e = mark; e < w->fake.event_count && len + 64 < sizeof(buf); e++) {
        const struct event *ev = &w->fake.events[e];
        char item[32];
        switch (ev->type) {
        case EV_ISSUE:
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%sQ(", len ? " " : "");
            for (size_t k = 0; k < ev->count && len + 40 < sizeof(buf); k++) {
                box_name(w->tree, &w->fake.boxes[ev->first + k], item, sizeof(item));
                len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s%s", k ? "," : "", item);
            }
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, ")");
            break;
        case EV_DRAW:
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%sD(", len ? " " : "");
            for (size_t k = 0; k < ev->count && len + 40 < sizeof(buf); k++)
                len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s%u", k ? "," : "",
                                        w->fake.clusters[ev->first + k]);
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, ")");
            break;
        case EV_WAIT:
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s%s", len ? " " : "",
                                    ev->blocked ? "W" : "w");
            break;
        case EV_READY:
        case EV_FLUSH:
            break;
        }
    }
    return buf;
}

/* Only the issues, one group per query: "L0,L1 | L2". */
static const char *describe_issues(const struct world *w, size_t mark)
{
    static char buf[16384];
    size_t len = 0;
    buf[0] = 0;
    for (size_t e = mark; e < w->fake.event_count && len + 64 < sizeof(buf); e++) {
        const struct event *ev = &w->fake.events[e];
        if (ev->type != EV_ISSUE)
            continue;
        len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s", len ? " | " : "");
        for (size_t k = 0; k < ev->count && len + 40 < sizeof(buf); k++) {
            char item[32];
            box_name(w->tree, &w->fake.boxes[ev->first + k], item, sizeof(item));
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s%s", k ? "," : "", item);
        }
    }
    return buf;
}

/* Clusters drawn since mark (of tile t), as a bit set over cluster indices. */
static void drawn_since(const struct world *w, size_t mark, uint32_t t, bool *drawn)
{
    memset(drawn, 0, MAX_NODES * sizeof(*drawn));
    for (size_t e = mark; e < w->fake.event_count; e++) {
        const struct event *ev = &w->fake.events[e];
        if (ev->type != EV_DRAW || ev->cell.j != (int64_t)t)
            continue;
        for (size_t k = 0; k < ev->count; k++)
            if (w->fake.clusters[ev->first + k] < MAX_NODES)
                drawn[w->fake.clusters[ev->first + k]] = true;
    }
}

/* "0,2" : the set of clusters drawn since mark, ascending. */
static const char *drawn_set(const struct world *w, size_t mark)
{
    static char buf[4096];
    bool drawn[MAX_NODES];
    drawn_since(w, mark, 0, drawn);
    size_t len = 0;
    buf[0] = 0;
    for (uint32_t c = 0; c < MAX_NODES && len + 16 < sizeof(buf); c++)
        if (drawn[c])
            len += (size_t)snprintf(buf + len, sizeof(buf) - len, "%s%u", len ? "," : "", c);
    return buf;
}

/* Sets every node of tile 0 as "visible last frame" (frame - 1), and then the
 * given leaves as invisible for invisible_frames frames. */
static void set_interior_visible(struct world *w, uint64_t frame)
{
    for (uint32_t n = 0; n < w->tree->bvh.node_count; n++) {
        w->state[0][n] = (struct tw_chc_node_state){frame - 1, frame + 100, 0, 0};
    }
}

static void set_leaf_invisible(struct world *w, uint32_t leaf, uint32_t invisible_frames)
{
    struct tw_chc_node_state *s = &w->state[0][w->tree->leaf_node[leaf]];
    s->visible_frame = 0;
    s->invisible_frames = invisible_frames;
    s->next_query_frame = 0;
}

static void leaf_center(const struct tree *t, uint32_t leaf, float out[3])
{
    for (int k = 0; k < 3; k++)
        out[k] = 0.5f * (t->leaf_box[leaf].min[k] + t->leaf_box[leaf].max[k]);
}

static void point_in_leaf(struct world *w, uint32_t leaf)
{
    float c[3];
    leaf_center(w->tree, leaf, c);
    fake_add_point(&w->fake, c[0], c[1], c[2]);
}

/* ---- tests ------------------------------------------------------------------------ */

/* Four leaves in a column ahead, L0 and L2 seen, L4 behind the eye and L5
 * beyond the view distance; every node's state new at frame 5. */
static struct world *first_sight_world(void)
{
    struct tw_box leaves[6];
    for (uint32_t k = 0; k < 4; k++)
        leaves[k] = column_box(k);
    leaves[4] = make_box(-1, 0, -11, 1, 1, -10);      /* behind the eye */
    leaves[5] = make_box(-1, 0, 600, 1, 1, 601);      /* beyond the view distance */
    struct world *w = world_create(tree_build(leaves, 6), NULL, FAKE_NEVER);
    point_in_leaf(w, 0);
    point_in_leaf(w, 2);
    tw_chc_state_init(w->state[0], &w->tree->bvh, 5);
    return w;
}

/* First sight: everything in the frustum is drawn at once, front to back,
 * before any query; each leaf in view is queried once (V-queries), no
 * interior node is queried; nodes behind the camera or beyond the view
 * distance are neither drawn nor queried. */
static void test_first_sight(void)
{
    test_name = "first_sight";
    struct world *w = first_sight_world();

    const size_t mark = run_frame(w, 5);
    CHECK_STR(describe(w, mark), "D(0,1,2,3) Q(L0) Q(L1) Q(L2) Q(L3)");
    const struct tw_chc_stats *st = tw_chc_stats(w->chc);
    CHECK_U(st->clusters_drawn, 4);
    CHECK_U(st->queries, 4);
    CHECK_U(st->nodes_queried, 4);
    CHECK_U(st->multiqueries, 0);
    CHECK_U(st->waits, 0);
    /* Results never ready: the V-queries are in flight, and say so. */
    CHECK_U(fake_in_flight(&w->fake), 4);
    for (uint32_t k = 0; k < 6; k++)
        CHECK((w->state[0][w->tree->leaf_node[k]].pending_query != 0) == (k < 4));

    /* Next frame: read as frame 5's results (test_deferred_vqueries checks
     * the state right after begin_frame); L1 and L3 are then queried again. */
    const size_t mark6 = run_frame(w, 6);
    for (uint32_t k = 0; k < 4; k++) {
        const struct tw_chc_node_state *s = &w->state[0][w->tree->leaf_node[k]];
        if (k == 0 || k == 2) {
            CHECK(s->visible_frame >= 5);
        } else {
            CHECK_U(s->visible_frame, 4);
            CHECK_U(s->invisible_frames, 2);
            CHECK_U(s->pending_query, 0);
        }
    }
    /* Outside the view: state untouched, never drawn, never queried. */
    CHECK_U(w->state[0][w->tree->leaf_node[4]].visible_frame, 4);
    CHECK_U(w->state[0][w->tree->leaf_node[5]].visible_frame, 4);
    bool drawn[MAX_NODES];
    drawn_since(w, mark6, 0, drawn);
    CHECK(drawn[0] && drawn[2] && !drawn[1] && !drawn[3] && !drawn[4] && !drawn[5]);
    CHECK(strstr(describe_issues(w, 0), "L4") == NULL);
    CHECK(strstr(describe_issues(w, 0), "L5") == NULL);
    world_destroy(w);
}

/* First sight, by default: the leaves in the frustum are queried before any
 * is drawn, their parents taken as visible (no query of an interior node);
 * only the leaves found visible are drawn, and they are then scheduled for
 * re-queries like any visible leaf; the hidden ones count a hidden frame. */
static void test_first_sight_queries(void)
{
    test_name = "first_sight_queries";
    world_queries_first = true;
    struct world *w = first_sight_world();

    const size_t mark = run_frame(w, 5);
    CHECK_STR(describe(w, mark), "Q(L0) Q(L1) Q(L2) Q(L3) W D(0) W W D(2) W");
    const struct tw_chc_stats *st = tw_chc_stats(w->chc);
    CHECK_U(st->clusters_drawn, 2);
    CHECK_U(st->nodes_queried, 4);
    for (uint32_t k = 0; k < 4; k++) {
        const struct tw_chc_node_state *s = &w->state[0][w->tree->leaf_node[k]];
        if (k == 0 || k == 2) {
            CHECK_U(s->visible_frame, 5);
            CHECK(s->next_query_frame > 5);
        } else {
            CHECK_U(s->visible_frame, 4);
            CHECK_U(s->invisible_frames, 1);
        }
        CHECK_U(s->pending_query, 0);
    }
    CHECK_U(w->state[0][w->tree->leaf_node[4]].visible_frame, 4);
    CHECK_U(w->state[0][w->tree->leaf_node[5]].visible_frame, 4);
    CHECK(strstr(describe_issues(w, 0), "L4") == NULL);
    CHECK(strstr(describe_issues(w, 0), "L5") == NULL);

    /* Next frame: L0 and L2 are drawn as visible leaves, before any query. */
    const size_t mark6 = run_frame(w, 6);
    bool drawn[MAX_NODES];
    drawn_since(w, mark6, 0, drawn);
    CHECK(drawn[0] && drawn[2] && !drawn[1] && !drawn[3]);
    CHECK(strncmp(describe(w, mark6), "D(0", 3) == 0);
    world_destroy(w);
    world_queries_first = false;
}

/* Pull-up: a visible leaf marks itself and its ancestors visible, nothing else. */
static void test_pull_up(void)
{
    test_name = "pull_up";
    /* 8 leaves, preorder: 0 root; 1 (L0-L3); 2 (L0,L1); 3 L0; 4 L1; 5 (L2,L3);
     * 6 L2; 7 L3; 8 (L4-L7); 9 (L4,L5); 10 L4; 11 L5; 12 (L6,L7); 13 L6; 14 L7. */
    struct world *w = world_create(column_tree(8), NULL, 0);
    CHECK_U(w->tree->leaf_node[5], 11);
    CHECK_U(w->tree->leaf_node[0], 3);
    point_in_leaf(w, 5);
    tw_chc_state_init(w->state[0], &w->tree->bvh, 1);
    run_frame(w, 1);
    static const bool visible1[15] = {1, 0, 0, 0, 0, 0, 0, 0, 1, 1, 0, 1, 0, 0, 0};
    for (uint32_t n = 0; n < 15; n++) {
        CHECK_U(w->state[0][n].visible_frame, visible1[n] ? 1 : 0);
        if (visible1[n])
            CHECK_U(w->state[0][n].invisible_frames, 0);
    }

    /* L0 turns visible: its chain 3, 2, 1 joins the already visible root. */
    point_in_leaf(w, 0);
    run_frame(w, 2);
    static const bool visible2[15] = {1, 1, 1, 1, 0, 0, 0, 0, 1, 1, 0, 1, 0, 0, 0};
    for (uint32_t n = 0; n < 15; n++)
        CHECK_U(w->state[0][n].visible_frame == 2, visible2[n]);
    world_destroy(w);
}

/* A cluster referenced by two leaves is drawn once per frame. */
static void test_shared_cluster(void)
{
    test_name = "shared_cluster";
    struct world *w = world_create(column_tree(4), NULL, 0);
    struct tree *t = w->tree;
    /* Leaves: L0 [0], L1 [1, 7], L2 [2, 7], L3 [3]. */
    static const uint32_t order[6] = {0, 1, 7, 2, 7, 3};
    static const uint32_t first[4] = {0, 1, 3, 5}, count[4] = {1, 2, 2, 1};
    memcpy(t->cluster_order, order, sizeof(order));
    t->bvh.cluster_count = 6;
    t->proto.cluster_count = 8;
    for (uint32_t k = 0; k < 4; k++) {
        t->nodes[t->leaf_node[k]].first_cluster = first[k];
        t->nodes[t->leaf_node[k]].cluster_count = count[k];
    }
    for (uint32_t k = 0; k < 4; k++)
        point_in_leaf(w, k);
    tw_chc_state_init(w->state[0], &t->bvh, 1);
    size_t mark = run_frame(w, 1);
    CHECK_STR(describe(w, mark), "D(0,1,7,2,3) Q(L0) Q(L1) Q(L2) Q(L3) w w w w");
    CHECK_U(tw_chc_stats(w->chc)->clusters_drawn, 5);

    /* L1 and L2 found visible through I-queries in the same frame. */
    set_interior_visible(w, 2);
    set_leaf_invisible(w, 1, 3);
    set_leaf_invisible(w, 2, 3);
    mark = run_frame(w, 2);
    CHECK_STR(drawn_set(w, mark), "0,1,2,3,7");
    world_destroy(w);
}

/* A previously visible leaf is drawn before the traversal blocks on anything,
 * and the wait is first spent issuing the due V-query. */
static void test_drawn_before_wait(void)
{
    test_name = "drawn_before_wait";
    struct world *w = world_create(column_tree(4), NULL, FAKE_NEVER);
    set_interior_visible(w, 10);
    for (uint32_t k = 0; k < 3; k++)
        set_leaf_invisible(w, k, 2);
    w->state[0][w->tree->leaf_node[3]].next_query_frame = 10;    /* due */
    const size_t mark = run_frame(w, 10);
    /* p(2) = 0.8953; group values 1, 1.4316, 1.6240: one multiquery of three. */
    CHECK_STR(describe(w, mark), "D(3) Q(L0,L1,L2) Q(L3) W");
    CHECK_U(tw_chc_stats(w->chc)->waits, 1);
    for (uint32_t k = 0; k < 3; k++)
        CHECK_U(w->state[0][w->tree->leaf_node[k]].invisible_frames, 3);
    /* The V-query stays in flight, recorded on the leaf. */
    CHECK(w->state[0][w->tree->leaf_node[3]].pending_query != 0);
    CHECK_U(fake_in_flight(&w->fake), 1);
    world_destroy(w);
}

/* A multiquery that comes back visible is re-issued as single queries, in the
 * same order; only the visible node is drawn. */
static void test_failed_multiquery(void)
{
    test_name = "failed_multiquery";
    struct world *w = world_create(column_tree(8), NULL, 1);
    set_interior_visible(w, 20);
    for (uint32_t k = 0; k < 8; k++)
        set_leaf_invisible(w, k, 5);
    point_in_leaf(w, 5);
    const size_t mark = run_frame(w, 20);
    CHECK_STR(describe(w, mark),
              "Q(L0,L1,L2,L3,L4,L5,L6,L7) W Q(L0) Q(L1) Q(L2) Q(L3) Q(L4) Q(L5) Q(L6) Q(L7)"
              " W W W W W W D(5) W W");
    const struct tw_chc_stats *st = tw_chc_stats(w->chc);
    CHECK_U(st->queries, 9);
    CHECK_U(st->multiqueries, 1);
    CHECK_U(st->requeries, 8);
    CHECK_U(st->nodes_queried, 16);
    CHECK_U(st->clusters_drawn, 1);
    CHECK_U(st->waits, 9);
    for (uint32_t k = 0; k < 8; k++) {
        const struct tw_chc_node_state *s = &w->state[0][w->tree->leaf_node[k]];
        CHECK_U(s->pending_query, 0);
        if (k == 5) {
            CHECK_U(s->visible_frame, 20);
            CHECK_U(s->invisible_frames, 0);
            /* Newly visible: first re-query in [f + 1, f + 1 + n_av]. */
            CHECK(s->next_query_frame >= 21 && s->next_query_frame <= 29);
        } else {
            CHECK_U(s->invisible_frames, 6);
        }
    }
    CHECK_U(fake_in_flight(&w->fake), 0);
    world_destroy(w);
}

/* Groups of the I-queue for hand-computed cases. p(i) = 0.99 - 0.7 e^-i, a
 * group M of size >= 2 costs 1 + (1 - prod p) |M|, a single query costs 1;
 * nodes sorted by p descending (ties front to back), a group grows while
 * |M| / cost does not fall. */
static const char *grouping(uint32_t leaves, const uint32_t *invisible_frames,
                            const struct tw_chc_settings *settings)
{
    static char result[4096];
    struct world *w = world_create(column_tree(leaves), settings, FAKE_NEVER);
    set_interior_visible(w, 30);
    for (uint32_t k = 0; k < leaves; k++)
        set_leaf_invisible(w, k, invisible_frames[k]);
    const size_t mark = run_frame(w, 30);
    snprintf(result, sizeof(result), "%s", describe_issues(w, mark));
    CHECK_U(fake_in_flight(&w->fake), 0);
    world_destroy(w);
    return result;
}

static void test_multiquery_grouping(void)
{
    test_name = "multiquery_grouping";
    uint32_t frames[25];

    /* p(50) = 0.99: |M| = 1..12 gives 1, 1.923, 2.755, 3.455, 4.016, 4.441,
     * 4.744, 4.944, 5.061, 5.112, 5.1132, 5.077: groups of 11. */
    for (uint32_t k = 0; k < 25; k++)
        frames[k] = 50;
    CHECK_STR(grouping(25, frames, NULL),
              "L0,L1,L2,L3,L4,L5,L6,L7,L8,L9,L10 | L11,L12,L13,L14,L15,L16,L17,L18,L19,L20,L21"
              " | L22,L23,L24");

    /* p(1) = 0.7325: 1, 1.038, 1.063, then 1.039 falls: groups of 3. */
    for (uint32_t k = 0; k < 7; k++)
        frames[k] = 1;
    CHECK_STR(grouping(7, frames, NULL), "L0,L1,L2 | L3,L4,L5 | L6");

    /* p(0) = 0.29: a pair is worth 0.706 < 1: single queries. */
    for (uint32_t k = 0; k < 3; k++)
        frames[k] = 0;
    CHECK_STR(grouping(3, frames, NULL), "L0 | L1 | L2");

    /* Mixed, sorted by p: L3 L4 L5 (i=5), L7 (3), L6 (2), L1 L2 (1), L0 (0).
     * {L3..L5}: 2.654, +L7: 2.973, +L6: 2.617 falls. {L6}: 1, +L1: 1.185,
     * +L2: 1.172 falls. {L2}: 1, +L0: 0.777 falls. {L0}. */
    static const uint32_t mixed[8] = {0, 1, 1, 5, 5, 5, 2, 3};
    CHECK_STR(grouping(8, mixed, NULL), "L3,L4,L5,L7 | L6,L1 | L2 | L0");

    /* Batches of b = 4: the I-queue is issued whenever it holds 4 nodes, and
     * the rest when traversal runs dry (one batch of 10 would be one group). */
    struct tw_chc_settings s = {.batch_size = 4};
    for (uint32_t k = 0; k < 10; k++)
        frames[k] = 50;
    CHECK_STR(grouping(10, frames, NULL), "L0,L1,L2,L3,L4,L5,L6,L7,L8,L9");
    CHECK_STR(grouping(10, frames, &s), "L0,L1,L2,L3 | L4,L5,L6,L7 | L8,L9");

    /* no_multiqueries: every node alone. */
    struct tw_chc_settings single = {.no_multiqueries = true};
    CHECK_STR(grouping(4, frames, &single), "L0 | L1 | L2 | L3");
}

/* Near-plane rule: a node whose box holds the eye, or lies within near-plane
 * distance of it, is treated as visible without a query (here the queries
 * would all say "invisible"). The tile is placed by its offset. */
static void test_near_plane(void)
{
    test_name = "near_plane";
    for (int variant = 0; variant < 2; variant++) {
        struct tw_box leaves[4];
        /* Tile-local boxes; the offset below moves them back to the column. */
        for (uint32_t k = 0; k < 4; k++) {
            leaves[k] = column_box(k);
            leaves[k].min[0] += 100.0f;
            leaves[k].max[0] += 100.0f;
            leaves[k].min[2] += 20.0f;
            leaves[k].max[2] += 20.0f;
        }
        struct world *w = world_create(tree_build(leaves, 4), NULL, 0);
        w->tile[0].offset[0] = -100.0f;
        w->tile[0].offset[2] = -20.0f;
        /* Inside L0 (z in [10, 11]), or 0.05 m in front of it. */
        w->eye[2] = variant == 0 ? 10.5f : 9.95f;
        const size_t mark = run_frame(w, 7);    /* zeroed state: all invisible before */
        /* Root (N0), N1 and L0 are near: no query; L1 and N4 are queried (singles,
         * p(0)), and say invisible. */
        CHECK_STR(describe(w, mark), "D(0) Q(L1) Q(N4) w w");
        CHECK_U(w->state[0][w->tree->leaf_node[0]].visible_frame, 7);
        CHECK_U(w->state[0][0].visible_frame, 7);     /* pulled up */
        CHECK_U(w->state[0][1].visible_frame, 7);
        CHECK_U(w->state[0][w->tree->leaf_node[1]].visible_frame, 0);
        CHECK_U(w->state[0][4].visible_frame, 0);
        world_destroy(w);
    }
}

/* V-queries in flight when the tile ends are read by the next frame's
 * begin_frame and applied as the previous frame's results; with the tile gone
 * (resolve NULL) they are read and dropped. */
static void test_deferred_vqueries(void)
{
    test_name = "deferred_vqueries";
    for (int variant = 0; variant < 3; variant++) {
        struct world *w = world_create(column_tree(4), NULL, FAKE_NEVER);
        point_in_leaf(w, 0);
        point_in_leaf(w, 2);
        tw_chc_state_init(w->state[0], &w->tree->bvh, 5);
        size_t mark = run_frame(w, 5);
        CHECK_STR(describe(w, mark), "D(0,1,2,3) Q(L0) Q(L1) Q(L2) Q(L3)");
        CHECK_U(fake_in_flight(&w->fake), 4);
        uint32_t handles[4];
        for (uint32_t k = 0; k < 4; k++) {
            handles[k] = w->state[0][w->tree->leaf_node[k]].pending_query;
            CHECK(handles[k] != 0);
        }
        struct tw_chc_node_state before[7];
        memcpy(before, w->state[0], sizeof(before));

        struct tw_view v;
        world_view(w, &v, 6);
        w->frame = 6;
        mark = w->fake.event_count;
        w->resolve_nothing = variant == 1;
        /* variant 2: no resolve callback at all. */
        tw_chc_begin_frame(w->chc, &v, &w->be, variant == 2 ? NULL : resolve, w);
        /* All four read, blocking (never ready), in issue order. */
        CHECK_STR(describe(w, mark), "W W W W");
        CHECK_U(fake_in_flight(&w->fake), 0);
        CHECK_U(tw_chc_stats(w->chc)->waits, 4);
        if (variant != 0) {
            CHECK(memcmp(before, w->state[0], sizeof(before)) == 0);
            world_destroy(w);
            continue;
        }
        /* Nodes: 0 root, 1 (L0,L1), 2 L0, 3 L1, 4 (L2,L3), 5 L2, 6 L3. */
        static const uint64_t visible_frame[7] = {5, 5, 5, 4, 5, 5, 4};
        for (uint32_t n = 0; n < 7; n++) {
            CHECK_U(w->state[0][n].visible_frame, visible_frame[n]);
            CHECK_U(w->state[0][n].pending_query, 0);
        }
        CHECK_U(w->state[0][3].invisible_frames, 1);
        CHECK_U(w->state[0][6].invisible_frames, 1);
        /* Applied as frame 5's: first re-query in [5 + 1, 5 + 1 + n_av]. */
        CHECK(w->state[0][2].next_query_frame >= 6 && w->state[0][2].next_query_frame <= 14);
        CHECK(w->state[0][5].next_query_frame >= 6 && w->state[0][5].next_query_frame <= 14);
        /* Not due in frame 6, whatever the random offsets were. */
        w->state[0][2].next_query_frame = w->state[0][5].next_query_frame = 100;

        /* Frame 6: L1 and L3 were invisible in frame 5, so they are queried
         * (p(1): a pair is worth 1.038 >= 1, one multiquery) and not drawn;
         * L0 and L2 are drawn before any query. */
        mark = w->fake.event_count;
        for (uint32_t t = 0; t < w->tile_count; t++)
            tw_chc_traverse(w->chc, &v, &w->be, &w->tile[t]);
        CHECK_STR(describe(w, mark), "D(0,2) Q(L1,L3) W");
        CHECK_STR(drawn_set(w, mark), "0,2");
        world_destroy(w);
    }
}

/* An occluded subtree: its root is queried, found invisible, and nothing
 * below it is drawn or queried, frame after frame. */
static void test_occluded_subtree(void)
{
    test_name = "occluded_subtree";
    /* Nodes as in test_pull_up; L0, L1 visible; 5 (L2,L3) and 8 (L4-L7) hidden. */
    struct world *w = world_create(column_tree(8), NULL, 0);
    point_in_leaf(w, 0);
    point_in_leaf(w, 1);
    tw_chc_state_init(w->state[0], &w->tree->bvh, 1);
    size_t mark = run_frame(w, 1);
    CHECK_STR(drawn_set(w, mark), "0,1,2,3,4,5,6,7");
    for (uint64_t f = 2; f <= 12; f++) {
        mark = run_frame(w, f);
        CHECK_STR(drawn_set(w, mark), "0,1");
        const char *issues = describe_issues(w, mark);
        for (uint32_t k = 2; k < 8; k++) {
            char name[8];
            snprintf(name, sizeof(name), "L%u", k);
            if (strstr(issues, name))
                fail(__LINE__, "frame %llu: hidden leaf %s queried: %s",
                     (unsigned long long)f, name, issues);
        }
        CHECK(strstr(issues, "N9") == NULL && strstr(issues, "N12") == NULL);
        CHECK(strstr(issues, "N5") != NULL && strstr(issues, "N8") != NULL);
    }
    CHECK_U(w->state[0][8].invisible_frames, 11);
    CHECK_U(w->state[0][8].visible_frame, 0);
    world_destroy(w);
}

/* A hidden node turns visible: it is queried, found visible, its subtree is
 * traversed and the leaf drawn, all in the same frame; with polls (ready after
 * two polls) rather than blocking where possible. */
static void test_becomes_visible(void)
{
    test_name = "becomes_visible";
    struct world *w = world_create(column_tree(8), NULL, 2);
    point_in_leaf(w, 0);
    point_in_leaf(w, 1);
    tw_chc_state_init(w->state[0], &w->tree->bvh, 1);
    for (uint64_t f = 1; f <= 5; f++)
        run_frame(w, f);
    point_in_leaf(w, 6);    /* node 13, under 12, under 8 */
    const size_t mark = run_frame(w, 6);
    CHECK_STR(drawn_set(w, mark), "0,1,6");
    /* Drawn after the query that found it visible. */
    size_t issue_at = SIZE_MAX, draw_at = SIZE_MAX;
    for (size_t e = mark; e < w->fake.event_count; e++) {
        const struct event *ev = &w->fake.events[e];
        for (size_t k = 0; k < ev->count; k++) {
            if (ev->type == EV_ISSUE && issue_at == SIZE_MAX &&
                box_equal(&w->fake.boxes[ev->first + k], &w->tree->leaf_box[6]))
                issue_at = e;
            if (ev->type == EV_DRAW && draw_at == SIZE_MAX && w->fake.clusters[ev->first + k] == 6)
                draw_at = e;
        }
    }
    CHECK(issue_at != SIZE_MAX && draw_at != SIZE_MAX && issue_at < draw_at);
    CHECK_U(w->state[0][13].visible_frame, 6);
    CHECK_U(w->state[0][12].visible_frame, 6);
    CHECK_U(w->state[0][8].visible_frame, 6);
    CHECK_U(w->state[0][9].visible_frame == 6, 0);
    CHECK_U(w->state[0][14].visible_frame == 6, 0);
    world_destroy(w);
}

/* Re-queries of a visible leaf: the first after becoming visible at a random
 * offset in [0, n_av], then every n_av + 1 frames; offsets spread over leaves. */
static void test_requery_schedule(void)
{
    test_name = "requery_schedule";
    const struct tw_chc_settings s = {.assumed_visible = 3, .seed = 7};
    struct world *w = world_create(column_tree(16), &s, 0);
    for (uint32_t k = 0; k < 16; k++)
        point_in_leaf(w, k);
    tw_chc_state_init(w->state[0], &w->tree->bvh, 1);
    uint64_t first_requery[16] = {0};
    uint64_t last_query[16] = {0};
    for (uint64_t f = 1; f <= 40; f++) {
        const size_t mark = run_frame(w, f);
        CHECK_STR(drawn_set(w, mark), "0,1,2,3,4,5,6,7,8,9,10,11,12,13,14,15");
        for (size_t e = mark; e < w->fake.event_count; e++) {
            const struct event *ev = &w->fake.events[e];
            if (ev->type != EV_ISSUE)
                continue;
            if (ev->count != 1) {
                fail(__LINE__, "multiquery on visible leaves");
                continue;
            }
            uint32_t k = 0;
            while (k < 16 && !box_equal(&w->fake.boxes[ev->first], &w->tree->leaf_box[k]))
                k++;
            if (k == 16) {
                fail(__LINE__, "frame %llu: an interior node was queried",
                     (unsigned long long)f);
                continue;
            }
            if (f == 1) {
                last_query[k] = 1;
                continue;
            }
            if (first_requery[k] == 0) {
                first_requery[k] = f;
                if (f < 2 || f > 5)
                    fail(__LINE__, "leaf %u: first re-query at frame %llu", k,
                         (unsigned long long)f);
            } else if (f - last_query[k] != 4) {
                fail(__LINE__, "leaf %u: re-queried at %llu after %llu", k,
                     (unsigned long long)f, (unsigned long long)last_query[k]);
            }
            last_query[k] = f;
        }
    }
    bool spread = false;
    for (uint32_t k = 0; k < 16; k++) {
        CHECK(first_requery[k] != 0);
        CHECK(last_query[k] >= 37);
        spread |= first_requery[k] != first_requery[0];
    }
    CHECK(spread);
    world_destroy(w);
}

/* Threshold T: visible only when samples > T. */
static void test_threshold(void)
{
    test_name = "threshold";
    const struct tw_chc_settings s = {.threshold = 1};
    struct world *w = world_create(column_tree(2), &s, 0);
    set_interior_visible(w, 3);
    set_leaf_invisible(w, 0, 0);
    set_leaf_invisible(w, 1, 0);
    point_in_leaf(w, 0);            /* one sample: not enough */
    point_in_leaf(w, 1);
    point_in_leaf(w, 1);            /* two samples */
    const size_t mark = run_frame(w, 3);
    CHECK_STR(describe(w, mark), "Q(L0) Q(L1) w w D(1)");
    world_destroy(w);
}

/* Tight boxes: a node's query draws its tight-box list, unless disabled. */
static void test_tight_boxes(void)
{
    test_name = "tight_boxes";
    for (int variant = 0; variant < 2; variant++) {
        const struct tw_chc_settings s = {.no_tight_boxes = variant == 1};
        struct world *w = world_create(column_tree(4), &s, 0);
        struct tree *t = w->tree;
        /* Node 1 (L0, L1): tight list = the two leaves' boxes. */
        t->tight[7] = t->leaf_box[0];
        t->tight[8] = t->leaf_box[1];
        t->bvh.tight_box_count = 9;
        t->nodes[1].first_tight = 7;
        t->nodes[1].tight_count = 2;
        set_interior_visible(w, 4);
        w->state[0][1] = (struct tw_chc_node_state){0, 0, 0, 0};
        w->state[0][4] = (struct tw_chc_node_state){0, 0, 0, 0};
        const size_t mark = run_frame(w, 4);
        CHECK_STR(describe_issues(w, mark), variant == 0 ? "L0,L1 | N4" : "N1 | N4");
        world_destroy(w);
    }
}

/* ---- randomised worlds: conservativeness, consistency, determinism ---------------- */

static uint64_t rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static float rng_float(uint64_t *s, float lo, float hi)
{
    return lo + (hi - lo) * (float)((rng_next(s) >> 11) * (1.0 / 9007199254740992.0));
}

/* Random leaves, sorted along z so that the balanced tree is spatially
 * coherent; every interior node at odd depth gets its children's boxes as
 * tight boxes. */
static struct tree *random_tree(uint64_t *rng, uint32_t leaves)
{
    struct tw_box boxes[MAX_NODES];
    for (uint32_t k = 0; k < leaves; k++) {
        const float x = rng_float(rng, -25, 25), z = rng_float(rng, 1, 70);
        const float sx = rng_float(rng, 0.3f, 3), sy = rng_float(rng, 0.5f, 6);
        const float sz = rng_float(rng, 0.3f, 3);
        boxes[k] = make_box(x, 0, z, x + sx, sy, z + sz);
    }
    for (uint32_t a = 1; a < leaves; a++)
        for (uint32_t b = a; b > 0 && boxes[b].min[2] < boxes[b - 1].min[2]; b--) {
            const struct tw_box t = boxes[b];
            boxes[b] = boxes[b - 1];
            boxes[b - 1] = t;
        }
    struct tree *t = tree_build(boxes, leaves);
    uint32_t next = t->bvh.node_count;
    for (uint32_t n = 0; n < t->bvh.node_count; n++) {
        const struct tw_bvh_node *node = &t->nodes[n];
        if (node->child[0] == TW_BVH_NONE || node->depth % 2 == 0)
            continue;
        t->tight[next] = t->nodes[node->child[0]].box;
        t->tight[next + 1] = t->nodes[node->child[1]].box;
        t->nodes[n].first_tight = next;
        t->nodes[n].tight_count = 2;
        next += 2;
    }
    t->bvh.tight_box_count = next;
    return t;
}

static uint64_t hash_bytes(uint64_t h, const void *p, size_t n)
{
    const unsigned char *b = p;
    for (size_t k = 0; k < n; k++)
        h = (h ^ b[k]) * 0x100000001b3ull;
    return h;
}

static uint64_t log_hash(const struct fake *f)
{
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t e = 0; e < f->event_count; e++) {
        const struct event *ev = &f->events[e];
        const uint32_t head[4] = {ev->type, ev->query, ev->blocked, ev->answer};
        h = hash_bytes(h, head, sizeof(head));
        if (ev->type == EV_ISSUE)
            h = hash_bytes(h, &f->boxes[ev->first], ev->count * sizeof(*f->boxes));
        if (ev->type == EV_DRAW)
            h = hash_bytes(h, &f->clusters[ev->first], ev->count * sizeof(*f->clusters));
    }
    return h;
}

struct random_run {
    uint64_t hash;
    size_t events;
    size_t bytes_warm, bytes_end;
    uint32_t suspended;     /* passes suspended over the run (async) */
    uint32_t waits;
    uint32_t idle_flushes;  /* flushes with nothing issued or drawn since the last */
    uint32_t flushes;       /* every flush */
    uint32_t rounds;        /* wavefront: the world's own */
    uint32_t unsent_waits;  /* waits on a query issued since the last flush */
};

/* Blocking waits, after log index mark, on a query that no flush had sent
 * yet (a result the fake has ready needed no flush). */
static uint32_t unsent_waits(const struct fake *f, size_t mark)
{
    uint32_t n = 0;
    for (size_t e = mark; e < f->event_count; e++) {
        if (f->events[e].type != EV_WAIT || !f->events[e].blocked)
            continue;
        bool sent = false;
        for (size_t k = e; k-- > 0;) {
            if (f->events[k].type == EV_FLUSH)
                sent = true;
            if (f->events[k].type == EV_ISSUE && f->events[k].query == f->events[e].query)
                break;
        }
        n += !sent;
    }
    return n;
}

static uint32_t idle_flushes(const struct fake *f)
{
    uint32_t n = 0;
    bool since = true;
    for (size_t e = 0; e < f->event_count; e++) {
        const enum ev_type t = f->events[e].type;
        if (t == EV_FLUSH) {
            n += !since;
            since = false;
        } else if (t == EV_ISSUE || t == EV_DRAW) {
            since = true;
        }
    }
    return n;
}

/* The tiles random_run() walks (2 to MAX_TILES) and whether it traverses
 * them with tw_chc_traverse_async(). */
static uint32_t random_tiles = 2;
static bool random_async;
static bool random_wavefront;

/* Two tiles sharing one random BVH, random visibility changing every frame, a
 * jittering camera. Checks every frame: each leaf that the fake sees (a point
 * inside its box, in the frustum, within view distance) is drawn; no cluster
 * drawn twice; pending_query set exactly on the nodes with a query in flight;
 * after begin_frame nothing is in flight. */
static struct random_run random_run(uint64_t seed, const struct tw_chc_settings *settings,
                                    uint32_t ready_after, uint32_t frames)
{
    uint64_t rng = seed;
    const uint32_t leaves = 24 + (uint32_t)(rng_next(&rng) % 40);
    struct world *w = world_create(random_tree(&rng, leaves), settings, ready_after);
    struct tree *t = w->tree;
    w->tile_count = random_tiles;
    w->async = random_async || random_wavefront;
    w->wavefront = random_wavefront;
    tw_chc_set_wavefront(w->chc, random_wavefront);
    for (uint32_t k = 1; k < w->tile_count; k++) {
        w->tile[k] = w->tile[0];
        w->tile[k].cell = (struct tw_cell){0, k};
        w->tile[k].state = w->state[k];
        w->tile[k].offset[2] = 75.0f * (float)k;
        w->tile[k].tag = TAG_B + k - 1;
    }
    tw_chc_state_init(w->state[0], &t->bvh, 1);
    /* Tiles B...: zeroed state, as the cache hands it out. */

    static bool visible_leaf[MAX_TILES][MAX_NODES];
    memset(visible_leaf, 0, sizeof(visible_leaf));
    struct random_run out = {0};
    for (uint32_t f = 1; f <= frames; f++) {
        /* Visibility changes: each leaf flips with probability 1/5. */
        w->fake.point_count = 0;
        for (uint32_t tile = 0; tile < w->tile_count; tile++)
            for (uint32_t k = 0; k < leaves; k++) {
                if (rng_next(&rng) % 5 == 0)
                    visible_leaf[tile][k] = !visible_leaf[tile][k];
                if (visible_leaf[tile][k]) {
                    float c[3];
                    leaf_center(t, k, c);
                    c[2] += w->tile[tile].offset[2];
                    fake_add_point(&w->fake, c[0], c[1], c[2]);
                }
            }
        w->eye[0] = rng_float(&rng, -2, 2);
        w->eye[2] = rng_float(&rng, -3, 3);
        w->yaw = rng_float(&rng, -25, 25);

        size_t begin_mark;
        const size_t mark = run_frame_at(w, f, &begin_mark, __LINE__);
        out.suspended += tw_chc_stats(w->chc)->suspended;
        out.waits += tw_chc_stats(w->chc)->waits;
        out.rounds += w->rounds;
        out.unsent_waits += unsent_waits(&w->fake, mark);
        for (size_t e = mark; e < w->fake.event_count; e++)
            out.flushes += w->fake.events[e].type == EV_FLUSH;
        if (w->fake.query_count > 0 && fake_in_flight(&w->fake) > 0) {
            /* Only queries issued in this frame's traversal may be in flight. */
            for (size_t e = 0; e < begin_mark; e++)
                if (w->fake.events[e].type == EV_ISSUE &&
                    !w->fake.queries[w->fake.events[e].query - 1].released)
                    fail(__LINE__, "seed %llu frame %u: an old query is still unread",
                         (unsigned long long)seed, f);
        }

        struct tw_view v;
        world_view(w, &v, f);
        for (uint32_t tile = 0; tile < w->tile_count; tile++) {
            bool drawn[MAX_NODES];
            drawn_since(w, mark, tile, drawn);
            for (uint32_t k = 0; k < leaves; k++) {
                const struct tw_box *b = &t->leaf_box[k];
                const float *off = w->tile[tile].offset;
                if (!visible_leaf[tile][k] || tw_cull_box_distance(&v, b, off) > v.view_distance ||
                    tw_cull_frustum_box(&v.frustum, b, off) == TW_CULL_OUTSIDE)
                    continue;
                if (!drawn[k])
                    fail(__LINE__, "seed %llu frame %u: visible leaf %u of tile %u not drawn",
                         (unsigned long long)seed, f, k, tile);
            }
            /* pending_query <=> a query on that node in flight. */
            for (uint32_t n = 0; n < t->bvh.node_count; n++) {
                const uint32_t q = w->state[tile][n].pending_query;
                if (q != 0 && (q > w->fake.query_count || w->fake.queries[q - 1].released))
                    fail(__LINE__, "seed %llu frame %u: node %u pending on a read query",
                         (unsigned long long)seed, f, n);
            }
        }
        size_t pending = 0;
        for (uint32_t tile = 0; tile < w->tile_count; tile++)
            for (uint32_t n = 0; n < t->bvh.node_count; n++)
                pending += w->state[tile][n].pending_query != 0;
        if (pending != fake_in_flight(&w->fake))
            fail(__LINE__, "seed %llu frame %u: %zu nodes pending, %zu queries in flight",
                 (unsigned long long)seed, f, pending, fake_in_flight(&w->fake));
        if (f == 10)
            out.bytes_warm = tw_chc_bytes(w->chc);
    }
    out.bytes_end = tw_chc_bytes(w->chc);
    out.hash = log_hash(&w->fake);
    out.idle_flushes = idle_flushes(&w->fake);
    out.events = w->fake.event_count;
    world_destroy(w);
    return out;
}

/* The results come back after 0, 1 or 3 polls, or only when waited for. */
static const uint32_t ready_modes[4] = {0, 1, 3, FAKE_NEVER};

/* Settings that vary with the seed: batch size, multiqueries, tight boxes,
 * assumed-visible frames. */
static struct tw_chc_settings random_settings(uint64_t seed)
{
    struct tw_chc_settings s = {.seed = seed};
    if (seed % 3 == 1)
        s.batch_size = 3;
    if (seed % 4 == 2)
        s.no_multiqueries = true;
    if (seed % 5 == 3)
        s.no_tight_boxes = true;
    s.assumed_visible = (uint32_t)(seed % 6);
    return s;
}

static void test_random_worlds(void)
{
    test_name = "random_worlds";
    for (uint64_t seed = 1; seed <= 12; seed++)
        for (int m = 0; m < 4; m++) {
            const struct tw_chc_settings s = random_settings(seed);
            const struct random_run r = random_run(seed * 977, &s, ready_modes[m], 40);
            /* Warm: no growth after the first frames. */
            if (r.bytes_warm != r.bytes_end)
                fail(__LINE__, "seed %llu: engine grew from %zu to %zu bytes once warm",
                     (unsigned long long)seed, r.bytes_warm, r.bytes_end);
        }
}

/* The random worlds over six tiles, traversed with tw_chc_traverse_async(),
 * one pass suspended at a time (the default) and four: the same invariants
 * hold (every visible leaf drawn, nothing drawn twice, nothing left in
 * flight but deferred V-queries) while passes are suspended, and more
 * passes than slots (the oldest then finished first). Where results come
 * late, passes are suspended and fewer waits block. */
static void test_async_worlds(void)
{
    test_name = "async_worlds";
    random_tiles = MAX_TILES;
    for (uint64_t seed = 1; seed <= 16; seed++)
        for (int m = 0; m < 4; m++) {
            struct tw_chc_settings s = random_settings(seed);
            s.suspended_passes = seed % 2 ? 1 : TW_CHC_MAX_SUSPENDED;
            random_async = false;
            const struct random_run sync = random_run(seed * 313, &s, ready_modes[m], 30);
            random_async = true;
            const struct random_run async = random_run(seed * 313, &s, ready_modes[m], 30);
            if (ready_modes[m] == 0 && async.suspended != 0)
                fail(__LINE__, "seed %llu: %u passes suspended though every result was ready",
                     (unsigned long long)seed, async.suspended);
            /* (Results that never come make every wait block, either way.) */
            if (ready_modes[m] != 0 &&
                (async.suspended == 0 ||
                 (ready_modes[m] != FAKE_NEVER && async.waits >= sync.waits)))
                fail(__LINE__, "seed %llu, results after %u polls: %u suspended, %u waits "
                     "(traversed one by one: %u)", (unsigned long long)seed, ready_modes[m],
                     async.suspended, async.waits, sync.waits);
            /* Nothing drawn or issued since the last flush: no flush (a
             * resumed pass whose results are not in yet has nothing new). */
            if (async.idle_flushes != 0 || sync.idle_flushes != 0)
                fail(__LINE__, "seed %llu, results after %u polls: %u idle flushes "
                     "(one by one: %u)", (unsigned long long)seed, ready_modes[m],
                     async.idle_flushes, sync.idle_flushes);
        }
    random_async = false;
    random_tiles = 2;
}

/* Wavefront mode (tilequery+chc): the random worlds over six tiles, every
 * pass suspended at once, the world flushing once per wavefront and the
 * passes resumed after it. The same invariants hold (every visible leaf
 * drawn, nothing drawn twice, nothing left in flight but deferred
 * V-queries); the engine never flushes itself (every flush is one of the
 * world's) and never waits on a query that no flush has sent. */
static void test_wavefront_worlds(void)
{
    test_name = "wavefront_worlds";
    random_tiles = MAX_TILES;
    random_wavefront = true;
    for (uint64_t seed = 1; seed <= 16; seed++)
        for (int m = 0; m < 4; m++) {
            const struct tw_chc_settings s = random_settings(seed);
            const struct random_run r = random_run(seed * 313, &s, ready_modes[m], 30);
            if (r.flushes != r.rounds || r.unsent_waits != 0)
                fail(__LINE__, "seed %llu, results after %u polls: %u flushes for %u "
                     "wavefronts, %u waits on unsent queries", (unsigned long long)seed,
                     ready_modes[m], r.flushes, r.rounds, r.unsent_waits);
            if (ready_modes[m] != 0 && r.suspended == 0)
                fail(__LINE__, "seed %llu: no pass suspended", (unsigned long long)seed);
        }
    random_wavefront = false;
    random_tiles = 2;
}

/* Same inputs, same log; another PRNG seed, another re-query schedule. */
static void test_determinism(void)
{
    test_name = "determinism";
    const struct tw_chc_settings s = {.seed = 99};
    const struct random_run a = random_run(4242, &s, 1, 30);
    const struct random_run b = random_run(4242, &s, 1, 30);
    CHECK_U(a.events, b.events);
    CHECK_U(a.hash, b.hash);
    const struct tw_chc_settings other = {.seed = 100};
    const struct random_run c = random_run(4242, &other, 1, 30);
    CHECK(a.hash != c.hash);
}

/* ---- the cost model (DESIGN §14) ----------------------------------------------------- */

/* Queries cost a millisecond, a leaf of 10 triangles 2 microseconds. */
static const struct tw_cost_model expensive_queries = {
    .query = 1.0f, .query_box = 0.01f, .query_pixel = 0.0f, .draw = 1e-3f, .triangle = 1e-4f,
    .screen_pixels = 1e5f,
};
/* Queries cost a microsecond, a leaf of 10 triangles two milliseconds. */
static const struct tw_cost_model cheap_queries = {
    .query = 1e-3f, .query_box = 0.0f, .query_pixel = 0.0f, .draw = 1.0f, .triangle = 0.1f,
    .screen_pixels = 1e5f,
};

/* Expensive queries: previously hidden small leaves are drawn without a
 * query, counted as skipped, and not marked visible (so that their parent
 * may still be found hidden); with cheap queries, as without a model. */
static void test_cost_skip_hidden(void)
{
    test_name = "cost_skip_hidden";
    const char *expect[3] = {
        "Q(L0) Q(L1) Q(L2) Q(L3) W W D(1) W W",  /* no model: p(0) singles */
        "D(0,1,2,3)",                              /* expensive: drawn, no query */
        "Q(L0) Q(L1) Q(L2) Q(L3) W W D(1) W W",  /* cheap: as without */
    };
    const struct tw_cost_model *models[3] = {NULL, &expensive_queries, &cheap_queries};
    for (int m = 0; m < 3; m++) {
        world_costs = models[m];
        struct world *w = world_create(column_tree(4), NULL, FAKE_NEVER);
        world_costs = NULL;
        set_interior_visible(w, 20);
        for (uint32_t k = 0; k < 4; k++)
            set_leaf_invisible(w, k, 0);
        point_in_leaf(w, 1);
        const size_t mark = run_frame(w, 20);
        CHECK_STR(describe(w, mark), expect[m]);
        const struct tw_chc_stats *st = tw_chc_stats(w->chc);
        CHECK_U(st->queries_skipped, m == 1 ? 4 : 0);
        CHECK_U(st->queries, m == 1 ? 0 : 4);
        /* Drawn, never hidden; visible only where a query said so. */
        CHECK_U(st->clusters_drawn, m == 1 ? 4 : 1);
        for (uint32_t k = 0; k < 4; k++) {
            const struct tw_chc_node_state *ls = &w->state[0][w->tree->leaf_node[k]];
            if (m == 1)
                CHECK(ls->visible_frame == 0 && ls->pending_query == 0);
            else
                CHECK((ls->visible_frame == 20) == (k == 1));
        }
        world_destroy(w);
    }
}

/* Expensive queries: at first sight the small leaves are drawn and their
 * re-queries skipped (they cannot pay: a hidden answer could save at most
 * n_av + 1 frames of their parent's few triangles); they stay visible and
 * are due again n_av + 1 frames later. Cheap queries: re-queried as always. */
static void test_cost_skip_requery(void)
{
    test_name = "cost_skip_requery";
    for (int m = 0; m < 2; m++) {
        world_costs = m ? &expensive_queries : &cheap_queries;
        struct world *w = world_create(column_tree(4), NULL, FAKE_NEVER);
        world_costs = NULL;
        tw_chc_state_init(w->state[0], &w->tree->bvh, 5);
        const size_t mark = run_frame(w, 5);
        const struct tw_chc_stats *st = tw_chc_stats(w->chc);
        if (m) {
            CHECK_STR(describe(w, mark), "D(0,1,2,3)");
            CHECK_U(st->queries_skipped, 4);
            for (uint32_t k = 0; k < 4; k++) {
                const struct tw_chc_node_state *ls = &w->state[0][w->tree->leaf_node[k]];
                CHECK_U(ls->visible_frame, 5);
                CHECK_U(ls->next_query_frame, 5 + 1 + 8);
            }
            CHECK_U(w->state[0][0].visible_frame, 5);
        } else {
            CHECK_STR(describe(w, mark), "D(0,1,2,3) Q(L0) Q(L1) Q(L2) Q(L3)");
            CHECK_U(st->queries_skipped, 0);
        }
        world_destroy(w);
    }
}

/* A visible leaf's re-query is weighed by the measured chance that it finds
 * the leaf hidden: with every leaf always visible, re-queries that paid at
 * the prior (one in two) stop paying once answers come back visible, and
 * only the exploring few are issued; with cheap queries none is skipped. */
static void test_cost_requery_rate(void)
{
    test_name = "cost_requery_rate";
    /* A hidden answer saves at most 9 frames x 2 draws of the parent: 18 p
     * against a query of 4, worth it while p > 0.22. */
    static const struct tw_cost_model middling = {
        .query = 4.0f, .draw = 1.0f, .screen_pixels = 1e5f,
    };
    for (int m = 0; m < 2; m++) {
        world_costs = m ? &cheap_queries : &middling;
        struct world *w = world_create(column_tree(4), NULL, 0);
        world_costs = NULL;
        tw_chc_state_init(w->state[0], &w->tree->bvh, 2);
        for (uint32_t k = 0; k < 4; k++)
            point_in_leaf(w, k);
        uint32_t early = 0, late = 0, late_skipped = 0, skipped = 0;
        for (uint64_t f = 2; f <= 80; f++) {
            run_frame(w, f);
            const struct tw_chc_stats *st = tw_chc_stats(w->chc);
            skipped += st->queries_skipped;
            if (f <= 12)
                early += st->queries;
            if (f > 40) {
                late += st->queries;
                late_skipped += st->queries_skipped;
            }
        }
        if (m) {
            CHECK_U(skipped, 0);
        } else {
            CHECK(early >= 4);
            CHECK(late_skipped > 2 * late);
        }
        world_destroy(w);
    }
}

/* A large leaf is queried even when queries are expensive: its triangles
 * cost more than the query. */
static void test_cost_large_leaf(void)
{
    test_name = "cost_large_leaf";
    world_costs = &expensive_queries;
    struct world *w = world_create(column_tree(2), NULL, FAKE_NEVER);
    world_costs = NULL;
    /* Leaf 0: 20000 triangles (2 ms to draw > 1 ms / p); leaf 1 stays small. */
    w->tree->nodes[w->tree->leaf_node[0]].triangle_count = 20000;
    set_interior_visible(w, 7);
    set_leaf_invisible(w, 0, 3);
    set_leaf_invisible(w, 1, 3);
    const size_t mark = run_frame(w, 7);
    CHECK_STR(describe(w, mark), "D(1) Q(L0) W");
    CHECK_U(tw_chc_stats(w->chc)->queries_skipped, 1);
    world_destroy(w);
}

/* A hidden node's pixels are priced too: the same small leaves that
 * expensive queries leave unqueried are queried once drawing their boxes'
 * pixels (depth-tested, hidden) costs more than a query. */
static void test_cost_hidden_pixels(void)
{
    test_name = "cost_hidden_pixels";
    struct tw_cost_model pixels = expensive_queries;
    pixels.draw_pixel = 1e-1f;
    for (int m = 0; m < 2; m++) {
        world_costs = m ? &pixels : &expensive_queries;
        struct world *w = world_create(column_tree(2), NULL, FAKE_NEVER);
        world_costs = NULL;
        set_interior_visible(w, 7);
        set_leaf_invisible(w, 0, 3);
        set_leaf_invisible(w, 1, 3);
        const size_t mark = run_frame(w, 7);
        CHECK_STR(describe(w, mark), m ? "Q(L0,L1) W" : "D(0,1)");
        CHECK_U(tw_chc_stats(w->chc)->queries_skipped, m ? 0 : 2);
        world_destroy(w);
    }
}

/* The fixed costs are shared, so the choice is made per group and per
 * batch: four small leaves, long hidden, that a query of their own would
 * not pay for are queried as one group; the same four are drawn when
 * sending the batch and waiting for it (query_flush) costs more than they
 * can save. */
static void test_cost_batch(void)
{
    test_name = "cost_batch";
    /* A leaf: 10 triangles, 5 microseconds to draw; a query 10. */
    struct tw_cost_model shared = {
        .query = 0.01f, .draw = 0.004f, .triangle = 1e-4f,
        .screen_pixels = 1e5f,
    };
    const char *expect[2] = {"Q(L0,L1,L2,L3) W", "D(0,1,2,3)"};
    for (int m = 0; m < 2; m++) {
        shared.query_flush = m ? 1.0f : 0.0f;
        world_costs = &shared;
        struct world *w = world_create(column_tree(4), NULL, FAKE_NEVER);
        world_costs = NULL;
        set_interior_visible(w, 20);
        for (uint32_t k = 0; k < 4; k++)
            set_leaf_invisible(w, k, 3);
        const size_t mark = run_frame(w, 20);
        CHECK_STR(describe(w, mark), expect[m]);
        CHECK_U(tw_chc_stats(w->chc)->queries_skipped, m ? 4 : 0);
        world_destroy(w);
    }
}

/* Groups sized with costs: when a query's cost is all in its boxes (the
 * fixed part nothing), grouping saves nothing and every node goes alone;
 * when it is all in the fixed part, the groups are those of unit costs. */
static void test_cost_grouping(void)
{
    test_name = "cost_grouping";
    uint32_t frames[12];
    for (uint32_t k = 0; k < 12; k++)
        frames[k] = 50;
    const struct tw_cost_model boxes_cost = {
        .query = 1e-6f, .query_box = 1.0f, .draw = 10.0f, .triangle = 1.0f,
        .screen_pixels = 1e5f,
    };
    world_costs = &boxes_cost;
    CHECK_STR(grouping(4, frames, NULL), "L0 | L1 | L2 | L3");
    world_costs = &cheap_queries;
    CHECK_STR(grouping(12, frames, NULL), "L0,L1,L2,L3,L4,L5,L6,L7,L8,L9,L10 | L11");
    world_costs = NULL;
    CHECK_STR(grouping(12, frames, NULL), "L0,L1,L2,L3,L4,L5,L6,L7,L8,L9,L10 | L11");
}

/* Whatever the costs, every visible leaf is drawn (random worlds), and with
 * cheap queries the run is the run without a model, event for event. */
static void test_cost_random_worlds(void)
{
    test_name = "cost_random_worlds";
    const struct tw_cost_model middle = {
        .query = 0.03f, .query_box = 0.001f, .query_pixel = 1e-6f, .draw = 0.002f,
        .triangle = 1e-3f, .screen_pixels = 1e5f,
    };
    const struct tw_cost_model *models[2] = {&expensive_queries, &middle};
    for (uint64_t seed = 1; seed <= 6; seed++)
        for (int m = 0; m < 2; m++) {
            const struct tw_chc_settings s = {.seed = seed, .assumed_visible = (uint32_t)seed % 4};
            world_costs = models[m];
            random_run(seed * 131, &s, seed % 2 ? 1 : FAKE_NEVER, 30);
            world_costs = NULL;
        }
    const struct tw_chc_settings s = {.seed = 7};
    const struct random_run plain = random_run(555, &s, 1, 30);
    world_costs = &cheap_queries;
    const struct random_run cheap = random_run(555, &s, 1, 30);
    world_costs = &expensive_queries;
    const struct random_run dear = random_run(555, &s, 1, 30);
    const struct tw_chc_settings off = {.seed = 7, .no_cost_model = true};
    const struct random_run ignored = random_run(555, &off, 1, 30);
    world_costs = NULL;
    CHECK_U(cheap.hash, plain.hash);
    CHECK_U(cheap.events, plain.events);
    CHECK(dear.hash != plain.hash);
    CHECK_U(ignored.hash, plain.hash);
}

static void test_api_edges(void)
{
    test_name = "api_edges";
    struct tw_chc_settings s = {0};
    tw_chc_default_settings(&s);
    CHECK_U(s.batch_size, 50);
    CHECK_U(s.assumed_visible, 8);
    CHECK_U(s.threshold, 0);
    CHECK_U(s.suspended_passes, 1);
    CHECK(tw_chc_create(NULL, NULL) == TW_ERR_INVALID);
    {
        struct tw_chc *bad = (struct tw_chc *)&s;
        const struct tw_chc_settings many = {.suspended_passes = TW_CHC_MAX_SUSPENDED + 1};
        CHECK(tw_chc_create(&many, &bad) == TW_ERR_INVALID && bad == NULL);
    }
    tw_chc_destroy(NULL);
    struct tree *t = column_tree(3);
    CHECK_U(tw_chc_state_bytes(&t->bvh), 5 * sizeof(struct tw_chc_node_state));
    free(t);
    struct tw_chc *chc = NULL;
    CHECK(tw_chc_create(NULL, &chc) == TW_OK && chc != NULL);
    CHECK(tw_chc_bytes(chc) > 0);
    tw_chc_destroy(chc);
}

int main(void)
{
    test_api_edges();
    test_first_sight();
    test_first_sight_queries();
    test_pull_up();
    test_shared_cluster();
    test_drawn_before_wait();
    test_wavefront_worlds();
    test_failed_multiquery();
    test_multiquery_grouping();
    test_near_plane();
    test_deferred_vqueries();
    test_occluded_subtree();
    test_becomes_visible();
    test_requery_schedule();
    test_threshold();
    test_tight_boxes();
    test_random_worlds();
    test_async_worlds();
    test_determinism();
    test_cost_skip_hidden();
    test_cost_skip_requery();
    test_cost_requery_rate();
    test_cost_large_leaf();
    test_cost_hidden_pixels();
    test_cost_batch();
    test_cost_grouping();
    test_cost_random_worlds();
    if (failures) {
        fprintf(stderr, "test-chc: %d check(s) failed\n", failures);
        return 1;
    }
    printf("test-chc: all tests passed\n");
    return 0;
}
