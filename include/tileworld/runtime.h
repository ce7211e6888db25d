/*
 * runtime: the public API of tileworld, what the `tileworld` command and a
 * host world generator use (DESIGN.md §2).
 *
 *   tw_world_create()             a world: a tileset on the infinite grid,
 *                                 drawn with a culling method
 *   tw_world_frame()              renders one frame from a camera
 *   tw_world_read_rgb()           reads the frame's image
 *   tw_world_destroy()
 *
 * Threading: a world is used on the thread where its GL context is current,
 * by one thread at a time, and never from its own callbacks (selection,
 * provider, logger). Every call that draws, reads an image or changes the
 * world checks this and refuses otherwise: TW_ERR_STATE, with one error
 * line through the world's logger ("cannot render a frame: the world's
 * OpenGL context is not current on the calling thread ..."). The getters
 * (tw_world_settings, _tile_events, _drawn, _level, _last_view,
 * _reversed_z, _cache_totals, _debug_boxes) only read what the last call
 * left, and may be called from the callbacks. A world moves to another
 * thread with its context (tw_context_release() where it was current, then
 * tw_context_make_current() on the new thread). A NULL world or a NULL
 * pointer argument is TW_ERR_INVALID (or NULL, 0, nothing for calls
 * without an error code). No global state: several worlds may live in one
 * process (each needs its GL context current when it is called).
 */
#ifndef TW_RUNTIME_H
#define TW_RUNTIME_H

#include <stdbool.h>
#include <stdint.h>

#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Returns the address of a GL entry point, or NULL. */
typedef void *(*tw_gl_get_proc_fn)(const char *name);

/* ---- methods (DESIGN §6) -------------------------------------------------------- */

enum tw_method {
    TW_METHOD_DEFAULT = 0,      /* the default of DESIGN §6: tilequery+chc */
    TW_METHOD_VFC,
    TW_METHOD_TILEQUERY,
    TW_METHOD_CHC,
    TW_METHOD_TILEQUERY_CHC,
    TW_METHOD_HZB,              /* two-phase hierarchical-Z culling (DESIGN §6) */
    TW_METHOD_TILEQUERY_HZB,    /* §4 answered by the depth pyramid instead of queries */
    TW_METHOD_COUNT
};
/* The first real method: loops over methods run [TW_METHOD_FIRST, TW_METHOD_COUNT). */
#define TW_METHOD_FIRST TW_METHOD_VFC

/* "vfc", "tilequery", "chc", "tilequery+chc", "hzb", "tilequery+hzb"
 * ("default" for TW_METHOD_DEFAULT). */
const char *tw_method_name(enum tw_method m);
/* Parses a method name (not "default"); returns TW_ERR_INVALID for an
 * unknown one. */
int tw_method_from_name(const char *name, enum tw_method *out);
/* ---- the world ------------------------------------------------------------------ */

/* A camera: a world position (cell + local offset, DESIGN §3) and angles in
 * degrees (yaw 0 looks along +z, 90 along +x; pitch > 0 looks up). */
struct tw_camera {
    struct tw_world_pos pos;
    float yaw;
    float pitch;
};

/* What a frame does with a visible cell whose generated tile is not ready
 * (DESIGN §12). */
enum tw_stream_policy {
    TW_STREAM_WAIT = 0,     /* the frame waits for it: images do not depend on timing */
    TW_STREAM_SKIP,         /* the frame draws without it (a hole, counted in tiles_pending) */
};

/* What happened to a cell's generated tile. */
enum tw_tile_event_kind {
    TW_TILE_READY = 0,      /* generated, built and uploaded: it can be drawn */
    TW_TILE_EVICTED,        /* it left the cache (budget, or invalidated) */
    TW_TILE_REFUSED,        /* generate() failed, or the tile exceeded the provider's bound
                               or a cap (max_tile_triangles, max_tile_bytes): the cell
                               shows nothing until it is asked for again (retry_after_frames
                               later, twice as late each time, at most retry_max times
                               while in sight; after it has been out of sight; when it is
                               invalidated or tw_world_retry_cell() is called); or memory
                               ran out making or uploading it (asked for again when next
                               wanted) */
};

struct tw_tile_event {
    struct tw_cell cell;
    enum tw_tile_event_kind kind;
    uint64_t bytes;         /* what the tile costs (READY) or freed (EVICTED), CPU + GPU */
    uint32_t latency;       /* READY: frames from its request to ready */
    bool reload;            /* READY: the cell's tile had been evicted before (lately) */
    bool empty;             /* READY: generate() found the cell empty (TW_GENERATE_EMPTY):
                               nothing to draw, bytes 0 */
    int error;              /* REFUSED: why, a negative tw_error (TW_ERR_LIMIT for the
                               bound and the caps, else what generate() returned) */
    uint32_t attempt;       /* REFUSED: refusals of the cell in a row, from 1 */
    uint32_t retry_in;      /* REFUSED: frames (of any method) until the cell is asked for
                               again if still wanted (0: not before it leaves sight, is
                               invalidated or retried) */
    char message[256];      /* REFUSED: the reason in words, as logged (the provider's own,
                               given through tw_tileset_fail(), when it gave one) */
};

/* Host rendering (README "Host rendering"): the world streams, culls and
 * budgets, and the host draws. One batch of clusters of one tile, to draw
 * now. */
struct tw_host_draw {
    struct tw_cell cell;        /* the tile's cell */
    uint32_t prototype;         /* its content, as tw_drawn_cluster names it */
    uint32_t level;             /* the level of detail to draw: tw_world_level(prototype,
                                   level) gives its prototype and tileset */
    const uint32_t *clusters;   /* indices into that prototype's clusters, in order */
    uint32_t count;
    float offset[3];            /* the tile's origin, view-relative metres: every
                                   instance is drawn at transform * p + offset, seen through
                                   the frame's view (tw_world_last_view) */
    void *host_data;            /* what prepare() returned for the tile (NULL for shared
                                   content, or without prepare) */
};

/* What tw_host_renderer.release() is given for a tile dropped before it
 * was ready: no prototype, the data prepare_worker() returned. */
#define TW_HOST_NOT_READY UINT32_MAX

struct tw_host_renderer {
    /* Draws the batch now, on the render thread, inside tw_world_frame(),
     * into the framebuffer that was bound when the frame was called (its
     * size at least the world's width x height), with depth test and
     * writes, the view's projection (proj_rz when tw_world_reversed_z(),
     * else proj, with view) and the depth convention the world set up
     * (reversed: the depth cleared to 0, GL_GEQUAL). The world's occlusion
     * queries are drawn between batches into the same framebuffer and test
     * its depth: a batch must write the depth its clusters make. The
     * callback may change any GL state (programs, vertex arrays, buffers,
     * uniforms, textures, masks, culling); the world sets what it needs
     * again after each call. Non-NULL: the world is in host rendering. */
    void (*draw)(void *user, const struct tw_host_draw *batch);
    /* On a worker thread, once a generated tile (tile) and its levels of
     * detail (levels: level k is its prototype k - 1; NULL without) are
     * made: the host may turn them into what its engine uploads (vertex
     * formats, compression; never GL), returning its data for prepare(), or
     * for release() if the tile is dropped before it is ready. Concurrent
     * for different tiles. May be NULL. */
    void *(*prepare_worker)(void *user, struct tw_cell cell, const struct tw_tileset *tile,
                            const struct tw_tileset *levels);
    /* On the render thread, when a generated tile becomes ready, before any
     * batch names it: the host uploads it (the tilesets stay valid until
     * release), returns its data for the tile (given back in every batch's
     * host_data) and sets *bytes to what it holds for it (counted in
     * bytes_gpu and the cache budget). While prepare is set the world keeps
     * no GPU copy of generated tiles. May be NULL (the host then uploads
     * in draw, and the world keeps a copy of its own). */
    void *(*prepare)(void *user, uint32_t prototype, const struct tw_tileset *tile,
                     const struct tw_tileset *levels, void *worker_data, uint64_t *bytes);
    /* A generated tile's content (and its levels) leaves the world, on the
     * render thread: what the host made for prototype (data: what prepare
     * returned) can go; or, with prototype TW_HOST_NOT_READY, a tile
     * dropped before it was ready (data: what prepare_worker returned, on
     * the render thread too). May be NULL. Shared content (a fixed
     * tileset's, a provider's shared) is never released: it lives as long as
     * the world. A worker still in generate() when the world is destroyed
     * and left behind (tw_world_destroy) calls nothing of the host's
     * again: what its prepare_worker would have made is not made. */
    void (*release)(void *user, uint32_t prototype, void *data);
    void *user;
    bool clear;                 /* the world clears the framebuffer (colour to its sky, depth
                                   to the far value) when a frame begins; else the host does */
};

/* Settings of a world. Zero-initialisable: tw_world_create() resolves every
 * zero field to its default (see tw_world_default_settings()). A world
 * shows either a fixed tileset (tileset + selection) or a provider. */
struct tw_world_settings {
    const struct tw_tileset *tileset;  /* borrowed; must outlive the world */
    struct tw_selection selection;     /* which prototype each cell shows */
    const struct tw_tile_provider *provider; /* instead of tileset: a world generator
                                          (tiles.h), borrowed; must outlive the world */
    const struct tw_tileset *object_models; /* moving objects (tw_world_object_add): a
                                          finished tileset whose prototypes are the models
                                          objects show, model-local (the origin is the
                                          object's position; every box within the world's
                                          footprint of it); borrowed, must outlive the
                                          world. NULL: no objects. A provider's own
                                          coarser levels (tiles.h) are not used then: a
                                          block would leave the objects out */
    uint32_t workers;                  /* threads generating tiles; default: cores - 1,
                                          at least 1 */
    enum tw_stream_policy policy;      /* default TW_STREAM_WAIT */
    uint64_t cache_budget_bytes;       /* every byte the tiles cost, CPU and GPU; 0: none */
    uint64_t upload_budget_bytes;      /* per frame, of tiles not yet needed; default 32 MiB */
    float upload_budget_ms;            /* per frame, likewise; default 4 */
    uint32_t retry_after_frames;       /* a refused tile is asked for again this many frames
                                          later, then twice as late each time; default (0)
                                          30; TW_NEVER_RETRY: only when it leaves sight, is
                                          invalidated or tw_world_retry_cell() is called */
    uint32_t retry_max;                /* how many times at most while in sight; default
                                          (0) 4 */
    uint64_t max_tile_triangles;       /* a generated tile with more triangles is refused
                                          (TW_ERR_LIMIT, the cell and the cap logged); default
                                          (0) TW_MAX_TILE_TRIANGLES; UINT64_MAX: no cap */
    uint64_t max_tile_bytes;           /* likewise for what a tile takes in memory (its
                                          geometry, clusters and BVH); default (0)
                                          TW_MAX_TILE_BYTES, or a quarter of
                                          cache_budget_bytes when that is less;
                                          UINT64_MAX: no cap */
    uint32_t shutdown_timeout_ms;      /* how long tw_world_destroy() waits for a provider's
                                          generate() calls still running before it leaves
                                          them behind; default (0) 5000 */
    enum tw_method method;             /* default (0): tilequery+chc */
    uint32_t width, height;            /* default 640 x 360 */
    float fov_y;                       /* vertical field of view, degrees; default 60 */
    float near_plane;                  /* metres; default 0.2 */
    float view_distance;               /* metres; default 600 */
    float max_screen_error;            /* levels of detail (DESIGN §17): a tile is drawn at
                                          the coarsest of its levels whose geometric error
                                          projects to at most this many pixels; default (0)
                                          1; TW_FULL_DETAIL (negative): full detail always,
                                          and no levels are built */
    const char *levels_cache_dir;      /* levels of detail kept in this folder (made if
                                          missing), keyed by the content they are made of,
                                          and read back by later worlds and processes
                                          instead of built again: the same levels, in
                                          milliseconds (README "Levels of detail");
                                          NULL: none */
    uint64_t levels_cache_bytes;       /* the folder's files together, the least recently
                                          used going beyond it; default (0) 1 GiB; the
                                          first world of a process to name a folder sets
                                          it */
    uint32_t evict_after_frames;       /* tile cache; default 60 */
    bool verify;                       /* run the oracle's ID pass every frame (untimed) and
                                          count what the method missed (missed_pixels) */
    float verify_tolerance;            /* relative depth difference that --verify takes for
                                          a real one (DESIGN §8); default
                                          TW_VERIFY_TOLERANCE */
    bool deterministic;                /* no query result counts as ready before it is
                                          waited on: a run's counts then do not depend
                                          on the GPU's timing (tests, comparisons);
                                          slower, as latency is no longer hidden */
    struct tw_host_renderer host;      /* host rendering when host.draw is set: no verify, no
                                          oracles, no image of the world's own; the HZB
                                          methods read the host's depth back */
    tw_gl_get_proc_fn get_proc;        /* loader of the current context; required */
    struct tw_log log;                 /* copied; zeroed: silent */
};

/* tw_world_settings.retry_after_frames: a refused tile is not asked for
 * again while in sight. */
#define TW_NEVER_RETRY UINT32_MAX
/* The defaults of the caps of one generated tile: about a hundred times the
 * largest tile of the built-in providers (city-gen's: 41 k triangles, 2.1 MiB
 * of geometry and clusters), so that a provider's runaway cell is refused
 * instead of filling the memory. */
#define TW_MAX_TILE_TRIANGLES 4000000ull
#define TW_MAX_TILE_BYTES (256ull << 20)

/* tw_world_settings.max_screen_error: no levels of detail. */
#define TW_FULL_DETAIL (-1.0f)

/* The default of tw_world_settings.verify_tolerance: two surfaces whose eye
 * distances differ by less than this fraction are one surface to a user (a
 * depth tie between touching clusters), see DESIGN §8 and README. */
#define TW_VERIFY_TOLERANCE 1e-5f

/* Resolves the defaults of every zero field of s. */
void tw_world_default_settings(struct tw_world_settings *s);

/* Statistics of one frame: the columns of frames.csv (DESIGN §9). Fields a
 * method does not produce are 0. */
struct tw_frame_stats {
    uint64_t frame;
    enum tw_method method;
    double ms_frame;         /* wall time of the frame (see tw_world_frame, tw_world_finish) */
    double ms_cull;          /* CPU time of culling, outside draws and waits */
    double ms_wait;          /* time blocked on the GPU: query results, and flushes
                                that wait for the rasteriser to take the work */
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
    uint64_t missed_pixels;  /* pixels of a cluster the method did not draw, where what
                                it shows lies farther (beyond verify_tolerance) */
    uint32_t missed_clusters;/* clusters with a missed pixel */
    uint64_t overdraw_triangles;     /* drawn, of clusters without a visible pixel */
    uint64_t overdraw_box_triangles; /* of those, the clusters whose box shows in front of
                                        the frame's true depth at a pixel centre: what no
                                        query of their boxes could have culled */
    double cpu_ms;           /* process CPU time of the frame, every thread (including
                                the GPU's, on a software rasteriser) */
    uint64_t depth_errors;   /* pixels whose depth differs from the oracle's beyond
                                verify_tolerance, either way */
    uint32_t blocking_reads; /* query results waited for that were not ready yet */
    uint32_t queries_skipped;/* queries CHC++'s cost model found not worth issuing */
    /* Streaming (DESIGN §12, §13): world-wide, not per method. */
    uint32_t tiles_pending;  /* visible cells drawn without their tile (policy skip) */
    uint32_t loads_requested;/* generated tiles requested this frame */
    uint32_t loads_done;     /* generated tiles that became ready this frame */
    uint32_t evictions;      /* tiles that left the cache this frame (content and instances) */
    uint64_t bytes_cpu;      /* every byte of tiles on the CPU: shared content once,
                                generated geometry, clusters and BVHs, culling state */
    uint64_t bytes_gpu;      /* vertex and index buffers */
    uint64_t bytes_state;    /* of bytes_cpu, the culling state of every method (tile
                                instances and their tables); the rest is geometry, BVHs
                                and the stream's tables */
    uint64_t bytes_needed;   /* of bytes_cpu + bytes_gpu, what this frame could not do
                                without: every byte but the generated tiles it did not use */
    bool over_budget;        /* bytes_cpu + bytes_gpu > cache_budget_bytes after trimming:
                                what the frame needed exceeds the budget */
    double ms_upload;        /* render-thread time uploading finished tiles */
    uint64_t bytes_loading;  /* not in bytes_cpu: generated tiles waiting for their upload
                                (the per-frame upload budget), what their CPU copies cost */
    uint32_t tiles_loading;  /* their number */
    /* The HZB methods' depth pyramid (0 for the others). */
    uint32_t hzb_boxes;      /* boxes tested against it: common boxes and BVH nodes */
    double ms_hzb_build;     /* building it from the depth read back (in ms_cull) */
    double ms_hzb_read;      /* reading the depth back, blocked until phase 1 is drawn
                                (in ms_wait) */
    /* GPU time (GL_TIMESTAMP queries, never waited on; on a software rasteriser
     * it is the CPU's rasterising work). */
    double gpu_ms;           /* the timed frame's, from its start (an oracle's: after its
                                ID pass) to its last draw; filled by tw_world_finish(),
                                -1 not known */
    double gpu_ms_id;        /* the untimed ID pass's (oracles, verify), likewise; 0 when
                                the frame had none */
    uint64_t gpu_late_frame; /* for a host that never finishes: the latest earlier frame
                                of this method whose timers had come back when
                                tw_world_frame() began (its frame number; 0: none) */
    double gpu_late_ms;      /* that frame's gpu_ms; -1 with none */
    /* The CPU's round trips to the GPU in the frame (every method). */
    uint32_t waits;          /* query results read (each query once), ready or not */
    uint32_t flushes;        /* times issued work was sent to the GPU (glFlush) */
    uint64_t bytes_read_back;/* bytes the CPU read back from the GPU (the HZB methods'
                                depth, buffers); query results are not counted */
    /* The HZB methods with the pyramid on the GPU, whose answers arrive
     * later: cells whose common box the GPU found visible in a frame that
     * had not instantiated their tile (a frame that may have missed pixels),
     * counted when the answer arrives; and how many frames old the answers
     * applied in this frame were (0: none yet, or the CPU's pyramid). */
    uint32_t tiles_late;
    uint32_t hzb_lag;
    /* Levels of detail (DESIGN §17), with verify and max_screen_error > 0:
     * what they change against the same frame drawn at full detail. */
    uint64_t lod_pixels;     /* pixels whose colour differs (a channel by more than 2
                                of 255) from the other image's at the same place and at
                                its 8 neighbours, either way: what a shift of one pixel
                                (the bound of a level's edges at 1 px) does not explain */
    uint64_t lod_pixels_exact; /* pixels whose colour differs at the same place (far
                                sub-pixel detail aliases: a camera moved 5 cm changes
                                about 2 % of them at full detail) */
    double lod_depth_m;      /* the mean distance, metres along the view axis, between
                                the surfaces the two images show at the lod_pixels where
                                both show one */
    /* Moving objects (tw_world_object_add): world-wide, not per method. */
    uint32_t objects;        /* in the world */
    uint32_t object_cells;   /* cells holding one or more */
    uint32_t object_rebuilds;/* cells whose object BVH was built afresh this frame (objects
                                came or went, or refitting had worn it down); the others
                                with moves were refitted */
    double ms_objects;       /* render-thread time placing moved objects: their cells,
                                boxes and BVHs (in ms_frame and ms_cull) */
};

struct tw_world;

/* Creates a world; the GL context that s->get_proc belongs to must be
 * current. Uploads the tileset's meshes once. The caller owns *out. */
int tw_world_create(const struct tw_world_settings *s, struct tw_world **out);
/* Destroys w (NULL: nothing), with its GL context current (without it, the
 * world's memory is freed but its GL objects are left to the context, with
 * a warning; from inside a call on the world, e.g. from a callback, it is
 * refused with an error and nothing is freed), and returns the
 * number of tile workers left behind: 0, unless a provider's generate()
 * was still running shutdown_timeout_ms after the destroy began. Such a
 * call is not waited for any longer: the destroy logs one error (the
 * provider, the cells) through the world's logger and returns; the thread
 * is detached and keeps only what it owns (a copy of the provider struct,
 * the tile it was making), which it frees when generate() returns, without
 * touching anything of the world's. What the host must keep until then,
 * when the count is not 0: the provider's code, and everything generate()
 * reads or writes through provider->user (for the whole process's life, if
 * it may never return). The host's struct tw_tile_provider itself, the
 * tileset it shares, the logger and the GL context may go at once. */
uint32_t tw_world_destroy(struct tw_world *w);

/* Switches the culling method. Each method keeps its own temporal state
 * (tile cache, CHC++ state), so methods may alternate frame by frame. */
int tw_world_set_method(struct tw_world *w, enum tw_method m);

/* Renders one frame from cam with the current method and fills *stats
 * (may be NULL). Returns TW_ERR_INVALID for a camera with non-finite values,
 * and TW_ERR_NOMEM where memory ran out, among others when a generated tile
 * the frame waits for (policy wait) could not be made or uploaded for lack
 * of it (logged once per world; later ones are only counted).
 * The frame's work is sent to the GPU (glFlush), not waited for: a host
 * that wants the time to a finished frame calls tw_world_finish() next
 * (stats->ms_frame is then that time). With settings.verify the frame is
 * finished before the oracle's ID pass, and ms_frame is its time to finish.
 *
 * GL state: the world renders into framebuffers of its own and leaves the
 * host's GL state as it found it: the framebuffer, renderbuffer, program,
 * vertex array and array-buffer bindings, viewport, clip control, the
 * depth, cull, blend, scissor, stencil and polygon state, write masks,
 * clear values and pack alignment are saved on entry and restored on exit
 * of every call that draws or reads (tw_world_create included). Query
 * objects it owns stay in flight across frames. */
int tw_world_frame(struct tw_world *w, const struct tw_camera *cam,
                   struct tw_frame_stats *stats);

/* Waits for the GPU to finish the last frame (glFinish) and adds the time
 * waited to stats->ms_frame and its CPU time to stats->cpu_ms (stats may be
 * NULL); fills stats->gpu_ms and gpu_ms_id from the frame's timers, now back
 * (a fixed set's frame has none: they stay unknown). */
int tw_world_finish(struct tw_world *w, struct tw_frame_stats *stats);

/* What the cache holds, and what it did since the world was created. */
struct tw_cache_totals {
    uint32_t tiles_ready;       /* generated tiles in the cache */
    uint32_t tiles_loading;     /* requested, not ready yet */
    uint64_t tile_bytes;        /* of the ready generated tiles, CPU + GPU */
    uint64_t loads_requested, loads_done, evictions, reloads, refused;
};
int tw_world_cache_totals(const struct tw_world *w, struct tw_cache_totals *out);

/* The tile events of the last frame (tiles ready, evicted, refused), in the
 * order they happened. The array belongs to the world and lives until the
 * next frame. */
const struct tw_tile_event *tw_world_tile_events(const struct tw_world *w, size_t *count);

/* Drops what the world holds for cell (its generated tile, and every
 * method's culling state of it): the provider's answer for it has changed.
 * The next frame that needs it asks the provider again. */
int tw_world_invalidate(struct tw_world *w, struct tw_cell cell);
/* The same for every cell in [lo, hi] (inclusive in i and j). */
int tw_world_invalidate_rect(struct tw_world *w, struct tw_cell lo, struct tw_cell hi);
/* Asks for a refused cell's tile again the next time a frame needs it (the
 * host has fixed what made its provider fail), whatever the retry policy
 * says; nothing for a cell whose tile was not refused. */
int tw_world_retry_cell(struct tw_world *w, struct tw_cell cell);

/* The view of the last frame (TW_ERR_STATE before the first): its camera
 * cell, which is the origin of the frame's coordinates (view-relative
 * metres, DESIGN §3), and its matrices: view, proj (GL clip depth) and
 * proj_rz (reversed depth, which the world's own images use when
 * tw_world_reversed_z()), so that a host can draw its own things over a
 * frame: place them at (their cell - view.cell) * footprint + local. */
struct tw_world_view {
    struct tw_cell cell;        /* the camera's cell: origin of the frame's coordinates */
    float eye[3];               /* the camera, view-relative metres */
    float view[16];             /* column-major, view-relative world -> eye space */
    float proj[16];             /* eye -> clip, GL depth (z in [-w, w]) */
    float proj_rz[16];          /* eye -> clip, reversed depth (z in [0, w], near -> w) */
    float view_proj[16];        /* proj * view and proj_rz * view, as the world computes
                                   them: what its own draws and queries use, so that a host */
    float view_proj_rz[16];     /* drawing with them writes the same depths */
    float near_plane, far_plane;/* metres */
    uint64_t frame;             /* the frame's number, from 1 */
};
int tw_world_last_view(const struct tw_world *w, struct tw_world_view *out);
/* True when the world renders with reversed float depth (glClipControl). */
bool tw_world_reversed_z(const struct tw_world *w);

/* Copies the last frame's image as RGB8, top row first, into rgb
 * (width * height * 3 bytes, owned by the caller). */
int tw_world_read_rgb(struct tw_world *w, uint8_t *rgb);

/* Turns on or off the recording of every cluster drawn in a frame (off by
 * default: it costs time). A host that draws with an engine of its own
 * reads the set here. */
void tw_world_record_draws(struct tw_world *w, bool on);
/* The clusters drawn by the last frame, in draw order, while recording is
 * on. The array belongs to the world and lives until the next frame. */
const struct tw_drawn_cluster *tw_world_drawn(const struct tw_world *w, size_t *count);
/* Level level of content prototype (as tw_drawn_cluster names them; 0: the
 * content itself): its prototype (instances, clusters: what a drawn
 * cluster's index counts in) and, into *ts, the tileset whose meshes and
 * materials its instances name (the world's own for a level). NULL when the
 * content has no such level or is not live. Valid while the content is:
 * a shared content's for the world's life, a generated tile's until it is
 * evicted. */
const struct tw_prototype *tw_world_level(const struct tw_world *w, uint32_t prototype,
                                          uint32_t level, const struct tw_tileset **ts);

/* The world's resolved settings. */
const struct tw_world_settings *tw_world_settings(const struct tw_world *w);

/* ---- several views (README "Several views") ---------------------------------------- */

/* A second camera onto a world (split screen, a minimap, a mirror): its
 * own method, culling state (tile instances, CHC++), look-ahead, frame
 * numbers and statistics; the world's tiles, stream, cache budget (a tile
 * the latest frame of any view drew is kept), settings (image size, field
 * of view, view distance) and image shared. A viewport's frame draws into
 * the world's image: read it (tw_world_read_rgb, _blit, _blit_depth) after
 * that frame, before the next frame of any view; the getters
 * (tw_world_last_view, _drawn, _tile_events, ...) then tell of it too. */
struct tw_viewport;

/* Creates a viewport of w, with w's current method. The caller owns *out;
 * it is destroyed by tw_viewport_destroy() or with its world. */
int tw_viewport_create(struct tw_world *w, struct tw_viewport **out);
/* Frees vp (NULL: nothing) and its culling state. */
void tw_viewport_destroy(struct tw_viewport *vp);
/* tw_world_set_method() for the viewport's camera. */
int tw_viewport_set_method(struct tw_viewport *vp, enum tw_method m);
/* tw_world_frame() from the viewport's camera. */
int tw_viewport_frame(struct tw_viewport *vp, const struct tw_camera *cam,
                      struct tw_frame_stats *stats);

/* ---- moving objects (README "Moving objects") ------------------------------------- */

/* A moving object (a car, a person): an instance of model, a prototype of
 * the world's object_models, whose model-local point (x, y, z) is placed at
 * pos + (x cos(yaw) + z sin(yaw), y, z cos(yaw) - x sin(yaw)) (yaw in
 * degrees, turning +z towards +x). The world keeps every object of a cell
 * (the cell of pos, normalised) in a BVH of that cell, joined to its tile's,
 * so that objects are culled by the same tile queries and CHC++ as the tile:
 * they are occluded and they occlude. */
struct tw_object {
    struct tw_world_pos pos;
    float yaw;
    uint32_t model;
};

/* Adds an object; *id names it until it is removed (ids of removed objects
 * are used again). Takes effect at the next frame of any view. TW_ERR_STATE
 * without object_models (a world with hierarchical cells is not made with
 * them); in host rendering the objects come as batches of their own;
 * TW_ERR_INVALID for a model out of range or a position or yaw that is not
 * finite; TW_ERR_LIMIT beyond TW_MAX_OBJECTS. */
#define TW_MAX_OBJECTS (1u << 20)
int tw_world_object_add(struct tw_world *w, const struct tw_object *o, uint32_t *id);
/* Moves (or changes the model of) object id; takes effect at the next frame.
 * Within its cell the cell's BVH is refitted, keeping the culling state;
 * into another cell, both cells' BVHs are built afresh. */
int tw_world_object_update(struct tw_world *w, uint32_t id, const struct tw_object *o);
/* Removes object id (TW_ERR_INVALID if there is none). */
int tw_world_object_remove(struct tw_world *w, uint32_t id);

/* ---- camera paths (DESIGN §9, §10) ------------------------------------------------ */

struct tw_path {
    char name[64];
    struct tw_camera *keys;  /* one per frame, owned by the path */
    uint32_t count;
};

/* Names of the built-in paths, NULL-terminated. */
extern const char *const tw_path_builtin_names[];

/* Generates frames keys of the built-in path name for a tileset with
 * footprint w x d (streets run along the tile borders), deterministic for
 * seed, at speed metres per frame (0: the path's own: 1 for street,
 * teleport and spin, 0.8 for forest, 1 rising to 4 for flyover, 2 for the
 * memory test's long paths straight (along one street) and wander (through
 * the streets, turning at crossings)). Returns TW_ERR_INVALID for an
 * unknown name. */
int tw_path_builtin(const char *name, uint64_t seed, uint32_t frames, float speed, float w,
                    float d, struct tw_path *out);

/* The most rows (frames) a path CSV may have, and the most bytes of one:
 * ten million rows of about 100 bytes. */
#define TW_PATH_MAX_ROWS 10000000u
#define TW_PATH_MAX_CSV_BYTES (1ull << 30)

/* Reads a path CSV (header line, then cell_i,cell_j,x,y,z,yaw,pitch per
 * row). Every row is checked when the file is loaded: cells are decimal
 * 64-bit integers, x and z within +-1e7 m, y within +-TW_TILES_MAX_COORD,
 * yaw within +-1e6 degrees (kept modulo 360), pitch in (-89.9, 89.9); a
 * line holds at most 1022 characters. Only a regular file is read (a FIFO
 * or a device is refused, never waited on), of at most TW_PATH_MAX_CSV_BYTES
 * (checked before reading) and TW_PATH_MAX_ROWS rows. The file is read a
 * block at a time: the first bad row ends the reading, and frames > 0 stops
 * it after the first frames rows (fewer rows: an error; frames may not
 * exceed TW_PATH_MAX_ROWS). On error returns a negative code and writes one
 * line "FILE:LINE: reason" into err (text from the file escaped, tiles.h
 * tw_log_escape()), e.g. "walk.csv:3: field 6 (yaw) \"1e300\" is outside
 * [-1e+06, 1e+06] degrees" or "walk.csv: no such file". */
int tw_path_load_csv(const char *file, uint32_t frames, float w, float d,
                     struct tw_path *out, char *err, size_t err_size);
/* The same from size bytes of CSV at text (only read during the call); name
 * is the file name used in messages. */
int tw_path_parse_csv(const char *text, size_t size, const char *name, uint32_t frames,
                      float w, float d, struct tw_path *out, char *err, size_t err_size);

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

/* Copies the last frame's image into GL framebuffer target of the current
 * context (0: the window's), scaled to width x height. */
int tw_world_blit(struct tw_world *w, uint32_t target, uint32_t width, uint32_t height);
/* Copies the last frame's depth into the depth attachment of framebuffer
 * target, at the world's width x height from its lower left corner, for a
 * host that draws its own things into the world's image with the view of
 * tw_world_last_view. The attachment must have the world's depth format
 * (tw_world_depth_format()): TW_ERR_GL, with a line naming both, if not. */
int tw_world_blit_depth(struct tw_world *w, uint32_t target);
/* The internal format of the world's depth, a GLenum: GL_DEPTH_COMPONENT32F
 * with reversed depth (tw_world_reversed_z(): cleared to 0, GL_GEQUAL),
 * else GL_DEPTH_COMPONENT24 (cleared to 1, GL_LEQUAL). 0 for NULL. */
uint32_t tw_world_depth_format(const struct tw_world *w);

#ifdef __cplusplus
}
#endif

#endif
