/* Tile-query propagation with pending and postponed queues (DESIGN §4). */
#include "cull/cull-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

struct pending {
    uint32_t query;          /* 0: visible without a query */
    bool predicted;          /* visible last frame */
    bool known;              /* last frame had a verdict on the cell (a prediction exists) */
    bool visible;            /* this frame's verdict, once its wavefront is read */
    bool postponed;          /* drawn on last frame's word, its query read at the end */
    struct tw_cell cell;     /* a node of the cut: its base and level */
    uint32_t level;
};

struct tw_tilequery {
    struct tw_tilequery_settings s;
    struct tw_cell_map *visible;   /* cell -> last frame found visible */
    struct tw_cell_map *queried;   /* cell -> last frame queried or reached */
    struct pending *queue;         /* pending queue Q: [head, tail) */
    uint32_t head, tail, queue_cap;
    struct pending *postponed;     /* postponed queue P */
    uint32_t postponed_count, postponed_cap;
    uint32_t *stale;               /* unread queries of last frame, drained next frame */
    uint32_t stale_count, stale_cap;
    struct tw_cull_cell *cells;    /* scratch: finding the start node, a node's neighbours */
    size_t cell_cap;
    uint64_t last_prune;
    /* For tw_tilequery_last_cells(): the last frame and its start cell. */
    uint64_t last_frame;
    struct tw_cell last_start;
    bool last_started;
};

void tw_tilequery_default_settings(struct tw_tilequery_settings *s)
{
    if (s->neighbours != 8)
        s->neighbours = 4;
}

int tw_tilequery_create(const struct tw_tilequery_settings *settings, struct tw_tilequery **out)
{
    struct tw_tilequery *tq = calloc(1, sizeof(*tq));
    if (!tq)
        return TW_ERR_NOMEM;
    if (settings)
        tq->s = *settings;
    tw_tilequery_default_settings(&tq->s);
    int err = tw_cell_map_create(&tq->visible);
    if (!err)
        err = tw_cell_map_create(&tq->queried);
    if (err) {
        tw_tilequery_destroy(tq);
        return err;
    }
    *out = tq;
    return TW_OK;
}

void tw_tilequery_destroy(struct tw_tilequery *tq)
{
    if (!tq)
        return;
    tw_cell_map_destroy(tq->visible);
    tw_cell_map_destroy(tq->queried);
    free(tq->queue);
    free(tq->postponed);
    free(tq->stale);
    free(tq->cells);
    free(tq);
}

static bool prune_old(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    return value + 1 < *(const uint64_t *)user;
}

bool tw_tilequery_was_visible(const struct tw_tilequery *tq, struct tw_cell cell, uint64_t frame)
{
    const uint64_t *v = tw_cell_map_find(tq->visible, cell);
    return v && *v == frame;
}

size_t tw_tilequery_bytes(const struct tw_tilequery *tq)
{
    return sizeof(*tq) + tw_cell_map_bytes(tq->visible) + tw_cell_map_bytes(tq->queried) +
           sizeof(*tq->queue) * tq->queue_cap + sizeof(*tq->postponed) * tq->postponed_cap +
           sizeof(*tq->stale) * tq->stale_cap + sizeof(*tq->cells) * tq->cell_cap;
}

struct frame_ctx {
    struct tw_tilequery *tq;
    const struct tw_view *v;
    const struct tw_query_backend *be;
    const struct tw_cull_grid *g;
    struct tw_box box[TW_CULL_MAX_LEVELS];  /* each level's node box */
    tw_tilequery_render_fn render;
    tw_tilequery_front_fn front;
    void *user;
    struct tw_tilequery_stats *st;
    int err;
};

static void offset_of(const struct frame_ctx *fc, struct tw_cell cell, float out[3])
{
    tw_tiles_cell_offset(cell, fc->v->cell, fc->g->footprint[0], fc->g->footprint[1], out);
}

/* Node (cell, level) is a candidate: its box meets the frustum within view
 * distance. */
static bool in_view(const struct frame_ctx *fc, struct tw_cell cell, uint32_t level,
                    float *distance)
{
    float off[3];
    offset_of(fc, cell, off);
    *distance = tw_cull_box_distance(fc->v, &fc->box[level], off);
    if (*distance > fc->v->view_distance)
        return false;
    return tw_cull_frustum_box(&fc->v->frustum, &fc->box[level], off) != TW_CULL_OUTSIDE;
}

/* The box that a tile query of node (cell, level), placed at off, draws:
 * its box, stretched towards the eye's height when the eye is above (or
 * below) it, as far as a ray from the eye to a point of a common box within
 * the view distance can pass over (or under) the node. A query is answered
 * at pixel centres: seen from above, a far node's box may cover none of
 * them where its content is hidden, while the ray of a pixel passes just
 * above it to a visible cell beyond; without the stretch the propagation
 * stops there and the cell beyond is never reached. With it, every ray
 * from the eye to a visible point of a cell passes through the query box
 * of every node on its way (the argument of DESIGN §4 at pixel centres).
 * A ray from the eye at height e to a point at height h, horizontal
 * distance t <= R, crosses horizontal distance d at e + (h - e) d / t: over
 * a node at least d_min away, at most e - (e - top) d_min / R. */
static struct tw_box query_box(const struct frame_ctx *fc, uint32_t level, const float off[3])
{
    struct tw_box b = fc->box[level];
    const float *eye = fc->v->eye;
    const float R = fc->v->view_distance;
    float dx = 0.0f, dz = 0.0f;
    if (eye[0] < b.min[0] + off[0])
        dx = b.min[0] + off[0] - eye[0];
    else if (eye[0] > b.max[0] + off[0])
        dx = eye[0] - b.max[0] - off[0];
    if (eye[2] < b.min[2] + off[2])
        dz = b.min[2] + off[2] - eye[2];
    else if (eye[2] > b.max[2] + off[2])
        dz = eye[2] - b.max[2] - off[2];
    const float d = sqrtf(dx * dx + dz * dz);
    const float f = R > 0.0f && d < R ? d / R : 1.0f;
    const float y = eye[1] - off[1];
    if (y > b.max[1])
        b.max[1] = y - (y - b.max[1]) * f;
    else if (y < b.min[1])
        b.min[1] = y + (b.min[1] - y) * f;
    return b;
}

/* Step 3: query the neighbours of a rendered node, nearest first: the
 * first count entries of tq->cells, their distances set
 * (tw_cull_nodes_in_view_prefetch; INFINITY: out of view). */
static void query_neighbours(struct frame_ctx *fc, size_t count)
{
    struct tw_tilequery *tq = fc->tq;
    const uint64_t f = fc->v->frame;
    /* Those to query, moved to the front of tq->cells, nearest first
     * (insertion sort: a handful of entries; ties keep their order). */
    size_t n = 0;
    for (size_t k = 0; k < count; k++) {
        const struct tw_cull_cell c = tq->cells[k];
        const uint64_t *q = tw_cell_map_find(tq->queried, c.cell);
        if (q && *q == f)
            continue;
        if (c.distance == INFINITY) {
            if (tw_cell_map_set(tq->queried, c.cell, f)) {
                fc->err = TW_ERR_NOMEM;
                return;
            }
            continue;
        }
        size_t at = n++;
        while (at > 0 && tq->cells[at - 1].distance > c.distance) {
            tq->cells[at] = tq->cells[at - 1];
            at--;
        }
        tq->cells[at] = c;
    }
    if (n == 0)
        return;
    if (tw_array_reserve_u32((void **)&tq->queue, &tq->queue_cap, tq->tail + (uint32_t)n,
                             sizeof(*tq->queue), 64)) {
        fc->err = TW_ERR_NOMEM;
        return;
    }
    for (size_t k = 0; k < n; k++) {
        const struct tw_cull_cell c = tq->cells[k];
        const uint64_t *q = tw_cell_map_find(tq->queried, c.cell);
        const bool known = q && *q + 1 == f;
        if (tw_cell_map_set(tq->queried, c.cell, f)) {
            fc->err = TW_ERR_NOMEM;
            return;
        }
        struct pending *p = &tq->queue[tq->tail++];
        const uint64_t *vis = tw_cell_map_find(tq->visible, c.cell);
        p->cell = c.cell;
        p->level = c.level;
        p->predicted = vis && *vis + 1 == f;
        p->known = known || p->predicted;
        float off[3];
        offset_of(fc, c.cell, off);
        const struct tw_box qb = query_box(fc, c.level, off);
        if (tw_cull_near_box(fc->v, &qb, off)) {
            /* The near plane may cut this box: a query could lie. */
            p->query = 0;
            fc->st->tiles_free++;
        } else {
            if (fc->be->tile_query_next)
                fc->be->tile_query_next(fc->be->ctx);
            p->query = fc->be->issue(fc->be->ctx, &qb, 1, off);
            fc->st->tiles_queried++;
        }
    }
}

/* Step 2 then 3: render a visible node (condition: its unread query, when
 * it is drawn on last frame's word), then query its neighbours. */
static void visit(struct frame_ctx *fc, struct tw_cell cell, uint32_t level, uint32_t condition)
{
    struct tw_tilequery *tq = fc->tq;
    float off[3];
    offset_of(fc, cell, off);
    size_t count;
    if (tw_cell_map_set(tq->visible, cell, fc->v->frame) ||
        tw_cull_neighbours_into(fc->v, fc->g, cell, level, tq->s.neighbours, &tq->cells,
                                &tq->cell_cap, &count)) {
        fc->err = TW_ERR_NOMEM;
        return;
    }
    /* The neighbours' tiles are asked for before this one is drawn (which
     * may wait for it): DESIGN §12, prefetch when a neighbour is queried. */
    tw_cull_nodes_in_view_prefetch(fc->v, fc->g, tq->cells, count);
    fc->render(fc->user, cell, level, off, condition);
    fc->st->tiles_visible++;
    query_neighbours(fc, count);
}

/* Step 1: the node holding the camera's cell if its box meets the frustum,
 * else the nearest node of the cut whose box does. */
static bool find_start(struct frame_ctx *fc, struct tw_cell *start, uint32_t *level)
{
    float dist;
    *level = tw_cull_cover(fc->v, fc->g, fc->v->cell, start);
    if (in_view(fc, *start, *level, &dist))
        return true;
    struct tw_tilequery *tq = fc->tq;
    for (;;) {
        const size_t n = tw_cull_nodes_in_view(fc->v, fc->g, tq->cells, tq->cell_cap, NULL);
        if (n == 0)
            return false;
        if (n <= tq->cell_cap) {
            *start = tq->cells[0].cell;
            *level = tq->cells[0].level;
            return true;
        }
        struct tw_cull_cell *c = realloc(tq->cells, sizeof(*c) * n);
        if (!c) {
            fc->err = TW_ERR_NOMEM;
            return false;
        }
        tq->cells = c;
        tq->cell_cap = n;
    }
}

/* Step 4 for one wavefront, the queue's entries [head, end): first what
 * needs no wait (the near-plane rule; a cell visible last frame whose
 * answer is not in yet, postponed), then the answers of the others, read in
 * issue order (the first wait covers the rest: they were flushed together),
 * then the visible cells rendered in issue order. Their neighbours' queries
 * form the next wavefront. */
static void run_front(struct frame_ctx *fc, uint32_t end)
{
    struct tw_tilequery *tq = fc->tq;
    const struct tw_query_backend *be = fc->be;
    const uint32_t first = tq->head;
    tq->head = end;
    for (uint32_t k = first; k < end; k++) {
        struct pending *p = &tq->queue[k];
        p->visible = false;
        p->postponed = false;
        if (p->query == 0) {
            p->visible = true;
        } else if (p->predicted && !be->ready(be->ctx, p->query)) {
            /* Trust last frame: render now, read the answer at the end. */
            if (tw_array_reserve_u32((void **)&tq->postponed, &tq->postponed_cap,
                                     tq->postponed_count + 1, sizeof(*tq->postponed), 64)) {
                fc->err = TW_ERR_NOMEM;
                return;
            }
            tq->postponed[tq->postponed_count++] = *p;
            fc->st->postponed++;
            p->visible = true;
            p->postponed = true;
        }
    }
    for (uint32_t k = first; k < end; k++) {
        struct pending *p = &tq->queue[k];
        if (p->visible)
            continue;
        fc->st->waits++;
        p->visible = be->wait(be->ctx, p->query) > tq->s.threshold;
        if (p->visible != p->predicted && p->known)
            fc->st->predict_fail++;
    }
    for (uint32_t k = first; k < end && fc->err == TW_OK; k++) {
        const struct pending p = tq->queue[k];
        if (p.visible)
            visit(fc, p.cell, p.level, p.postponed ? p.query : 0);
    }
}

int tw_tilequery_frame(struct tw_tilequery *tq, const struct tw_view *v,
                       const struct tw_query_backend *be, const struct tw_cull_grid *g,
                       tw_tilequery_render_fn render, tw_tilequery_front_fn front, void *user,
                       struct tw_tilequery_stats *stats)
{
    struct tw_tilequery_stats st = {0};
    struct frame_ctx fc = {.tq = tq, .v = v, .be = be, .g = g, .render = render, .front = front,
                           .user = user, .st = &st, .err = TW_OK};
    const uint32_t levels = tw_cull_grid_hierarchical(g) ? g->levels.count : 1;
    for (uint32_t k = 0; k < levels && k < TW_CULL_MAX_LEVELS; k++)
        fc.box[k] = tw_cull_node_box(g, k);
    const uint64_t f = v->frame;

    /* Last frame's unresolved postponed queries: read and dropped (their
     * cells were already marked invisible for this frame). */
    for (uint32_t k = 0; k < tq->stale_count; k++)
        be->wait(be->ctx, tq->stale[k]);
    tq->stale_count = 0;
    tq->head = tq->tail = 0;
    tq->postponed_count = 0;

    /* Keep the maps to the cells of the last two frames. */
    if (f >= tq->last_prune + 16) {
        tw_cell_map_filter(tq->queried, prune_old, (void *)&f);
        tw_cell_map_filter(tq->visible, prune_old, (void *)&f);
        tq->last_prune = f;
    }

    struct tw_cell start;
    uint32_t start_level;
    tq->last_frame = f;
    tq->last_started = false;
    if (find_start(&fc, &start, &start_level)) {
        tq->last_start = start;
        tq->last_started = true;
        tw_cell_map_set(tq->queried, start, f);
        st.tiles_free++;
        visit(&fc, start, start_level, 0);
    }
    /* Step 4, a wavefront at a time: what the last one drew and issued (its
     * visible cells' tiles, their neighbours' queries, the local method's
     * own queries) goes to the GPU in one flush, then the local method reads
     * what it issued before it and goes on, then the wavefront's answers are
     * read and its visible cells rendered. */
    bool more = true;
    while (fc.err == TW_OK && (tq->head < tq->tail || more)) {
        be->flush(be->ctx);
        st.fronts++;
        more = front && front(user);
        run_front(&fc, tq->tail);
    }
    /* Step 6: postponed queries decide the next frame. */
    for (uint32_t k = 0; k < tq->postponed_count && fc.err == TW_OK; k++) {
        const struct pending *p = &tq->postponed[k];
        if (be->ready(be->ctx, p->query)) {
            if (be->wait(be->ctx, p->query) > tq->s.threshold)
                continue;
            st.predict_fail++;
        } else {
            if (tw_array_reserve_u32((void **)&tq->stale, &tq->stale_cap, tq->stale_count + 1,
                                     sizeof(*tq->stale), 64)) {
                fc.err = TW_ERR_NOMEM;
                break;
            }
            tq->stale[tq->stale_count++] = p->query;
        }
        /* Invisible next frame: it will be queried and waited on before it is drawn. */
        tw_cell_map_set(tq->visible, p->cell, 0);
    }
    if (stats)
        *stats = st;
    return fc.err;
}

void tw_tilequery_last_cells(const struct tw_tilequery *tq, tw_tilequery_cell_fn fn, void *user)
{
    if (!tq || !fn)
        return;
    if (tq->last_started)
        fn(user, tq->last_start, TW_TILEQUERY_CELL_START);
    /* The pending queue is reset only when the next frame starts, so [0,
     * tail) still holds every cell queued in the last one. A postponed cell
     * may have been marked invisible for the next frame already, so the
     * postponed queue is asked first; the others were waited on, and the
     * visible map holds their verdict. */
    for (uint32_t k = 0; k < tq->tail; k++) {
        const struct pending *p = &tq->queue[k];
        enum tw_tilequery_cell_state state;
        if (p->query == 0) {
            state = TW_TILEQUERY_CELL_FREE;
        } else {
            bool postponed = false;
            for (uint32_t q = 0; q < tq->postponed_count && !postponed; q++)
                postponed = tq->postponed[q].cell.i == p->cell.i &&
                            tq->postponed[q].cell.j == p->cell.j;
            if (postponed) {
                state = TW_TILEQUERY_CELL_POSTPONED;
            } else {
                state = tw_tilequery_was_visible(tq, p->cell, tq->last_frame)
                            ? TW_TILEQUERY_CELL_VISIBLE
                            : TW_TILEQUERY_CELL_OCCLUDED;
            }
        }
        fn(user, p->cell, state);
    }
}
