/*
 * runtime: the public API of tileworld, what the `tileworld` command and a
 * host world generator use (DESIGN.md §2).
 *
 *   tw_context_create_headless()  an OSMesa OpenGL 3.3+ core context
 *   tw_world_create()             a world: a tileset on the infinite grid,
 *                                 drawn with a culling method
 *   tw_world_frame()              renders one frame from a camera
 *   tw_world_read_rgb()           reads the frame's image
 *   tw_world_destroy()
 *
 * Threading: a world and its context are used from one thread at a time.
 * No global state: several worlds may live in one process (each needs its
 * GL context current when it is called).
 */
#ifndef TW_RUNTIME_H
#define TW_RUNTIME_H

#include <stdbool.h>
#include <stdint.h>

#include "bvh/bvh.h"
#include "cull/cull.h"
#include "tiles/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- GL contexts -------------------------------------------------------------- */

/* Returns the address of a GL entry point, or NULL. */
typedef void *(*tw_gl_get_proc_fn)(const char *name);

/* A headless OpenGL context rendering into memory (OSMesa, llvmpipe). */
struct tw_context;

/* Creates a 3.3+ core context with a width x height framebuffer and makes it
 * current on the calling thread. log is copied (may be NULL). */
int tw_context_create_headless(uint32_t width, uint32_t height,
                               const struct tw_log *log, struct tw_context **out);
/* The loader of the context's GL entry points. */
tw_gl_get_proc_fn tw_context_get_proc(const struct tw_context *ctx);
/* Makes the context current again (after another context was). */
int tw_context_make_current(struct tw_context *ctx);
void tw_context_destroy(struct tw_context *ctx);

/* ---- methods (DESIGN §6) -------------------------------------------------------- */

enum tw_method {
    TW_METHOD_VFC = 0,
    TW_METHOD_TILEQUERY,
    TW_METHOD_CHC,
    TW_METHOD_TILEQUERY_CHC,
    TW_METHOD_ORACLE,
    TW_METHOD_COUNT
};

/* "vfc", "tilequery", "chc", "tilequery+chc", "oracle". */
const char *tw_method_name(enum tw_method m);
/* Parses a method name; returns TW_ERR_INVALID for an unknown one. */
int tw_method_from_name(const char *name, enum tw_method *out);
/* True if the method is implemented in this build. */
bool tw_method_available(enum tw_method m);
/* True for methods that must never miss a visible pixel (all but an
 * aggressive threshold T > 0). */
bool tw_method_conservative(enum tw_method m);

/* ---- the world ------------------------------------------------------------------ */

/* A camera: a world position (cell + local offset, DESIGN §3) and angles in
 * degrees (yaw 0 looks along +z, 90 along +x; pitch > 0 looks up). */
struct tw_camera {
    struct tw_world_pos pos;
    float yaw;
    float pitch;
};

/* Settings of a world. Zero-initialisable: tw_world_create() resolves every
 * zero field to its default (see tw_world_default_settings()). */
struct tw_world_settings {
    const struct tw_tileset *tileset;  /* borrowed; must outlive the world */
    struct tw_selection selection;     /* which prototype each cell shows */
    enum tw_method method;             /* default TW_METHOD_VFC (0) */
    uint32_t width, height;            /* default 640 x 360 */
    float fov_y;                       /* vertical field of view, degrees; default 60 */
    float near_plane;                  /* metres; default 0.2 */
    float view_distance;               /* metres; default 600 */
    uint32_t evict_after_frames;       /* tile cache; default 60 */
    bool verify;                       /* run the oracle's ID pass every frame (untimed) */
    struct tw_chc_settings chc;
    struct tw_tilequery_settings tilequery;
    struct tw_bvh_settings bvh;
    tw_gl_get_proc_fn get_proc;        /* loader of the current context; required */
    struct tw_log log;                 /* copied; zeroed: silent */
};

/* Resolves the defaults of every zero field of s. */
void tw_world_default_settings(struct tw_world_settings *s);

/* Statistics of one frame: the columns of frames.csv (DESIGN §9). Fields a
 * method does not produce are 0. */
struct tw_frame_stats {
    uint64_t frame;
    enum tw_method method;
    double ms_frame;         /* wall time, including glFinish */
    double ms_cull;          /* CPU time of culling, outside draws and waits */
    double ms_wait;          /* time blocked on query results */
    uint64_t triangles;
    uint32_t clusters;
    uint32_t draws;
    uint32_t queries;
    uint32_t tiles_queried;
    uint32_t tiles_visible;  /* tiles drawn */
    uint32_t tiles_new;
    uint32_t tiles_cached;
    uint64_t cache_bytes;
    uint32_t predict_fail;
    uint64_t missed_pixels;
    uint32_t missed_clusters;
    uint64_t overdraw_triangles;
};

struct tw_world;

/* Creates a world; the GL context that s->get_proc belongs to must be
 * current. Uploads the tileset's meshes once. The caller owns *out. */
int tw_world_create(const struct tw_world_settings *s, struct tw_world **out);
void tw_world_destroy(struct tw_world *w);

/* Switches the culling method. Each method keeps its own temporal state
 * (tile cache, CHC++ state), so methods may alternate frame by frame. */
int tw_world_set_method(struct tw_world *w, enum tw_method m);

/* Renders one frame from cam with the current method and fills *stats
 * (may be NULL). Returns TW_ERR_INVALID for a camera with non-finite values. */
int tw_world_frame(struct tw_world *w, const struct tw_camera *cam,
                   struct tw_frame_stats *stats);

/* Copies the last frame's image as RGB8, top row first, into rgb
 * (width * height * 3 bytes, owned by the caller). */
int tw_world_read_rgb(struct tw_world *w, uint8_t *rgb);

/* One drawn cluster: which tile, which cluster of its prototype. */
struct tw_drawn_cluster {
    struct tw_cell cell;
    uint32_t prototype;
    uint32_t cluster;
};

/* Turns on or off the recording of every cluster drawn in a frame (for the
 * accuracy oracle and tests; off by default: it costs time). */
void tw_world_record_draws(struct tw_world *w, bool on);
/* The clusters drawn by the last frame, in draw order, while recording is
 * on. The array belongs to the world and lives until the next frame. */
const struct tw_drawn_cluster *tw_world_drawn(const struct tw_world *w, size_t *count);

/* The world's resolved settings. */
const struct tw_world_settings *tw_world_settings(const struct tw_world *w);

/* The BVH of prototype p (built when the world was created). */
const struct tw_bvh *tw_world_bvh(const struct tw_world *w, uint32_t p);

/* ---- camera paths (DESIGN §9, §10) ------------------------------------------------ */

struct tw_path {
    char name[64];
    struct tw_camera *keys;  /* one per frame, owned by the path */
    uint32_t count;
};

/* Names of the built-in paths, NULL-terminated. */
extern const char *const tw_path_builtin_names[];

/* Generates frames keys of the built-in path name for a tileset with
 * footprint w x d and the street width street (0: 14 m), deterministic for
 * seed. Returns TW_ERR_INVALID for an unknown name. */
int tw_path_builtin(const char *name, uint64_t seed, uint32_t frames, float w,
                    float d, struct tw_path *out);

/* Reads a path CSV (header line, then cell_i,cell_j,x,y,z,yaw,pitch per
 * row). Every row is checked when the file is loaded: cells are decimal
 * 64-bit integers, x and z within +-1e7 m, y within +-TW_TILES_MAX_COORD,
 * yaw within +-1e6 degrees (kept modulo 360), pitch in (-89.9, 89.9). Only
 * a regular file is read (a FIFO or a device is refused, never waited on).
 * On error returns a negative code and writes one line "FILE:LINE: reason"
 * into err (text from the file escaped, tiles.h tw_log_escape()). frames > 0
 * keeps only the first frames rows (fewer rows: an error). */
int tw_path_load_csv(const char *file, uint32_t frames, float w, float d,
                     struct tw_path *out, char *err, size_t err_size);
/* The same from size bytes of CSV at text (only read during the call); name
 * is the file name used in messages. */
int tw_path_parse_csv(const char *text, size_t size, const char *name, uint32_t frames,
                      float w, float d, struct tw_path *out, char *err, size_t err_size);

/* Moves every key by (di, dj) cells; TW_ERR_INVALID on int64 overflow. */
int tw_path_translate(struct tw_path *p, int64_t di, int64_t dj);

void tw_path_finish(struct tw_path *p);

/* ---- debugging and the viewer -------------------------------------------------------- */

/* Debug views, a mask for tw_world_set_debug(). */
#define TW_DEBUG_CELLS   (1u << 0)  /* cells by tile-query state (the paper's Figure 6) */
#define TW_DEBUG_NODES   (1u << 1)  /* BVH nodes that hold the clusters drawn */
#define TW_DEBUG_QUERIES (1u << 2)  /* occlusion-query boxes issued this frame */
#define TW_DEBUG_ALL     (TW_DEBUG_CELLS | TW_DEBUG_NODES | TW_DEBUG_QUERIES)

enum tw_debug_kind {
    /* Cells: a quad over the cell's footprint, just above the ground. */
    TW_DEBUG_CELL_START = 0,    /* propagation began here, without a query */
    TW_DEBUG_CELL_FREE,         /* visible without a query (near-plane rule) */
    TW_DEBUG_CELL_VISIBLE,      /* queried and found visible (vfc, chc, oracle: something drawn) */
    TW_DEBUG_CELL_POSTPONED,    /* drawn on last frame's word, its query read later */
    TW_DEBUG_CELL_OCCLUDED,     /* queried and found hidden: propagation stopped there */
    TW_DEBUG_CELL_NOT_REACHED,  /* in view, never queried (vfc, chc, oracle: nothing drawn) */
    /* BVH nodes of the tiles drawn. */
    TW_DEBUG_NODE_LEAF,         /* a leaf with a drawn cluster */
    TW_DEBUG_NODE_INNER,        /* an ancestor of one */
    /* Query boxes, by outcome. */
    TW_DEBUG_QUERY_VISIBLE,
    TW_DEBUG_QUERY_HIDDEN,
    TW_DEBUG_QUERY_UNREAD,      /* not read within the frame (postponed, or a V-query) */
    TW_DEBUG_KIND_COUNT
};

/* One box of a debug view, placed like geometry: tile-local coordinates of
 * cell, so that a copy kept across frames stays where it was. */
struct tw_debug_box {
    struct tw_cell cell;
    struct tw_box box;
    uint16_t kind;              /* enum tw_debug_kind */
    uint16_t level;             /* nodes: depth in the BVH; queries: boxes in the query */
    bool tile_query;            /* queries: a tile query (the common box) */
};

/* Short name of a kind ("visible", "leaf", ...), and its colour (straight RGBA). */
const char *tw_debug_kind_name(enum tw_debug_kind kind);
void tw_debug_kind_color(enum tw_debug_kind kind, float rgba[4]);

/* Chooses the debug views that tw_world_frame() records (mask of TW_DEBUG_*;
 * 0, the default, records nothing). Recording is done after the timed part
 * of the frame, except that TW_DEBUG_CELLS and TW_DEBUG_NODES record draws
 * (as tw_world_record_draws() does) and TW_DEBUG_QUERIES records query boxes
 * as they are issued: timings of such frames are not benchmark figures. */
int tw_world_set_debug(struct tw_world *w, unsigned flags);

/* The boxes the last tw_world_frame() recorded. The array belongs to the
 * world and lives until the next frame. */
const struct tw_debug_box *tw_world_debug_boxes(const struct tw_world *w, size_t *count);

/* Draws boxes (the last frame's, or a copy kept from an earlier frame) over
 * the last frame's image, seen from its camera and coloured by kind. Not
 * timed; boxes is only read during the call. */
int tw_world_draw_debug(struct tw_world *w, const struct tw_debug_box *boxes, size_t count);

/* Renders one frame from cam that draws exactly clusters, with no culling
 * and no queries (a frozen culled set, looked at from elsewhere). Fills the
 * drawing fields of *stats (may be NULL); leaves every method's temporal
 * state alone. clusters is only read during the call. */
int tw_world_frame_fixed(struct tw_world *w, const struct tw_camera *cam,
                         const struct tw_drawn_cluster *clusters, size_t count,
                         struct tw_frame_stats *stats);

/* Copies the last frame's image into GL framebuffer target of the current
 * context (0: the window's), scaled to width x height. */
int tw_world_blit(struct tw_world *w, uint32_t target, uint32_t width, uint32_t height);

#ifdef __cplusplus
}
#endif

#endif
