/* Debug views of the world (runtime.h "debugging and the viewer"): cells by
 * tile-query state, BVH nodes of what was drawn, query boxes; and their
 * drawing over the frame's image. */
#include "runtime/renderer-private.h"
#include "runtime/world-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>

void tw_debug_finish(struct tw_world *w)
{
    struct tw_debug_state *d = &w->debug;
    free(d->leaf_of);
    free(d->marked);
    free(d->boxes);
    free(d->draw);
    tw_cell_map_destroy(d->seen);
    memset(d, 0, sizeof(*d));
}

static const char *const debug_kind_names[TW_DEBUG_KIND_COUNT] = {
    [TW_DEBUG_CELL_START] = "start",
    [TW_DEBUG_CELL_FREE] = "free",
    [TW_DEBUG_CELL_VISIBLE] = "visible",
    [TW_DEBUG_CELL_POSTPONED] = "postponed",
    [TW_DEBUG_CELL_OCCLUDED] = "occluded",
    [TW_DEBUG_CELL_NOT_REACHED] = "not reached",
    [TW_DEBUG_NODE_LEAF] = "leaf",
    [TW_DEBUG_NODE_INNER] = "node",
    [TW_DEBUG_QUERY_VISIBLE] = "query visible",
    [TW_DEBUG_QUERY_HIDDEN] = "query hidden",
    [TW_DEBUG_QUERY_UNREAD] = "query unread",
};

/* Cells after the paper's Figure 6: yellow where propagation starts, light
 * blue visible, dark blue hidden; the states it does not show get colours
 * of their own. */
static const float debug_kind_colors[TW_DEBUG_KIND_COUNT][4] = {
    [TW_DEBUG_CELL_START] = {1.00f, 0.86f, 0.10f, 0.55f},
    [TW_DEBUG_CELL_FREE] = {1.00f, 0.55f, 0.10f, 0.55f},
    [TW_DEBUG_CELL_VISIBLE] = {0.35f, 0.80f, 1.00f, 0.50f},
    [TW_DEBUG_CELL_POSTPONED] = {0.80f, 0.35f, 1.00f, 0.55f},
    [TW_DEBUG_CELL_OCCLUDED] = {0.05f, 0.12f, 0.60f, 0.65f},
    [TW_DEBUG_CELL_NOT_REACHED] = {0.45f, 0.45f, 0.45f, 0.35f},
    [TW_DEBUG_NODE_LEAF] = {0.10f, 0.95f, 0.90f, 0.90f},
    [TW_DEBUG_NODE_INNER] = {1.00f, 0.85f, 0.25f, 0.70f},
    [TW_DEBUG_QUERY_VISIBLE] = {0.55f, 1.00f, 0.15f, 0.95f},
    [TW_DEBUG_QUERY_HIDDEN] = {1.00f, 0.20f, 0.15f, 0.95f},
    [TW_DEBUG_QUERY_UNREAD] = {1.00f, 0.30f, 1.00f, 0.95f},
};

const char *tw_debug_kind_name(enum tw_debug_kind kind)
{
    return (unsigned)kind < TW_DEBUG_KIND_COUNT ? debug_kind_names[kind] : "unknown";
}

void tw_debug_kind_color(enum tw_debug_kind kind, float rgba[4])
{
    if (!rgba)
        return;
    static const float none[4] = {1.0f, 1.0f, 1.0f, 1.0f};
    memcpy(rgba, (unsigned)kind < TW_DEBUG_KIND_COUNT ? debug_kind_colors[kind] : none,
           sizeof(float) * 4);
}

int tw_world_set_debug(struct tw_world *w, unsigned flags)
{
    if (!w || (flags & ~TW_DEBUG_ALL))
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "choose the debug views", false);
    if (err)
        return err;
    if ((flags & TW_DEBUG_CELLS) && !w->debug.seen)
        err = tw_cell_map_create(&w->debug.seen);
    if (!err) {
        w->debug.flags = flags;
        w->debug.count = 0;
        if (!(flags & TW_DEBUG_QUERIES))
            tw_renderer_record_queries(w->renderer, false);
    }
    tw_world_leave(w, false);
    return err;
}

const struct tw_debug_box *tw_world_debug_boxes(const struct tw_world *w, size_t *count)
{
    if (!w || !count) {
        if (count)
            *count = 0;
        return NULL;
    }
    *count = w->debug.count;
    return w->debug.boxes;
}

static struct tw_debug_box *push_debug(struct tw_world *w)
{
    if (tw_array_reserve((void **)&w->debug.boxes, &w->debug.cap, w->debug.count + 1,
                         sizeof(*w->debug.boxes), 1024))
        return NULL;
    struct tw_debug_box *b = &w->debug.boxes[w->debug.count++];
    memset(b, 0, sizeof(*b));
    return b;
}

/* A cell's quad: its footprint inset by half a percent, so that
 * neighbours stay apart and a street on the border still shows both. */
static int push_cell(struct tw_world *w, struct tw_cell cell, enum tw_debug_kind kind)
{
    const float *fp = w->provider.footprint;
    struct tw_debug_box *b = push_debug(w);
    if (!b || tw_cell_map_set(w->debug.seen, cell, 1))
        return TW_ERR_NOMEM;
    b->cell = cell;
    b->box = (struct tw_box){{0.005f * fp[0], 0.3f, 0.005f * fp[1]},
                             {0.995f * fp[0], 0.3f, 0.995f * fp[1]}};
    b->kind = (uint16_t)kind;
    return TW_OK;
}

struct cell_report {
    struct tw_world *w;
    int err;
};

static void report_cell(void *user, struct tw_cell cell, enum tw_tilequery_cell_state state)
{
    static const enum tw_debug_kind kinds[] = {
        [TW_TILEQUERY_CELL_START] = TW_DEBUG_CELL_START,
        [TW_TILEQUERY_CELL_FREE] = TW_DEBUG_CELL_FREE,
        [TW_TILEQUERY_CELL_VISIBLE] = TW_DEBUG_CELL_VISIBLE,
        [TW_TILEQUERY_CELL_OCCLUDED] = TW_DEBUG_CELL_OCCLUDED,
        [TW_TILEQUERY_CELL_POSTPONED] = TW_DEBUG_CELL_POSTPONED,
    };
    struct cell_report *cr = user;
    if (!cr->err && (unsigned)state < sizeof(kinds) / sizeof(kinds[0]))
        cr->err = push_cell(cr->w, cell, kinds[state]);
}

static int collect_cells(struct tw_world *w, const struct method_state *ms, const struct tw_view *v)
{
    struct cell_report cr = {w, TW_OK};
    tw_cell_map_clear(w->debug.seen);
    const struct tw_tilequery *tq = tw_cull_driver_tilequery(ms->driver);
    if (tq) {
        tw_tilequery_last_cells(tq, report_cell, &cr);
    } else {
        size_t n = 0;
        const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
        for (size_t k = 0; k < n && !cr.err; k++)
            if (!tw_cell_map_find(w->debug.seen, d[k].cell))
                cr.err = push_cell(w, d[k].cell, TW_DEBUG_CELL_VISIBLE);
    }
    int err = cr.err ? cr.err : tw_cull_cells_of_frame(&w->cur->cells, v, &w->grid);
    for (size_t k = 0; k < w->cur->cells.count && !err; k++)
        if (!tw_cell_map_find(w->debug.seen, w->cur->cells.cells[k].cell))
            err = push_cell(w, w->cur->cells.cells[k].cell, TW_DEBUG_CELL_NOT_REACHED);
    return err;
}

/* Every node on the way from a drawn cluster's leaf to the root, once per
 * tile (a run of drawn clusters of one cell and content). */
static int collect_nodes(struct tw_world *w)
{
    struct tw_debug_state *dbg = &w->debug;
    size_t n = 0;
    const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
    const struct tw_bvh *bvh = NULL;
    for (size_t k = 0; k < n; k++) {
        if (k == 0 || d[k].cell.i != d[k - 1].cell.i || d[k].cell.j != d[k - 1].cell.j ||
            d[k].prototype != d[k - 1].prototype) {
            /* A new tile: which leaf holds each of its clusters, and no node
             * marked yet. */
            const struct tw_prototype *proto = tw_renderer_content(w->renderer, d[k].prototype, &bvh);
            if (!proto || !bvh)
                return TW_ERR_STATE;
            if (tw_array_reserve((void **)&dbg->leaf_of, &dbg->leaf_cap,
                                 (size_t)proto->cluster_count + 1, sizeof(*dbg->leaf_of), 64) ||
                tw_array_reserve((void **)&dbg->marked, &dbg->marked_cap,
                                 (size_t)bvh->node_count + 1, 1, 64))
                return TW_ERR_NOMEM;
            memset(dbg->marked, 0, bvh->node_count);
            for (uint32_t c = 0; c < proto->cluster_count; c++)
                dbg->leaf_of[c] = TW_BVH_NONE;
            for (uint32_t q = 0; q < bvh->node_count; q++) {
                const struct tw_bvh_node *node = &bvh->nodes[q];
                for (uint32_t c = 0; c < node->cluster_count; c++)
                    dbg->leaf_of[bvh->cluster_order[node->first_cluster + c]] = q;
            }
        }
        uint32_t node = dbg->leaf_of[d[k].cluster];
        while (node != TW_BVH_NONE && !dbg->marked[node]) {
            dbg->marked[node] = 1;
            struct tw_debug_box *b = push_debug(w);
            if (!b)
                return TW_ERR_NOMEM;
            b->cell = d[k].cell;
            b->box = bvh->nodes[node].box;
            b->kind = bvh->nodes[node].cluster_count ? TW_DEBUG_NODE_LEAF : TW_DEBUG_NODE_INNER;
            b->level = (uint16_t)bvh->nodes[node].depth;
            node = bvh->nodes[node].parent;
        }
    }
    return TW_OK;
}

static int collect_queries(struct tw_world *w, const struct tw_view *v)
{
    size_t n = 0;
    const struct tw_renderer_query_box *q = tw_renderer_queries(w->renderer, &n);
    for (size_t k = 0; k < n; k++) {
        struct tw_debug_box *b = push_debug(w);
        if (!b)
            return TW_ERR_NOMEM;
        b->cell = v->cell;
        memcpy(b->box.min, q[k].min, sizeof(b->box.min));
        memcpy(b->box.max, q[k].max, sizeof(b->box.max));
        b->kind = q[k].result > 0    ? TW_DEBUG_QUERY_VISIBLE
                  : q[k].result == 0 ? TW_DEBUG_QUERY_HIDDEN
                                     : TW_DEBUG_QUERY_UNREAD;
        b->level = (uint16_t)(q[k].boxes < UINT16_MAX ? q[k].boxes : UINT16_MAX);
        b->tile_query = q[k].tile;
    }
    return TW_OK;
}

int tw_debug_collect(struct tw_world *w, const struct method_state *ms, const struct tw_view *v)
{
    w->debug.count = 0;
    int err = TW_OK;
    if (w->debug.flags & TW_DEBUG_CELLS)
        err = collect_cells(w, ms, v);
    if (!err && (w->debug.flags & TW_DEBUG_NODES))
        err = collect_nodes(w);
    if (!err && (w->debug.flags & TW_DEBUG_QUERIES))
        err = collect_queries(w, v);
    return err;
}

/* Draws boxes over the frame's image with v's camera, after the frame (not
 * timed, not counted): translucent faces, depth-tested without depth
 * writes, when fill; else edges line_px wide, hidden parts faint. Between
 * the renderer's enter and leave. */
static void draw_boxes(struct tw_renderer *r, const struct tw_view *v,
                       const struct tw_renderer_debug_box *boxes, size_t count, bool fill,
                       float line_px)
{
    if (count == 0)
        return;
    const struct tw_gl *gl = &r->gl;
    const float *view_proj = r->reversed_z ? v->view_proj_rz : v->view_proj;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->Viewport(0, 0, (GLsizei)r->width, (GLsizei)r->height);
    gl->BindVertexArray(r->box_vao);
    r->bound_vao = r->box_vao;
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->DepthMask(GL_FALSE);
    gl->Enable(GL_BLEND);
    gl->BlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    gl->DepthFunc(r->reversed_z ? GL_GEQUAL : GL_LEQUAL);
    if (fill) {
        /* Faces are wound inwards: culling front faces keeps the outside. */
        gl->UseProgram(r->programs.fill.program);
        gl->UniformMatrix4fv(r->programs.fill.view_proj, 1, GL_FALSE, view_proj);
        gl->Enable(GL_CULL_FACE);
        gl->CullFace(GL_FRONT);
        gl->Enable(GL_DEPTH_TEST);
        for (size_t k = 0; k < count; k++) {
            gl->Uniform3fv(r->programs.fill.min, 1, boxes[k].min);
            gl->Uniform3fv(r->programs.fill.max, 1, boxes[k].max);
            gl->Uniform4fv(r->programs.fill.color, 1, boxes[k].color);
            gl->DrawElements(GL_TRIANGLES, 36, GL_UNSIGNED_BYTE, (const void *)0);
        }
    } else {
        gl->UseProgram(r->programs.line.program);
        gl->UniformMatrix4fv(r->programs.line.view_proj, 1, GL_FALSE, view_proj);
        gl->Disable(GL_CULL_FACE);
        /* Hidden edges faint (x-ray), then visible edges at full strength. */
        for (int pass = 0; pass < 2; pass++) {
            if (pass == 0)
                gl->Disable(GL_DEPTH_TEST);
            else
                gl->Enable(GL_DEPTH_TEST);
            const float viewport[3] = {(float)r->width, (float)r->height,
                                       pass == 0 ? line_px * 0.75f : line_px};
            gl->Uniform3fv(r->programs.line.viewport, 1, viewport);
            for (size_t k = 0; k < count; k++) {
                float color[4];
                memcpy(color, boxes[k].color, sizeof(color));
                if (pass == 0)
                    color[3] *= 0.25f;
                gl->Uniform3fv(r->programs.line.min, 1, boxes[k].min);
                gl->Uniform3fv(r->programs.line.max, 1, boxes[k].max);
                gl->Uniform4fv(r->programs.line.color, 1, color);
                gl->DrawElements(GL_LINES, 24, GL_UNSIGNED_BYTE, (const void *)36);
            }
        }
    }
    gl->Disable(GL_BLEND);
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthMask(GL_TRUE);
    gl->CullFace(GL_BACK);
    r->mode = TW_RENDERER_MODE_NONE;
}

int tw_world_draw_debug(struct tw_world *w, const struct tw_debug_box *boxes, size_t count)
{
    if (!w || (count && !boxes))
        return TW_ERR_INVALID;
    if (!w->last->has_view) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot draw the debug view: no frame has been rendered yet");
        return TW_ERR_STATE;
    }
    if (w->s.host.draw) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot draw the debug view: the world draws "
                      "into the host's framebuffer (host rendering) and has no image of its own");
        return TW_ERR_STATE;
    }
    const int err = tw_world_enter(w, "draw the debug view", true);
    if (err)
        return err;
    if (count > w->debug.draw_cap) {
        struct tw_renderer_debug_box *d = realloc(w->debug.draw, sizeof(*d) * count);
        if (!d) {
            tw_world_leave(w, true);
            return TW_ERR_NOMEM;
        }
        w->debug.draw = d;
        w->debug.draw_cap = count;
    }
    const struct tw_view *v = &w->last->last_view;
    const float *fp = w->provider.footprint;
    /* Five layers, one renderer call each: cell quads, inner nodes, leaves,
     * tile queries (wider), node queries. */
    static const struct {
        bool fill;
        float line_px;
    } layers[5] = {{true, 0.0f}, {false, 1.0f}, {false, 1.25f}, {false, 2.5f}, {false, 1.5f}};
    for (int layer = 0; layer < 5; layer++) {
        size_t n = 0;
        for (size_t k = 0; k < count; k++) {
            const struct tw_debug_box *b = &boxes[k];
            int in;
            if (b->kind <= TW_DEBUG_CELL_NOT_REACHED)
                in = 0;
            else if (b->kind == TW_DEBUG_NODE_INNER)
                in = 1;
            else if (b->kind == TW_DEBUG_NODE_LEAF)
                in = 2;
            else if (b->kind < TW_DEBUG_KIND_COUNT)
                in = b->tile_query ? 3 : 4;
            else
                continue;
            if (in != layer)
                continue;
            struct tw_renderer_debug_box *r = &w->debug.draw[n++];
            float offset[3];
            tw_tiles_cell_offset(b->cell, v->cell, fp[0], fp[1], offset);
            for (int a = 0; a < 3; a++) {
                r->min[a] = b->box.min[a] + offset[a];
                r->max[a] = b->box.max[a] + offset[a];
            }
            tw_debug_kind_color((enum tw_debug_kind)b->kind, r->color);
            if (b->kind == TW_DEBUG_NODE_INNER) {
                /* Deeper nodes fainter: the root frames the tile, leaves show detail. */
                r->color[3] *= 1.0f / (1.0f + 0.25f * (float)b->level);
            }
        }
        draw_boxes(w->renderer, v, w->debug.draw, n, layers[layer].fill, layers[layer].line_px);
    }
    tw_world_leave(w, true);
    return TW_OK;
}

