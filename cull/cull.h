/*
 * cull: visibility algorithms with no GL in them (DESIGN.md §4-§7).
 *
 * Coordinates: every position here is *view-relative*: metres from the origin
 * corner of the camera's cell (struct tw_view.cell). A tile at cell c is
 * placed at offset tw_tiles_cell_offset(c, view.cell, W, D); its tile-local
 * boxes are moved by that offset. Nothing here ever sees an absolute world
 * position in float.
 *
 * The GPU is reached only through struct tw_query_backend, so that every
 * algorithm runs against OpenGL (runtime/) and against a deterministic fake
 * in unit tests.
 *
 * This header is what runtime/ sees: the view, the backend, the settings
 * and the method drivers. The engines the methods are made of (CHC++, the
 * depth pyramid, tile-query propagation) are in cull-private.h.
 */
#ifndef TW_CULL_H
#define TW_CULL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "bvh/bvh.h"
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- frusta ---------------------------------------------------------------- */

/* A plane n.p + d = 0; points with n.p + d >= 0 are inside. */
struct tw_plane {
    float n[3];
    float d;
};

/* Left, right, bottom, top, near, far; normals point inwards. */
struct tw_frustum {
    struct tw_plane planes[6];
};

enum tw_cull_test {
    TW_CULL_OUTSIDE = 0,
    TW_CULL_INTERSECT = 1,
    TW_CULL_INSIDE = 2,
};

/* Extracts the frustum of a column-major view-projection matrix (OpenGL clip
 * conventions, -w <= x, y, z <= w), normalising the planes. */
void tw_cull_frustum_from_matrix(const float view_proj[16],
                                 struct tw_frustum *out);

/* Classifies box b moved by offset (NULL for none) against f. Conservative:
 * TW_CULL_OUTSIDE only when the box is certainly outside. */
enum tw_cull_test tw_cull_frustum_box(const struct tw_frustum *f,
                                      const struct tw_box *b,
                                      const float offset[3]);

/* ---- the view of one frame ------------------------------------------------ */

struct tw_view {
    struct tw_cell cell;        /* the camera's cell: origin of view-relative space */
    float eye[3];               /* camera position, view-relative (= its local offset) */
    float view_proj[16];        /* column-major, view-relative world -> clip (GL, z in [-w, w]) */
    float view_proj_rz[16];     /* the same with reversed depth, z in [0, w], near -> w: for a
                                   float depth buffer with glClipControl(ZERO_TO_ONE) */
    float view[16];             /* column-major, view-relative world -> eye space */
    float proj[16];             /* eye -> clip (GL); view_proj = proj * view */
    float proj_rz[16];          /* eye -> clip, reversed depth; view_proj_rz = proj_rz * view */
    struct tw_frustum frustum;
    float near_plane;           /* metres */
    float far_plane;            /* metres */
    float near_radius;          /* eye to the near plane's corners, metres */
    float view_distance;        /* metres; tiles whose box lies farther are not drawn */
    uint64_t frame;             /* frame number, starting at 1 */
};

/* Fills view_proj and frustum from the camera (eye in view-relative space,
 * yaw/pitch in degrees as DESIGN §9 defines them), a vertical field of view
 * in degrees, an aspect ratio, near and far planes. */
void tw_cull_view_setup(struct tw_view *v, struct tw_cell cell,
                        const float eye[3], float yaw_deg, float pitch_deg,
                        float fov_y_deg, float aspect, float near_plane,
                        float far_plane);

/* The box that an occlusion query on box b (moved by offset, view-relative)
 * draws: b grown on every side by TW_CULL_QUERY_MARGIN_M plus
 * TW_CULL_QUERY_MARGIN_PER_M times its distance from eye. A surface lying on
 * its own box's face (a facade is its building's box side) ties with the
 * box in depth, and rounding could then fail the query; the margin grows
 * with distance as the depth error does. */
#define TW_CULL_QUERY_MARGIN_M 0.005f
#define TW_CULL_QUERY_MARGIN_PER_M 2e-5f
struct tw_box tw_cull_query_box(const float eye[3], const struct tw_box *b, const float offset[3]);

/* The distance from the eye within which the near plane may cut a box: to
 * the near plane's corners (at least to the plane itself). */
float tw_cull_near_reach(const struct tw_view *v);

/* True if the camera is inside the query box of b moved by offset
 * (tw_cull_query_box, margin included), or within near-plane distance of
 * it: such a box may be clipped by the near plane, so an occlusion query on
 * it can wrongly return 0 samples (DESIGN §4 step 1). */
bool tw_cull_near_box(const struct tw_view *v, const struct tw_box *b,
                      const float offset[3]);

/* The screen rectangle of box b (moved by offset, NULL: none): lo and hi in
 * normalised device coordinates (x, y; not clipped to [-1, 1]), and the
 * least clip w of its corners (the eye distance along the view axis of the
 * nearest one). False if a corner lies on or before the near plane, or the
 * figures are not finite: the box then has no rectangle. */
bool tw_cull_box_screen_rect(const struct tw_view *v, const struct tw_box *b,
                             const float offset[3], float lo[2], float hi[2], float *w_min);

/* The fraction of the image that the screen rectangle of box b (moved by
 * offset) covers, clipped to the image: at most 1, and 1 for a box reaching
 * the near plane. An upper bound of what drawing the box or the geometry
 * inside it can touch. */
float tw_cull_box_screen_fraction(const struct tw_view *v, const struct tw_box *b,
                                  const float offset[3]);

/* Distance from the eye to the nearest point of box b moved by offset. */
float tw_cull_box_distance(const struct tw_view *v, const struct tw_box *b,
                           const float offset[3]);

/* A cell considered for drawing, with its distance (eye to the nearest
 * point of the common box placed there). With a hierarchy of cells
 * (struct tw_cull_levels), a node of it: the block of 2^level x 2^level
 * cells whose first cell is cell, its distance to the node's box. */
struct tw_cull_cell {
    struct tw_cell cell;
    float distance;
    uint32_t level;
};

/* Every cell whose common box (tile-local, footprint w x d) placed at that
 * cell meets the frustum and lies within the view distance, sorted front to
 * back (by distance, ties by cell). Writes up to cap cells into out and
 * returns how many there are in all (may exceed cap: call again with more
 * room). */
size_t tw_cull_cells_in_view(const struct tw_view *v,
                             const struct tw_box *common_box, float w, float d,
                             struct tw_cull_cell *out, size_t cap);

/* What one cell scan did. */
struct tw_cull_scan {
    uint64_t cells_tested;      /* cells whose common box was tested: at most
                                   TW_TILES_MAX_CELLS_IN_VIEW */
    bool truncated;             /* the cells within reach were more than that: only the
                                   square nearest the camera's cell was tested, farther
                                   ones were left out of the frame */
};

/* tw_cull_cells_in_view(), also saying in *scan (may be NULL) how much it
 * tested and whether it had to stop short. Its cost is bounded whatever the
 * footprint, the common box and the view distance (tiles.h,
 * TW_TILES_MAX_CELLS_IN_VIEW); a footprint, view distance or eye that is
 * not finite and positive gives no cells. */
size_t tw_cull_cells_in_view_scan(const struct tw_view *v,
                                  const struct tw_box *common_box, float w, float d,
                                  struct tw_cull_cell *out, size_t cap,
                                  struct tw_cull_scan *scan);

/* The nodes of the cut (struct tw_cull_levels) whose box, placed at their
 * base, meets the frustum within the view distance, front to back, as
 * tw_cull_cells_in_view_scan() gives cells (what it is without a
 * hierarchy): up to cap into out, returning how many there are in all. The
 * work is bounded the same way: at most TW_TILES_MAX_CELLS_IN_VIEW nodes
 * tested, at every level, those around the camera first. */
struct tw_cull_grid;
size_t tw_cull_nodes_in_view(const struct tw_view *v, const struct tw_cull_grid *g,
                             struct tw_cull_cell *out, size_t cap, struct tw_cull_scan *scan);

/* ---- the query backend (DESIGN §5) ----------------------------------------- */

/* Query handles are non-zero. Every issued query is read exactly once with
 * wait(), which also releases it; a query may stay unread across frames. A
 * backend that cannot make a query (out of memory) says so in its log and
 * returns TW_QUERY_VISIBLE, which is ready at once and reads as visible
 * (UINT32_MAX samples): culling then errs on the side of drawing. */
#define TW_QUERY_VISIBLE UINT32_MAX
struct tw_query_backend {
    void *ctx;
    /* Issues one occlusion query drawing count tile-local boxes moved by
     * offset (several boxes: a multiquery). Never blocks. */
    uint32_t (*issue)(void *ctx, const struct tw_box *boxes, uint32_t count,
                      const float offset[3]);
    /* True once the query's result is available. Never blocks. */
    bool (*ready)(void *ctx, uint32_t query);
    /* Blocks until the result is available, releases the query and returns
     * the number of samples that passed (for GL_ANY_SAMPLES_PASSED: 0 or 1). */
    uint32_t (*wait)(void *ctx, uint32_t query);
    /* Draws clusters (indices into the tile's clusters) of the tile at cell
     * whose content is content (struct tw_cull_tile), placed at offset.
     * Arrays are only read during the call. */
    void (*draw)(void *ctx, struct tw_cell cell, uint32_t content,
                 const float offset[3], const uint32_t *clusters,
                 uint32_t count);
    /* May be NULL. Draws as draw() does, but only if query (issued, not read
     * yet) passes, the GPU deciding without a CPU wait (conditional
     * rendering); a GPU that has no answer yet when the draw reaches it
     * draws. The query must still be read once with wait(). NULL where there
     * is no conditional rendering: callers then wait, or draw, as before. */
    void (*draw_if)(void *ctx, uint32_t query, struct tw_cell cell, uint32_t content,
                    const float offset[3], const uint32_t *clusters, uint32_t count);
    /* Sends issued work to the GPU. */
    void (*flush)(void *ctx);
    /* May be NULL. Says that the next query issued is a tile query (the
     * box of a cell or block of the grid, stretched or not), for debug
     * views that tell tile queries from BVH node queries. */
    void (*tile_query_next)(void *ctx);
    /* The depth of everything drawn so far this frame, for the HZB methods
     * (DESIGN §6): fills *width, *height and *reversed (window depth near =
     * 1, far = 0; else near = 0, far = 1) and, when depth is not NULL,
     * blocks until what was drawn is done and copies width * height window
     * depths, bottom row first, into depth (the caller's, that many
     * floats). Returns false when there is no depth to read; may itself be
     * NULL. Either way nothing can then be proven hidden, and the HZB
     * methods draw everything in the frustum. */
    bool (*read_depth)(void *ctx, float *depth, uint32_t *width, uint32_t *height,
                       bool *reversed);
    /* The HZB on the GPU (DESIGN §6), where the backend has compute
     * shaders; all NULL where it has not (the HZB methods then read the
     * depth back and build the pyramid on the CPU). No call waits for the
     * GPU.
     * gpu_hzb_build: builds a depth pyramid of everything drawn so far this
     *   frame and clears the frame's candidates; false: none could be made
     *   (nothing is then proven hidden). owner names whose frame it is
     *   (methods run side by side share a backend): results go to it.
     * gpu_hzb_candidate: queues box (view-relative, the query margin
     *   included) for the frame's test; when it passes, or when always
     *   (a box the near plane may cut), count clusters of the tile at cell
     *   (content placed at offset) are drawn. Returns the candidate's
     *   index in the frame's results.
     * gpu_hzb_test: tests every candidate queued against the pyramid and
     *   draws the clusters of those that pass, in the order queued.
     * gpu_hzb_results: the results of the latest frame whose test the GPU
     *   has finished and that was not yet given out: one bit per candidate
     *   (bit i % 32 of word i / 32 set: passed), their number, and that
     *   frame's number (the view's); NULL when none is new. wait: block
     *   until the latest frame tested is finished (a deterministic run). */
    bool (*gpu_hzb_build)(void *ctx, const void *owner, uint64_t frame);
    uint32_t (*gpu_hzb_candidate)(void *ctx, const struct tw_box *box, bool always,
                                  struct tw_cell cell, uint32_t content, const float offset[3],
                                  const uint32_t *clusters, uint32_t count);
    void (*gpu_hzb_test)(void *ctx);
    const uint32_t *(*gpu_hzb_results)(void *ctx, const void *owner, bool wait, uint32_t *count,
                                       uint64_t *frame);
};

/* ---- vfc: view-frustum culling inside one tile ------------------------------ */

/* Writes into out (room for proto->cluster_count) the clusters of proto whose
 * box, moved by offset, meets the frustum within the view distance, and
 * returns how many. */
uint32_t tw_cull_vfc_tile(const struct tw_view *v, const struct tw_prototype *proto,
                          const float offset[3], uint32_t *out);

/* ---- CHC++ inside a tile (DESIGN §7): its settings and costs ------------------- */

#define TW_CHC_MAX_SUSPENDED 4u
struct tw_chc_settings {
    uint32_t batch_size;        /* b: I-queue batch; default 50 */
    uint32_t assumed_visible;   /* n_av: frames a visible leaf goes unqueried; default 8 */
    uint32_t threshold;         /* T: visible when samples > T; default 0 */
    bool no_multiqueries;       /* issue every I-query alone (for measurements) */
    bool no_tight_boxes;        /* query node boxes, not tight-box lists */
    bool no_cost_model;         /* ignore tw_chc_set_costs(): every query costs one unit,
                                   as in the paper (for measurements) */
    bool per_tile_waits;        /* tilequery+chc: passes flush and wait tile by tile, at
                                   most suspended_passes suspended (the default: they
                                   suspend without limit and resume at each wavefront's
                                   one flush, tw_chc_set_wavefront) */
    uint32_t suspended_passes;  /* tw_chc_traverse_async: passes suspended at once,
                                   1..TW_CHC_MAX_SUSPENDED; default 1 */
    bool first_sight_draws;     /* a leaf never found visible by a query (a new tile's) is
                                   drawn before it is queried, as DESIGN §7 has it (for
                                   measurements); default: it is queried first, with the
                                   I-queue, its parents still taken as visible */
    uint64_t seed;              /* for the randomised re-query offsets */
};

/* What work costs on the GPU a frame runs on (DESIGN §14), in milliseconds
 * of CPU time (a software rasteriser's work is CPU time). A zeroed model
 * (query == 0) is no model: every query costs one unit, as in the paper. */
struct tw_cost_model {
    float query;                /* one occlusion query of one box, in a batch */
    float query_flush;          /* what a batch of queries adds once: sending it and
                                   waiting for an answer (a round trip less a query) */
    float query_box;            /* each further box of a query */
    float query_pixel;          /* each pixel its boxes cover */
    float draw;                 /* one draw call (a cluster) */
    float triangle;             /* each triangle drawn */
    float draw_pixel;           /* each pixel a drawn node's box covers (hidden: depth
                                   tested, not shaded) */
    float screen_pixels;        /* width * height: no box covers more */
};

/* Fills in the defaults of every zero field that has one. */
void tw_chc_default_settings(struct tw_chc_settings *s);

/* ---- tile-query propagation (DESIGN §4): its settings ---------------------------- */

struct tw_tilequery_settings {
    uint32_t neighbours;        /* 4 (edge neighbours) or 8 (and diagonals); default 4 */
    uint32_t threshold;         /* a cell is visible when its query passes > threshold samples */
};

void tw_tilequery_default_settings(struct tw_tilequery_settings *s);

/* The propagation engine: the pending and postponed queues, which cells
 * were visible last frame, scratch space. No allocation per frame once warm. */
struct tw_tilequery;

/* ---- the method drivers: one frame over the grid, top-down ------------------------ */

/* A cell's tile as a frame culls and draws it. The pointers are borrowed
 * from the tile source and stay valid until the end of the frame. */
struct tw_cull_tile {
    const struct tw_prototype *proto;   /* its instances and clusters, tile-local */
    const struct tw_bvh *bvh;           /* over proto's clusters */
    uint32_t content;                   /* what the backend draws (a fixed tileset: the
                                           prototype index) */
    uint32_t key;                       /* names the content for the cell's tile
                                           instance: an instance made for another key
                                           is made afresh (a fixed tileset: the
                                           prototype index) */
    uint32_t level;                     /* of the node it is the tile of (0: a cell's);
                                           the frame sets it, not the source */
};

/* The key of an empty cell's tile (proto NULL: nothing to draw). */
#define TW_CULL_KEY_EMPTY (UINT32_MAX - 1u)

/* tw_tile_source.get() flags. */
#define TW_TILE_SOURCE_RESIDENT 1u      /* only if already at hand: never request, never wait */
#define TW_TILE_SOURCE_WAIT 2u          /* wait for the tile whatever the policy (an oracle
                                           must see every tile) */
#define TW_TILE_SOURCE_QUIET 4u         /* do not count the tile as drawn (for eviction) */

/* What tw_tile_source.get() returns for a tile that is not ready (yet). */
#define TW_TILE_PENDING 1

/* Where a frame finds the tile of a cell. */
struct tw_tile_source {
    void *ctx;
    /* Fills *out with the tile at cell and returns TW_OK; returns
     * TW_TILE_PENDING when the tile is not ready (it is then drawn as a
     * hole: its query box still counts for propagation, its geometry
     * occludes nothing), or a negative error (the frame stops with it).
     * level: 0 for a cell's tile; with a hierarchy (struct tw_cull_levels),
     * the node of that level whose base is cell, its tile standing for all
     * of its cells (placed at the base, inside the node's box). distance:
     * eye to the node's box placed at cell, always: a priority, and what
     * the level of detail drawn depends on (the same node must get the
     * same content wherever in the frame it is asked for). Called on the
     * frame's thread. */
    int (*get)(void *ctx, struct tw_cell cell, uint32_t level, float distance, unsigned flags,
               struct tw_cull_tile *out);
    /* A hint that the node (cell, level) will soon be needed (its tile
     * query is about to be issued); may be NULL. */
    void (*prefetch)(void *ctx, struct tw_cell cell, uint32_t level, float distance);
};

/* The hierarchy of cells a frame culls over (DESIGN §17): a node of level k
 * is the block of 2^k x 2^k cells whose first cell has i and j multiples of
 * 2^k (level 0: a cell); it is named by that cell, its base. Its box is the
 * common box placed at each of its cells, joined (tw_cull_node_box). A node
 * of level k >= 1 is refined into its four children while the eye is nearer
 * its box than refine[k] metres; the nodes of the top level, count - 1, tile
 * the plane. What a frame culls is the cut this makes: every cell lies in
 * exactly one node of it, found from the top down (tw_cull_cover), so a
 * base names one node of the cut in a frame. count 0 or 1: cells only. */
#define TW_CULL_MAX_LEVELS 12u
struct tw_cull_levels {
    uint32_t count;
    float refine[TW_CULL_MAX_LEVELS];
};

/* The grid a frame culls: footprint, the common box (tile-local; every tile
 * lies inside it: it is the tile query's box), the hierarchy of its cells
 * (zero: none) and the source of its tiles. */
struct tw_cull_grid {
    float footprint[2];
    struct tw_box common_box;
    struct tw_cull_levels levels;
    struct tw_tile_source source;
};

/* The box of a node of level (base-local: the base cell's placement moves
 * it, tw_tiles_cell_offset): the common box stretched over 2^level cells
 * each way. Level 0: the common box. */
struct tw_box tw_cull_node_box(const struct tw_cull_grid *g, uint32_t level);

/* The node of the frame's cut that holds cell (its base in *base, may be
 * NULL) and its level. */
uint32_t tw_cull_cover(const struct tw_view *v, const struct tw_cull_grid *g, struct tw_cell cell,
                       struct tw_cell *base);

/* Whether the grid has a hierarchy (more than one level). */
static inline bool tw_cull_grid_hierarchical(const struct tw_cull_grid *g)
{
    return g->levels.count > 1;
}

/* The nodes of the frame's cut next to node (base, level): those holding a
 * cell that shares an edge with one of its cells (neighbours 8: or a
 * corner), each once, none of them node itself. Writes up to cap of them
 * (cell, level; distance 0) into out and returns how many there are in all.
 * Without a hierarchy, the 4 or 8 cells of tw_cell_neighbour() in its order. */
size_t tw_cull_node_neighbours(const struct tw_view *v, const struct tw_cull_grid *g,
                               struct tw_cell base, uint32_t level, uint32_t neighbours,
                               struct tw_cull_cell *out, size_t cap);

/* A fixed tileset as a tile source: cell -> prototype by selection, drawn as
 * content = prototype index. Borrowed pointers, which must outlive the
 * source; bvhs has one BVH per prototype. A selection callback returning a
 * prototype out of range is an error (logged, TW_ERR_INVALID). */
struct tw_cull_fixed {
    const struct tw_tileset *tileset;
    const struct tw_selection *selection;
    struct tw_bvh *const *bvhs;
    const struct tw_log *log;           /* may be NULL */
};
struct tw_tile_source tw_cull_fixed_source(const struct tw_cull_fixed *f);
/* The grid of a fixed tileset (its footprint and common box). */
struct tw_cull_grid tw_cull_fixed_grid(const struct tw_cull_fixed *f);

/* The cells in view of one frame, enumerated once (tw_cull_cells_in_view)
 * and kept for whoever needs them in that frame. Zero-initialise; free with
 * tw_cull_cells_finish(). */
struct tw_cull_cells {
    struct tw_cull_cell *cells;
    size_t count, cap;
    bool valid;
    struct tw_cell cell;                /* the view they are for */
    float view_proj[16];
    float view_distance;
    struct tw_cull_levels levels;
    struct tw_box common_box;
};
/* The cells in view of v, front to back: enumerated on the first call for
 * a view, then given back until the view (cell, matrix, view distance) or
 * the grid (its levels, its common box) changes. */
int tw_cull_cells_of_frame(struct tw_cull_cells *c, const struct tw_view *v,
                           const struct tw_cull_grid *g);
void tw_cull_cells_finish(struct tw_cull_cells *c);

enum tw_cull_method {
    TW_CULL_VFC = 0,        /* every cluster in the frustum of every cell in view */
    TW_CULL_TILEQUERY,      /* §4, visible tiles drawn whole (frustum-culled) */
    TW_CULL_CHC,            /* CHC++ in every cell in view, front to back */
    TW_CULL_TILEQUERY_CHC,  /* §4 with CHC++ inside each visible tile */
    TW_CULL_GIVEN,          /* exactly the set of tw_cull_driver_give() */
    TW_CULL_HZB,            /* two-phase HZB: last frame's visible clusters, then every
                               cell and node in view tested against their depth pyramid */
    TW_CULL_TILEQUERY_HZB,  /* §4 with every tile and node test answered by that pyramid */
    TW_CULL_METHOD_COUNT
};

struct tw_cull_driver_settings {
    enum tw_cull_method method;
    unsigned source_flags;              /* passed to every tw_tile_source.get() */
    uint32_t evict_after_frames;        /* tile instances unseen this long go; default 60 */
    struct tw_chc_settings chc;
    struct tw_tilequery_settings tilequery;
    float hzb_mutate_shrink;            /* testing only: tw_hzb_set_mutation() */
};

/* Counters of one frame. */
struct tw_cull_frame_stats {
    uint32_t queries_skipped;           /* by CHC++'s cost model (tw_chc_stats) */
    uint32_t tiles_queried;
    uint32_t tiles_visible;             /* tiles with something drawn (tile queries:
                                           tiles rendered) */
    uint32_t tiles_new;                 /* tile instances made this frame */
    uint32_t tiles_pending;             /* cells found visible whose tile was not ready */
    uint32_t tiles_cached;
    uint64_t cache_bytes;               /* the tile cache's heap bytes */
    uint32_t predict_fail;
    /* The HZB methods: tiles_queried counts common boxes tested against the
     * pyramid, predict_fail cells drawn in phase 1 and found hidden, or
     * tested hidden last frame and visible now. */
    uint32_t hzb_boxes;                 /* boxes tested against the pyramid: common boxes
                                           and BVH nodes */
    double ms_hzb_read;                 /* reading the depth back (be->read_depth), blocked
                                           until phase 1 is drawn */
    double ms_hzb_build;                /* building the pyramid (on the GPU: submitting it) */
    uint32_t tiles_late;                /* the GPU HZB: cells whose common box the GPU found
                                           visible in a frame that had not taken their tile
                                           (it learnt it too late: a frame may have missed
                                           pixels), counted when the answer arrives */
    uint32_t hzb_results_lag;           /* the GPU HZB: frames between the answers applied
                                           and this frame (0: none yet) */
};

/* A method with its temporal state: the tile cache of its instances, its
 * CHC++ engine and its propagation state. Methods that alternate frame by
 * frame each have their own driver. Holds queries across frames. */
struct tw_cull_driver;

int tw_cull_driver_create(const struct tw_cull_driver_settings *s, struct tw_cull_driver **out);
/* Accepts NULL. Queries in flight are abandoned unread. */
void tw_cull_driver_destroy(struct tw_cull_driver *d);

/* For TW_CULL_GIVEN: the clusters the next frame draws, in runs of one tile
 * (one draw call per run). set is borrowed until that frame is done. */
void tw_cull_driver_give(struct tw_cull_driver *d, const struct tw_drawn_cluster *set,
                         size_t count);

/* Runs one frame of v (v->frame increases by one per call of this driver):
 * everything found visible is drawn through be before it returns. cells
 * holds (or receives) the frame's cells in view. */
int tw_cull_driver_frame(struct tw_cull_driver *d, const struct tw_view *v,
                         const struct tw_cull_grid *g, const struct tw_query_backend *be,
                         struct tw_cull_cells *cells, struct tw_cull_frame_stats *stats);

/* The costs CHC++ decides with from the next frame on (copied; NULL: none),
 * see tw_chc_set_costs(). */
void tw_cull_driver_set_costs(struct tw_cull_driver *d, const struct tw_cost_model *costs);

enum tw_cull_method tw_cull_driver_method(const struct tw_cull_driver *d);
/* The driver's propagation engine (NULL for methods without tile queries). */
const struct tw_tilequery *tw_cull_driver_tilequery(const struct tw_cull_driver *d);
/* Heap bytes held by the driver (the tile cache, the engines, scratch). */
size_t tw_cull_driver_bytes(const struct tw_cull_driver *d);
/* Drops the driver's tile instance at cell (its content changed). */
void tw_cull_driver_forget(struct tw_cull_driver *d, struct tw_cell cell);
/* The same for every cell in [lo, hi] (inclusive). */
void tw_cull_driver_forget_rect(struct tw_cull_driver *d, struct tw_cell lo, struct tw_cell hi);
/* Evicts tile instances not visible in frame, least recently visible first,
 * until excess bytes are freed or none is left; returns the bytes freed and
 * adds the instances evicted to *count. */
uint64_t tw_cull_driver_trim(struct tw_cull_driver *d, uint64_t excess, uint64_t frame,
                             uint32_t *count);

/* ---- debugging: the cells of the last frame (read-only; the viewer) --------------- */

/* What the last tw_tilequery_frame() made of a cell it reached (the colours
 * of Figure 6 in the paper). */
enum tw_tilequery_cell_state {
    TW_TILEQUERY_CELL_START = 0,    /* where propagation began: visible without a query */
    TW_TILEQUERY_CELL_FREE,         /* near-plane rule: visible without a query */
    TW_TILEQUERY_CELL_VISIBLE,      /* queried, waited on, found visible */
    TW_TILEQUERY_CELL_OCCLUDED,     /* queried, waited on, found hidden: propagation stopped */
    TW_TILEQUERY_CELL_POSTPONED,    /* drawn on last frame's word, its result read later */
};

typedef void (*tw_tilequery_cell_fn)(void *user, struct tw_cell cell,
                                     enum tw_tilequery_cell_state state);

/* Calls fn for every cell that the last tw_tilequery_frame() rendered or
 * queried (start cell first, then in issue order); cells it never reached
 * are not reported. Changes nothing; valid until the next frame. */
void tw_tilequery_last_cells(const struct tw_tilequery *tq, tw_tilequery_cell_fn fn, void *user);

#ifdef __cplusplus
}
#endif

#endif
