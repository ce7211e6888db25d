/*
 * cull's insides shared by its files (cull.h is the module's contract with
 * runtime/): the growth of scratch arrays, the front-to-back order of cells
 * and a binary min-heap of (distance, index) entries in caller storage, for
 * traversals nearest first; the engines the methods are made of (CHC++, the
 * depth pyramid and its traversals, tile-query propagation); and the methods
 * behind struct tw_cull_driver, one file and one ops table each. Private to
 * cull/ and its unit tests.
 */
#ifndef TW_CULL_PRIVATE_H
#define TW_CULL_PRIVATE_H

#include <assert.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "cull/cull.h"
#include "tiles/array.h"

/* Grows *p to hold at least need elements of size elem (tiles/array.h's
 * doubling, from 64); the new elements are zeroed. False when out of memory
 * (*p unchanged). */
static inline bool tw_cull_reserve(void **p, size_t *cap, size_t need, size_t elem)
{
    const size_t old = *cap;
    if (tw_array_reserve(p, cap, need, elem, 64) != TW_OK)
        return false;
    if (*cap > old)
        memset((char *)*p + old * elem, 0, (*cap - old) * elem);
    return true;
}

/* Front to back: by distance, ties by cell (i, then j); < 0, 0 or > 0. */
static inline int tw_cull_cell_order(const struct tw_cull_cell *x, const struct tw_cull_cell *y)
{
    if (x->distance != y->distance)
        return x->distance < y->distance ? -1 : 1;
    if (x->cell.i != y->cell.i)
        return x->cell.i < y->cell.i ? -1 : 1;
    return (x->cell.j > y->cell.j) - (x->cell.j < y->cell.j);
}

/* One entry of a distance heap: what (an index of the caller's) and how far. */
struct tw_distance_entry {
    float distance;
    uint32_t index;
};

/* Nearest first, ties by index: a total order, so traversals are
 * deterministic. */
static inline int tw_distance_less(const struct tw_distance_entry *a,
                                   const struct tw_distance_entry *b)
{
    if (a->distance != b->distance)
        return a->distance < b->distance;
    return a->index < b->index;
}

/* Pushes onto heap[0, *count); the caller has made room (*count < cap). */
static inline void tw_distance_push(struct tw_distance_entry *heap, size_t *count,
                                    float distance, uint32_t index)
{
    const struct tw_distance_entry e = {distance, index};
    size_t i = (*count)++;
    while (i > 0) {
        const size_t parent = (i - 1) / 2;
        if (!tw_distance_less(&e, &heap[parent]))
            break;
        heap[i] = heap[parent];
        i = parent;
    }
    heap[i] = e;
}

/* Pops the nearest entry's index off a non-empty heap. */
static inline uint32_t tw_distance_pop(struct tw_distance_entry *heap, size_t *count)
{
    assert(*count > 0);
    const uint32_t top = heap[0].index;
    const struct tw_distance_entry last = heap[--*count];
    const size_t n = *count;
    size_t i = 0;
    for (;;) {
        size_t c = 2 * i + 1;
        if (c >= n)
            break;
        if (c + 1 < n && tw_distance_less(&heap[c + 1], &heap[c]))
            c++;
        if (!tw_distance_less(&heap[c], &last))
            break;
        heap[i] = heap[c];
        i = c;
    }
    if (n > 0)
        heap[i] = last;
    return top;
}

/* ---- one tile instance, as a local method traverses it ------------------------ */

/* A cell's tile instance placed for one traversal: its tile, where it lies
 * and the per-node state that the local method keeps in the tile cache. */
struct tw_cull_instance {
    struct tw_cell cell;
    uint32_t level;                     /* of the node whose base is cell (0: a cell) */
    uint32_t content;                   /* handed to be->draw */
    const struct tw_prototype *proto;
    const struct tw_bvh *bvh;
    void *state;                        /* bvh->node_count entries of the method's node
                                           state: struct tw_chc_node_state (CHC++),
                                           struct tw_hzb_node_state (HZB) */
    float offset[3];                    /* view-relative placement of the tile */
    uint64_t tag;                       /* the caller's name for this tile instance (a
                                           tile-cache handle), given back with CHC++'s
                                           deferred V-query results */
};

/* ---- CHC++ inside one tile (DESIGN §7) --------------------------------------- */

/* Per-view state of one tile instance: one entry per BVH node. Lives in the
 * tile cache (its bytes are the instance's cost), zeroed by the cache. */
struct tw_chc_node_state {
    uint64_t visible_frame;     /* last frame found visible (0: never) */
    uint64_t next_query_frame;  /* a visible leaf is re-queried from this frame on */
    uint32_t invisible_frames;  /* frames in a row found invisible */
    uint32_t pending_query;     /* non-zero while a query on this node is in flight */
};

/* Bytes of per-node state a tile instance with this BVH needs. */
size_t tw_chc_state_bytes(const struct tw_bvh *bvh);

/* Initialises state for a tile seen for the first time at frame: every node
 * visible in the previous frame and due for a query, so that the first
 * traversal draws everything in the frustum and queries the leaves once
 * (no query round trip per level). */
void tw_chc_state_init(struct tw_chc_node_state *state, const struct tw_bvh *bvh,
                       uint64_t frame);

/* Counters of the current frame, summed over tiles. */
struct tw_chc_stats {
    uint32_t queries;           /* occlusion queries issued */
    uint32_t multiqueries;      /* of which covering more than one node */
    uint32_t nodes_queried;
    uint32_t requeries;         /* single queries re-issued after a failed multiquery */
    uint32_t clusters_drawn;
    uint32_t waits;             /* blocking waits */
    uint32_t queries_skipped;   /* queries the cost model found not worth issuing: a
                                   previously hidden node drawn without a query (cheaper
                                   than a query weighted by the chance that it is hidden),
                                   or a visible leaf's re-query that could not pay */
    uint32_t suspended;         /* passes suspended rather than blocked (tw_chc_traverse_async) */
};

/* The CHC++ traversal engine: queues and scratch space, reused every frame
 * (no allocation per frame once warm). Holds queries across frames. */
struct tw_chc;

int tw_chc_create(const struct tw_chc_settings *settings, struct tw_chc **out);
/* Frees the engine; queries still in flight are abandoned without reading
 * (the caller destroys the backend's context afterwards). Accepts NULL. */
void tw_chc_destroy(struct tw_chc *chc);

/* Resolves the tile state of a deferred V-query: returns the state array of
 * the tile instance named by tag, or NULL if it no longer exists. */
typedef struct tw_chc_node_state *(*tw_chc_resolve_fn)(void *user, uint64_t tag,
                                                       const struct tw_bvh **bvh);

/* Starts frame v->frame: reads the V-queries left in flight at the end of the
 * previous frame and applies them as that frame's results. */
void tw_chc_begin_frame(struct tw_chc *chc, const struct tw_view *v,
                        const struct tw_query_backend *be,
                        tw_chc_resolve_fn resolve, void *resolve_user);

/* Runs CHC++ over one tile to completion: everything found visible is drawn
 * through be->draw, front to back, before it returns; V-queries still in
 * flight are kept for tw_chc_begin_frame() of the next frame. */
void tw_chc_traverse(struct tw_chc *chc, const struct tw_view *v,
                     const struct tw_query_backend *be,
                     const struct tw_cull_instance *tile);

/* The same, except that where the pass would block on an I-query with
 * nothing left to traverse it is suspended instead (up to
 * settings.suspended_passes at a time, the oldest finished when one more
 * would start), so that the GPU gets the next tiles' work rather than
 * waiting: with more than one, a frame's blocking reads are then those of
 * its last tiles, but a farther tile's queries may be answered before a
 * nearer tile has drawn what would hide them (more overdraw); with one, the
 * next tile's pass starts only when the last one is done, and what runs in
 * between (the tile queries) overlaps the wait. A suspended pass is resumed by later calls and
 * finished by tw_chc_finish(), which the caller must call before the frame
 * ends and before tile, its BVH or its state may change or go. Tiles then
 * draw out of front-to-back order where a pass waits; conservative all the
 * same (a query counts what is drawn before it, and more drawn can only
 * hide more). */
void tw_chc_traverse_async(struct tw_chc *chc, const struct tw_view *v,
                           const struct tw_query_backend *be,
                           const struct tw_cull_instance *tile);
/* Runs every suspended pass to its end, oldest first. */
void tw_chc_finish(struct tw_chc *chc);

/* Wavefront mode (off by default), for a caller that flushes once per
 * wavefront of its own (tile-query propagation): tw_chc_traverse_async()
 * suspends any number of passes, never resumes one itself, and no pass
 * flushes; a pass that would wait on a query issued since the caller's
 * last flush is suspended instead. */
void tw_chc_set_wavefront(struct tw_chc *chc, bool on);
/* Wavefront mode: the caller has just flushed, so everything issued so far
 * is on its way. Resumes every suspended pass, oldest first, each until it
 * would wait on something issued after that flush (a wait before that is
 * one of the wavefront's batched reads). Returns whether a pass is still
 * suspended. */
bool tw_chc_resume_flushed(struct tw_chc *chc);

/* This frame's counters (reset by tw_chc_begin_frame). */
const struct tw_chc_stats *tw_chc_stats(const struct tw_chc *chc);

/* The costs the next traversals decide with (copied; NULL or a zeroed
 * model: none, every query one unit). With a model:
 *   - a previously invisible node whose drawing costs less than its query
 *     weighted by the chance p(i) that it stays hidden (p C_draw < C_query,
 *     pixels left out: a hidden node's pixels are tested either way) is
 *     drawn without a query (a leaf) or opened (an interior node: its
 *     children decide for themselves); it is not marked visible, as
 *     nothing was learnt, so that its parent can still be found hidden and
 *     be culled whole by one query;
 *   - a visible leaf due for a re-query is re-queried only when that can
 *     pay: when n_av + 1 frames of drawing its parent's subtree (which a
 *     hidden answer may let be culled whole), weighted by the measured
 *     chance that a re-query finds its leaf hidden (over about the last
 *     thousand answers, from a prior of one half), cost more than the
 *     query; else it stays visible, due again in n_av frames, except one
 *     in sixteen, issued all the same so that the chance stays measured;
 *   - multiquery groups grow while the cost they save, in milliseconds,
 *     does not fall behind what they cost.
 * Both decisions only ever draw more: never one that hides a node. */
void tw_chc_set_costs(struct tw_chc *chc, const struct tw_cost_model *costs);

/* Heap bytes held by the engine. */
size_t tw_chc_bytes(const struct tw_chc *chc);

/* ---- HZB: a hierarchical depth buffer (DESIGN §6, after Greene, Kass, Miller 1993) -- */

/* The depth pyramid of one frame and the per-tile traversals of the two
 * HZB methods. Level 0 is the depth buffer as read back (width x height);
 * level k + 1 is ceil(w_k / 2) x ceil(h_k / 2), each texel the *farthest*
 * depth of the up to 2 x 2 texels of level k it covers (at an odd edge
 * only the texels that exist), so that texel (x, y) of level k bounds the
 * depth of every pixel in [x 2^k, (x + 1) 2^k) x [y 2^k, (y + 1) 2^k)
 * clipped to the buffer. A box is hidden when the *nearest* depth of its
 * query box (tw_cull_query_box: the margin of a hardware query) lies
 * farther than the farthest depth of every texel that its screen
 * rectangle, rounded outwards by a pixel, touches, tested at the finest
 * level where that rectangle spans at most TW_HZB_SPAN texels along each
 * axis. A box that reaches the near plane is never hidden. Scratch space
 * is kept across frames: no allocation per frame once warm. */
struct tw_hzb;

#define TW_HZB_SPAN 8

int tw_hzb_create(struct tw_hzb **out);
/* Accepts NULL. */
void tw_hzb_destroy(struct tw_hzb *h);

/* Room for a width x height depth buffer (level 0), to be filled by the
 * caller, bottom row first, then turned into a pyramid by tw_hzb_build().
 * Returns NULL when out of memory or for a zero size. The pyramid reads as
 * empty (every box visible) until tw_hzb_build(). The buffer belongs to h
 * and lives until the next call or tw_hzb_destroy(). */
float *tw_hzb_depth_buffer(struct tw_hzb *h, uint32_t width, uint32_t height);
/* Builds the pyramid over the buffer's window depths; reversed: near = 1,
 * far = 0 (float depth with glClipControl), else near = 0, far = 1. The
 * buffer's contents are used up (it becomes level 0). */
void tw_hzb_build(struct tw_hzb *h, bool reversed);
/* No pyramid: every box reads as visible until the next build. */
void tw_hzb_clear(struct tw_hzb *h);
/* True if the pyramid holds a built depth buffer. */
bool tw_hzb_built(const struct tw_hzb *h);
/* Levels of the built pyramid (0 when none). */
uint32_t tw_hzb_levels(const struct tw_hzb *h);

/* False only if box b moved by offset (view-relative) is certainly hidden
 * behind the depth the pyramid was built from, seen with view v (whose
 * viewport is the depth buffer's size, and whose matrices match the depth
 * convention: view_proj_rz for reversed depth, view_proj else). */
bool tw_hzb_visible(const struct tw_hzb *h, const struct tw_view *v, const struct tw_box *b,
                    const float offset[3]);

/* Testing only: every tested box shrunk by this fraction of its size about
 * its centre before the test (a deliberately broken culler that the
 * accuracy checks must catch); 0 (the default) tests boxes as they are. */
void tw_hzb_set_mutation(struct tw_hzb *h, float shrink_fraction);

/* Per-view state of one tile instance: one entry per BVH node. Lives in the
 * tile cache, zeroed by the cache (0: never visible, never drawn). */
struct tw_hzb_node_state {
    uint64_t visible_frame;     /* last frame found visible: a leaf whose box passed, and
                                   its ancestors (0: never) */
    uint64_t drawn_frame;       /* leaf: last frame its clusters were drawn */
};

/* Bytes of per-node state a tile instance with this BVH needs. */
size_t tw_hzb_state_bytes(const struct tw_bvh *bvh);

/* Counters since tw_hzb_begin_frame(), summed over tiles. */
struct tw_hzb_stats {
    uint32_t boxes_tested;      /* node boxes tested against the pyramid */
    uint32_t boxes_hidden;      /* of which found hidden (their subtrees skipped) */
    uint32_t clusters_drawn;
};

/* Starts a frame: resets the counters. */
void tw_hzb_begin_frame(struct tw_hzb *h);
const struct tw_hzb_stats *tw_hzb_stats(const struct tw_hzb *h);

/* Phase 1 of frame v->frame: draws, front to back in one call of be->draw,
 * the clusters of the tile's leaves found visible in frame v->frame - 1
 * that lie in the frustum within the view distance, and marks them drawn
 * in this frame. Returns how many clusters were drawn. */
uint32_t tw_hzb_draw_last_visible(struct tw_hzb *h, const struct tw_view *v,
                                  const struct tw_query_backend *be,
                                  const struct tw_cull_instance *t);
/* Phase 2: traverses the tile's BVH front to back from the root, testing
 * each node in the frustum within the view distance against the pyramid
 * and skipping the subtrees of hidden ones; a visible leaf is marked
 * visible in this frame (with its ancestors) and, unless phase 1 drew it,
 * drawn (one call of be->draw). Returns how many clusters it drew. */
uint32_t tw_hzb_traverse(struct tw_hzb *h, const struct tw_view *v,
                         const struct tw_query_backend *be, const struct tw_cull_instance *t);

/* After phase 2, with the pyramid rebuilt from the frame's final depth:
 * decides again which of the tile's leaves drawn in this frame are visible
 * (their boxes tested against it, front to back, hidden subtrees skipped),
 * so that the next frame's phase 1 draws those only. Returns whether a node
 * of the tile is still visible. */
bool tw_hzb_retest(struct tw_hzb *h, const struct tw_view *v, const struct tw_cull_instance *t);

/* Heap bytes held: the pyramid and the scratch space. */
size_t tw_hzb_bytes(const struct tw_hzb *h);

/* ---- tile-query propagation (DESIGN §4) ------------------------------------------- */

/* Counters of one frame. */
struct tw_tilequery_stats {
    uint32_t tiles_queried;     /* cells whose common box was queried */
    uint32_t tiles_visible;     /* cells rendered */
    uint32_t tiles_free;        /* cells found visible without a query (near-plane rule, start) */
    uint32_t postponed;         /* cells rendered on last frame's word, result pending */
    uint32_t predict_fail;      /* predictions that a read result contradicted: visible last
                                   frame and found hidden, or considered last frame, found
                                   hidden then, and visible now; a cell with no verdict in
                                   the previous frame has no prediction to fail */
    uint32_t waits;             /* waits on tile queries (reads of a wavefront's answers) */
    uint32_t fronts;            /* wavefronts: the GPU was flushed once for each */
};

/* Renders the tile of node (cell, level; level 0: the cell's), placed at
 * offset (view-relative), with the local method, before its neighbours are
 * queried. condition: 0, or the node's own query, issued and not read yet,
 * when it is drawn on last frame's word (postponed): a local method may
 * draw under it (be->draw_if), the GPU skipping what it finds hidden; the
 * engine reads it. */
typedef void (*tw_tilequery_render_fn)(void *user, struct tw_cell cell, uint32_t level,
                                       const float offset[3], uint32_t condition);

/* Called once per wavefront, right after its flush: everything drawn and
 * issued so far has gone to the GPU, so the local method may now read what
 * it issued before (a wait there is covered by the same flush) and go on,
 * issuing more, without a flush of its own. Returns whether it still has
 * work waiting on the GPU (then one more wavefront follows even when no
 * tile query is left). */
typedef bool (*tw_tilequery_front_fn)(void *user);

int tw_tilequery_create(const struct tw_tilequery_settings *s, struct tw_tilequery **out);
/* Accepts NULL. Queries still in flight are abandoned unread. */
void tw_tilequery_destroy(struct tw_tilequery *tq);

/* Runs one frame (v->frame, increasing by one each call): spreads visibility
 * from the camera across grid g (its footprint; its hierarchy's cut, where
 * it has one: a node stands for its cells), front to back, querying the
 * node box (tw_cull_node_box; a cell's: the common box) placed at each
 * candidate, and calls render for every node found visible. It goes a
 * wavefront at a time: the nodes rendered in one wavefront have their
 * neighbours (tw_cull_node_neighbours) queried, then be->flush() is called
 * once (the only flush it makes), front (may be NULL) is called, and the
 * wavefront's answers are read; the visible nodes are the next wavefront's
 * to render. Before a visible node is rendered, g->source.prefetch (where
 * there is one) is asked for its neighbours in view. */
int tw_tilequery_frame(struct tw_tilequery *tq, const struct tw_view *v,
                       const struct tw_query_backend *be, const struct tw_cull_grid *g,
                       tw_tilequery_render_fn render, tw_tilequery_front_fn front, void *user,
                       struct tw_tilequery_stats *stats);

/* The neighbours of node (base, level) in the frame's cut
 * (tw_cull_node_neighbours) into *buf, grown as needed (*cap elements):
 * their number in *count. TW_ERR_NOMEM when it cannot grow. */
int tw_cull_neighbours_into(const struct tw_view *v, const struct tw_cull_grid *g,
                            struct tw_cell base, uint32_t level, uint32_t neighbours,
                            struct tw_cull_cell **buf, size_t *cap, size_t *count);

/* Sets the distance of each of nodes[0, n): the eye's to its node's box
 * when that box meets the frustum within the view distance, else
 * INFINITY; and, where g's tile source has a prefetch, asks it for the
 * tiles of those in view. */
void tw_cull_nodes_in_view_prefetch(const struct tw_view *v, const struct tw_cull_grid *g,
                                    struct tw_cull_cell *nodes, size_t n);

/* True if cell was found visible in frame (only the last two frames are kept). */
bool tw_tilequery_was_visible(const struct tw_tilequery *tq, struct tw_cell cell, uint64_t frame);

/* Heap bytes held. */
size_t tw_tilequery_bytes(const struct tw_tilequery *tq);

/* ---- the methods behind struct tw_cull_driver ------------------------------------- */

/* One frame of a driver as its method runs it: what the frame is of, what
 * the driver keeps for every method, and the counters the method fills. */
struct tw_cull_frame {
    const struct tw_view *v;
    const struct tw_cull_grid *g;
    const struct tw_query_backend *be;
    struct tw_cull_cells *cells;        /* the frame's cells in view, enumerated when
                                           asked for (tw_cull_cells_of_frame) */
    struct tw_tile_cache *cache;        /* the driver's tile instances; NULL for a method
                                           without (tw_cull_method_ops.tile_instances) */
    unsigned source_flags;              /* passed to every g->source.get() */
    struct tw_cull_frame_stats *st;     /* zeroed before the frame */
    int err;                            /* the first error: the frame stops at it */
};

/* Room for need elements of size elem in *array (tw_cull_reserve); out of
 * memory becomes the frame's error. */
bool tw_cull_frame_reserve(struct tw_cull_frame *fr, void **array, size_t *cap, size_t need,
                           size_t elem);

/* Cluster indices of one tile, their room kept from frame to frame. */
struct tw_cull_clusters {
    uint32_t *index;
    size_t cap;
};
/* Room for n indices in c; NULL when out of memory (the frame's error). */
uint32_t *tw_cull_frame_clusters(struct tw_cull_frame *fr, struct tw_cull_clusters *c, size_t n);

/* Fills *tile with the tile at cell (distance: eye to the cell's common
 * box) and returns true when it is ready and not empty. A tile not ready is
 * counted in st->tiles_pending; an error becomes the frame's. */
bool tw_cull_frame_tile(struct tw_cull_frame *fr, struct tw_cell cell, uint32_t level,
                        float distance, struct tw_cull_tile *tile);

/* The eye's distance to the common box placed at cell (what
 * tw_tile_source.get() is given). */
float tw_cull_frame_cell_distance(const struct tw_cull_frame *fr, struct tw_cell cell,
                                  uint32_t level);

/* True if the common box placed at cell (at off, which this fills, with
 * the eye's distance to it in *distance) meets the frustum within the view
 * distance. */
bool tw_cull_frame_cell_in_view(const struct tw_cull_frame *fr, struct tw_cell cell,
                                uint32_t level, float off[3], float *distance);

/* The tile instance of a cell found visible, from fr->cache: made on first
 * sight (and afresh for content other than its own) with state_bytes of
 * zeroed node state and counted in st->tiles_new, then marked visible in
 * this frame. Fills *inst with tile placed at offset, tagged with the
 * instance's handle, and *created with whether it was made now. Returns
 * inst->state: NULL on an error (the frame's) or when it has no state. */
void *tw_cull_frame_instance(struct tw_cull_frame *fr, struct tw_cell cell,
                             const struct tw_cull_tile *tile, const float offset[3],
                             size_t state_bytes, struct tw_cull_instance *inst, bool *created);

/* What every method has (enum tw_cull_method holds the plain name: C's struct
 * and enum tags share one namespace). Each method's file embeds it first in
 * its own struct, with impl pointing at the file's static const table. */
struct tw_cull_method_base {
    const struct tw_cull_method_ops *impl;
};

/* Draws the tile of cell (ready, placed at offset) with a method's local
 * method; returns whether it drew anything. */
typedef bool (*tw_cull_draw_fn)(struct tw_cull_method_base *m, struct tw_cull_frame *fr,
                                struct tw_cell cell, const struct tw_cull_tile *tile,
                                const float offset[3]);

/* Every cell in view, front to back, its tile drawn by draw where it is
 * ready; the tiles that draw drew something in are counted in
 * st->tiles_visible. Returns the frame's error. */
int tw_cull_frame_each_cell(struct tw_cull_method_base *m, struct tw_cull_frame *fr,
                            tw_cull_draw_fn draw);

struct tw_cull_method_ops {
    /* Frees m and what it holds; queries in flight are abandoned unread. */
    void (*destroy)(struct tw_cull_method_base *m);
    /* Runs one frame: everything found visible is drawn through fr->be
     * before it returns. Returns the frame's error. */
    int (*frame)(struct tw_cull_method_base *m, struct tw_cull_frame *fr);
    /* Heap bytes held by m, its own struct included (the tile cache is the
     * driver's). */
    size_t (*bytes)(const struct tw_cull_method_base *m);
    /* May be NULL: the costs CHC++ decides with (tw_cull_driver_set_costs). */
    void (*set_costs)(struct tw_cull_method_base *m, const struct tw_cost_model *costs);
    /* May be NULL: the set the next frame draws (tw_cull_driver_give). */
    void (*give)(struct tw_cull_method_base *m, const struct tw_drawn_cluster *set, size_t count);
    /* May be NULL: the propagation engine (tw_cull_driver_tilequery). */
    const struct tw_tilequery *(*tilequery)(const struct tw_cull_method_base *m);
    bool tile_instances;                /* keeps per-view state in tile instances: the
                                           driver keeps a tile cache for it */
};

/* The methods of enum tw_cull_method, one constructor and one file each
 * (method-*.c); s has its defaults filled in. */
int tw_cull_vfc_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out);
int tw_cull_chc_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out);
int tw_cull_tilequery_method_create(const struct tw_cull_driver_settings *s,
                                    struct tw_cull_method_base **out);
int tw_cull_tilequery_chc_method_create(const struct tw_cull_driver_settings *s,
                                        struct tw_cull_method_base **out);
int tw_cull_tilequery_hzb_method_create(const struct tw_cull_driver_settings *s,
                                        struct tw_cull_method_base **out);
int tw_cull_hzb_method_create(const struct tw_cull_driver_settings *s,
                              struct tw_cull_method_base **out);
int tw_cull_given_method_create(const struct tw_cull_driver_settings *s,
                                struct tw_cull_method_base **out);

/* vfc as a local method (method-vfc.c): the tile's clusters in the frustum
 * within the view distance, in one call of be->draw, their indices put in
 * c. Returns whether anything was drawn. */
bool tw_cull_vfc_draw(struct tw_cull_frame *fr, struct tw_cull_clusters *c, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3]);

/* CHC++ as a local method (method-chc.c), with engine chc. Starts a frame:
 * the V-queries the last one left in flight are read and applied to the
 * tile instances that still show what they were made for. */
void tw_cull_chc_begin(struct tw_chc *chc, struct tw_cull_frame *fr);
/* CHC++ over the cell's tile instance (made and initialised on first
 * sight). With async the pass may be suspended where it would block
 * (tw_chc_traverse_async), and what it draws later is not counted. Returns
 * whether anything was drawn. */
bool tw_cull_chc_draw(struct tw_chc *chc, struct tw_cull_frame *fr, struct tw_cell cell,
                      const struct tw_cull_tile *tile, const float offset[3], bool async);
/* Ends a frame: the suspended passes run to their end, and the queries the
 * cost model skipped are counted in st->queries_skipped. */
void tw_cull_chc_end(struct tw_chc *chc, struct tw_cull_frame *fr);

/* The two phases of the HZB methods (method-hzb.c), hzb's and
 * tilequery+hzb's alike:
 *
 *   phase 1  the tiles found visible last frame, front to back: their
 *            clusters found visible last frame, in the frustum
 *   pyramid  depth read back, depth pyramid built (cull/hzb.c)
 *   phase 2  the method's own choice of cells, each decided by its common
 *            box against the pyramid (tw_hzb_phases_decide); a visible
 *            cell's BVH is traversed testing node boxes, drawing what
 *            phase 1 did not (tw_hzb_phases_visit)
 *   end      when phase 2 drew more than phase 1, a second pyramid from the
 *            frame's final depth decides again what the next phase 1 draws
 *
 * Kept across frames: the pyramid and its traversals, the cells with a node
 * visible last frame and this frame's, the latest verdict on every cell
 * decided lately. Zero-initialise, then tw_hzb_phases_init(). */
struct tw_hzb_gpu_candidate;
#define TW_HZB_GPU_LISTS 4
struct tw_hzb_phases {
    struct tw_hzb *hzb;
    struct tw_cull_cell *last, *next;   /* cells with a visible node: last frame's
                                           (phase 1 draws them), this frame's */
    size_t last_count, last_cap, next_count, next_cap;
    struct tw_cell_map *verdict;        /* cell -> frame << 4 | what that frame learnt */
    uint64_t last_prune;
    /* On the GPU (the backend's gpu_hzb_* operations, DESIGN §6): phase 2's
     * tests are the GPU's, their answers arrive a frame or more later. */
    bool gpu;                           /* this frame's phase 2 is the GPU's */
    float shrink;                       /* testing only: tw_hzb_set_mutation() */
    uint64_t known;                     /* the latest frame whose answers were applied */
    struct tw_cell_map *gpu_verdict;    /* cell -> its common box passed (1) or not (0) in
                                           the latest answers (frame known) */
    struct tw_hzb_gpu_list {
        uint64_t frame;                 /* 0: free */
        struct tw_hzb_gpu_candidate *items;
        size_t count, cap;
    } lists[TW_HZB_GPU_LISTS];          /* the candidates of frames in flight */
    uint32_t *stack;                    /* a traversal's nodes */
    size_t stack_cap;
    uint32_t *render;                   /* phase 1's clusters of one tile */
    size_t render_count, render_cap;
    struct tw_cull_cell *near;          /* a node's neighbours (gpu_take) */
    size_t near_cap;
};

int tw_hzb_phases_init(struct tw_hzb_phases *p, float mutate_shrink);
/* Accepts a zeroed or half-initialised p. */
void tw_hzb_phases_finish(struct tw_hzb_phases *p);
size_t tw_hzb_phases_bytes(const struct tw_hzb_phases *p);
/* Phase 1 and the pyramid of its depth; returns how many clusters phase 1
 * drew. */
uint32_t tw_hzb_phases_begin(struct tw_hzb_phases *p, struct tw_cull_frame *fr);
/* Phase 2's verdict on a node of the cut in view (cell, level; a cell:
 * level 0), placed at off: visible without a test (free_pass: where
 * propagation starts, the near-plane rule) or as its box tests against the
 * pyramid. Counts a failed prediction and records the verdict; *prev
 * receives what phase 1 recorded of the node. */
bool tw_hzb_phases_decide(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                          uint32_t level, const float off[3], bool free_pass, uint64_t *prev);
/* Phase 2 in a visible node: its tile's BVH against the pyramid, drawing
 * what phase 1 did not (prev: what phase 1 recorded); the node is kept for
 * the next frame's phase 1 if a BVH node of it was found visible. */
void tw_hzb_phases_visit(struct tw_hzb_phases *p, struct tw_cull_frame *fr, struct tw_cell cell,
                         uint32_t level, float distance, const float off[3], uint64_t prev);
/* What this frame has recorded of cell so far (0: nothing), for
 * tw_hzb_phases_visit(). */
uint64_t tw_hzb_phases_verdict(const struct tw_hzb_phases *p, struct tw_cell cell);
/* True if phase 2 has decided on cell in this frame already. */
bool tw_hzb_phases_reached(const struct tw_hzb_phases *p, const struct tw_cull_frame *fr,
                           struct tw_cell cell);
/* After phase 2 (phase1: what tw_hzb_phases_begin() returned): the second
 * pyramid where it is worth one, and this frame's visible cells become the
 * next one's phase 1. Returns the frame's error. */
int tw_hzb_phases_end(struct tw_hzb_phases *p, struct tw_cull_frame *fr, uint32_t phase1);

#endif
