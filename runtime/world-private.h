/*
 * The world's insides, shared by its files: world.c (the API and the frame),
 * oracle.c (the accuracy oracle, DESIGN §8) and debug.c (debug views).
 * Private to runtime/.
 */
#ifndef TW_RUNTIME_WORLD_PRIVATE_H
#define TW_RUNTIME_WORLD_PRIVATE_H

#include "runtime/calibrate.h"
#include "runtime/gputime.h"
#include "runtime/renderer.h"
#include "runtime/stream.h"
#include "cull/cull.h"
#include "runtime/runtime-internal.h"
#include "tiles/tiles-internal.h"
#include "tileworld/runtime.h"

#include <stdatomic.h>

#define TW_ORACLE_BLOCK 8

/* The accuracy oracle: every cluster vfc would draw, rendered into an
 * object-ID buffer; id k names entries[k]. */
struct tw_oracle {
    struct tw_cull_driver *vfc;     /* enumerates what the ID pass draws */
    struct tw_drawn_cluster *entries;
    size_t count, cap;
    struct tw_drawn_cluster *visible;  /* entries with visible pixels: tiles in id order
                                          (front to back by cell), each tile's clusters
                                          front to back */
    size_t visible_count, visible_cap;
    struct oracle_order *order;     /* scratch of tw_oracle_order() */
    size_t order_cap;
    struct tw_cell_map *ranks;      /* of that sort: cell -> its tile's rank in the set */
    uint32_t *pixels;               /* visible pixels per id */
    uint8_t *drawn;                 /* per id: drawn by the method */
    size_t per_id_cap;
    uint32_t *ids;                  /* the ID buffer, width * height */
    float *id_depth;                /* its depth */
    float *block_far;               /* the farthest eye distance of id_depth in each
                                       block of TW_ORACLE_BLOCK x TW_ORACLE_BLOCK pixels */
    uint32_t blocks_x, blocks_y;
    struct tw_drawn_cluster *box_visible;  /* the box oracle's set: the entries
                                              visible or whose own box shows */
    uint8_t *box_state;             /* per id: whether its box shows, once tested
                                       (BOX_UNKNOWN, BOX_HIDDEN, BOX_SHOWS) */
    size_t box_visible_count, box_visible_cap;
    float *depth;                   /* the method's frame's depth */
    uint32_t *missed_per_id;        /* missed pixels per id (compare) */
    struct tw_cell_map *tiles;      /* cell -> first id << 32 | cluster count */
    int err;                        /* of the ID backend's draws */
};

/* What levels of detail change in the image (lod-image.c). */
struct tw_lod_image {
    struct tw_cull_driver *vfc;     /* draws the full-detail image */
    uint64_t frame;
    uint8_t *rgb;                   /* the full-detail image, top row first */
    float *depth;                   /* its window depth, bottom row first */
    uint8_t *frame_rgb;             /* the method's, likewise */
    float *frame_depth;
};

/* Per-method state: its driver (tile cache, CHC++, propagation) and frame count. */
struct method_state {
    struct tw_cull_driver *driver;
    uint64_t frame;
};

struct tw_debug_state {
    unsigned flags;
    struct tw_debug_box *boxes;
    size_t count, cap;
    struct tw_cell_map *seen;       /* cells reported this frame */
    uint32_t *leaf_of;              /* of the tile being collected: cluster -> its BVH leaf */
    size_t leaf_cap;
    uint8_t *marked;                /* of that tile: node already reported */
    size_t marked_cap;
    struct tw_renderer_debug_box *draw;
    size_t draw_cap;
};

/* Hierarchical cells (world-hlod.c): per level k >= 1, the stream of its
 * blocks' proxies, over a grid whose cells are those blocks. */
struct tw_world_hlod_level {
    const struct tw_world *w;
    uint32_t level;
    float error;                    /* E_k: the error a proxy of this level may have */
    char name[64];
    struct tw_tile_provider provider;
    struct tw_stream *stream;
};
struct tw_world_hlod {
    uint32_t count;                 /* levels, cells included; < 2: none */
    struct tw_world_hlod_level levels[TW_CULL_MAX_LEVELS];
};

/* What each camera onto the world has of its own: its method and every
 * method's culling state (tile instances, CHC++), the cells in its view,
 * the look-ahead's motion, its last view, its GPU timers. */
struct tw_view_state {
    enum tw_method method;
    struct method_state methods[TW_METHOD_ALL];
    struct tw_cull_cells cells;     /* the cells in view of the current view */
    struct tw_world_pos prev_pos;   /* the last frame's camera, for the look-ahead */
    float velocity[3];              /* metres per frame, smoothed */
    bool has_prev;
    struct tw_cull_cells ahead;     /* cells of the look-ahead view */
    struct tw_view last_view;
    bool has_view;
    struct tw_gputime gputime;      /* the frames' GPU time, read frames later */
};

/* A viewport: a view of its own (tw_viewport_create), listed in its world. */
struct tw_viewport {
    struct tw_world *w;
    struct tw_view_state state;
    struct tw_viewport *next;
};

struct tw_world {
    struct tw_world_settings s;
    /* The thread contract (README "Threads and callbacks"): set while a call
     * that changes the world runs, so that a call made from inside it (a
     * callback re-entering) or beside it (another thread) is refused; and
     * while such a refusal is being logged (a logger that re-enters is
     * refused without another line). */
    atomic_bool busy;
    atomic_bool refusing;
    struct tw_world_tuning t;      /* the methods' parameters (runtime/internal.h) */
    struct tw_renderer *renderer;
    /* What the world shows: the host's provider, or one made of the fixed
     * tileset and its selection. */
    struct tw_tile_provider provider;
    struct tw_bvh **bvhs;           /* one per shared prototype */
    uint32_t shared_count;          /* shared prototypes (contents 0 .. shared_count - 1) */
    uint64_t shared_cpu, shared_gpu;/* bytes of the shared content, counted once */
    /* Levels of detail (DESIGN §17): on when max_screen_error > 0. */
    bool lod_on;
    struct tw_file_cache *lods_store;  /* the levels kept on disk (tw_lods_store()); NULL: not */
    bool lod_full;                  /* a full-detail pass is drawing: level 0 everywhere */
    float lod_px_per_m;             /* the view's pixels per metre at a distance of 1 m */
    const struct tw_lods *lods;     /* of the shared prototypes: kept with their tileset,
                                       shared with the other worlds over it (never NULL) */
    struct tw_bvh **lod_bvhs;       /* one per level */
    uint32_t lod_count;             /* levels of the shared prototypes */
    uint32_t lod_first;             /* the renderer's content of the first level */
    float lod_least_error;          /* the least error of any shared prototype's first
                                       level (INFINITY: none has one) */
    struct tw_stream *stream;       /* tiles of their own (NULL: none can exist) */
    struct tw_world_hlod hlod;      /* blocks' proxies (none unless tuned) */
    struct tw_objects *objects;     /* moving objects (NULL: no object models) */
    uint64_t frame_serial;          /* every frame of every method: the streaming clock */
    struct tw_tile_event *events;   /* of the last frame */
    size_t event_count, event_cap;
    struct tw_tile_event *next_events;  /* since the last frame */
    size_t next_event_count, next_event_cap;
    struct tw_cull_grid grid;
    struct tw_cull_driver *fixed_set;  /* tw_world_frame_fixed */
    struct tw_drawn_cluster *fixed_order;  /* its set, grouped tile by tile */
    size_t fixed_order_cap;
    bool record_draws;
    struct tw_drawn_cluster *drawn; /* with levels of detail: the last frame's draws as
                                       tw_world_drawn() gives them */
    size_t drawn_count, drawn_cap;
    struct tw_oracle oracle;
    struct tw_lod_image lod_image;  /* with verify and levels of detail */

    struct tw_calibration calibration;  /* DESIGN §14: what queries and draws cost */
    uint32_t calibration_first;         /* the shared tileset's first content */
    struct tw_debug_state debug;    /* untouched while debug.flags is 0 */
    /* Views (a camera each, README "Several views"): the world's own, and
     * its viewports'. cur: the one a call draws with; last: the one of the
     * last frame, which the getters read. */
    struct tw_view_state own;
    struct tw_view_state *cur, *last;
    uint32_t view_count;            /* the own view and the viewports alive */
    struct tw_viewport *viewports;
};

/* How the oracle compares depths: the frame's near and far planes, the
 * depth convention, the relative tolerance. */
struct tw_oracle_depth {
    double n, f;
    bool reversed;
    double tol;
};

/* oracle.c */
/* Eye distance (metres along the view axis) of window depth d, near and far
 * planes n and f, depth reversed or not. */
double tw_eye_distance(double d, double n, double f, bool reversed);
int tw_oracle_init(struct tw_world *w);
void tw_oracle_finish(struct tw_oracle *o);
/* The ID pass of view v: which clusters have visible pixels, how many. Untimed. */
int tw_oracle_pass(struct tw_world *w, const struct tw_view *v);
/* Orders a set of clusters tile by tile, tiles in the order they first
 * appear; within a tile, front_to_back: by distance from v (to the nearest
 * point of the cluster's box), ties by cluster index, as the oracle draws
 * its set; else in the set's own order. */
int tw_oracle_order(struct tw_world *w, const struct tw_view *v, struct tw_drawn_cluster *set,
                    size_t count, bool front_to_back);
/* The box oracle's set for the view of the last ID pass: every cluster vfc
 * draws that is visible or whose own box shows in front of the pass's depth
 * at some pixel centre (or lies within the near plane's reach), ordered as
 * the oracle orders its set. What any conservative method that culls by
 * querying or depth-testing boxes containing the clusters' own must draw. */
int tw_oracle_box_set(struct tw_world *w, const struct tw_view *v);
/* Compares what the last frame drew with the last ID pass. */
void tw_oracle_compare(struct tw_world *w, struct tw_frame_stats *st);

/* lod-image.c */
/* Draws v at full detail (untimed) and keeps its image and depth. */
int tw_lod_image_full_pass(struct tw_world *w, const struct tw_view *v);
/* Compares the frame just drawn with the last full-detail pass: st's
 * lod_pixels and lod_depth_m. */
int tw_lod_image_compare(struct tw_world *w, const struct tw_view *v, struct tw_frame_stats *st);
void tw_lod_image_finish(struct tw_lod_image *li);

/* world-tiles.c */
/* Whether a cell in view of v may be drawn at a coarser level (always, for
 * a world with generated tiles). */
int tw_world_levels_in_view(struct tw_world *w, const struct tw_view *v, bool *any);
/* The provider the world shows, checked: the host's, or one made of the
 * fixed tileset and its selection. */
int tw_world_resolve_provider(struct tw_world *w);
/* Starts the stream of the provider's own tiles, handing them to the
 * renderer's GPU store. Between enter and leave. */
int tw_world_start_stream(struct tw_world *w);
/* The tile source the culling reads (struct tw_cull_source; ctx is the world). */
int tw_world_get_tile(void *ctx, struct tw_cell cell, uint32_t node_level, float distance,
                      unsigned flags,
                      struct tw_cull_tile *out);
void tw_world_prefetch_tile(void *ctx, struct tw_cell cell, uint32_t node_level, float distance);
/* The settings of a stream of the world's: tiles of provider, handed to
 * the GPU store, with the world's workers, policy, budgets and levels of
 * detail; its instance keys from key_base on. */
struct tw_stream_settings tw_world_stream_settings(struct tw_world *w,
                                                   const struct tw_tile_provider *provider,
                                                   uint32_t key_base);

/* world-hlod.c */
/* The levels of hierarchical cells the world asks for, cells included
 * (< 2: none): the tuning's, or the provider's own coarser levels where the
 * tuning says nothing (not with moving objects, nor in host rendering);
 * none without levels of detail. */
uint32_t tw_world_hlod_wanted(const struct tw_world *w);
/* Makes the streams of the blocks (the library's proxies, or a provider's
 * own levels) that tw_world_hlod_wanted() asks for. Between enter and
 * leave. */
int tw_world_hlod_start(struct tw_world *w);
/* Stops them; returns how many of their threads were left behind. */
uint32_t tw_world_hlod_stop(struct tw_world *w);
/* Before a frame, after the view (its focal length) is known: the grid's
 * levels and their radii, and the proxy streams' frame. */
void tw_world_hlod_begin_frame(struct tw_world *w);
/* The tile of node (cell, level >= 1): its block's proxy. */
int tw_world_hlod_get(struct tw_world *w, struct tw_cell cell, uint32_t level, float distance,
                      unsigned flags, float max_error, struct tw_cull_tile *out);
void tw_world_hlod_prefetch(struct tw_world *w, struct tw_cell cell, uint32_t level,
                            float distance);
/* Adds the proxies' bytes. */
void tw_world_hlod_bytes(const struct tw_world *w, uint64_t *cpu, uint64_t *gpu);
/* Evicts proxies not drawn this frame until excess bytes are freed; returns
 * the bytes freed. */
uint64_t tw_world_hlod_trim(struct tw_world *w, uint64_t excess);
/* Adds the proxy streams' counters of the frame to st (loads, evictions,
 * uploads, tiles on their way) and counts in bytes_needed only the proxies
 * the frame used. */
void tw_world_hlod_stats(const struct tw_world *w, struct tw_frame_stats *st);
/* Drops the proxies of the blocks holding a cell of [lo, hi]. */
void tw_world_hlod_invalidate(struct tw_world *w, struct tw_cell lo, struct tw_cell hi);
/* Requests the tiles the camera would need a second ahead along its motion
 * (DESIGN §12), nearest first, behind everything the frame asked for. */
void tw_world_look_ahead(struct tw_world *w, const struct tw_view *v);
/* Over budget, the least recently drawn tiles go, then the oldest culling
 * state of the other methods, then of this one; what this frame drew stays.
 * Fills the byte and streaming counters of st. */
void tw_world_keep_budget(struct tw_world *w, const struct method_state *ms,
                          struct tw_frame_stats *st);

/* objects.c: moving objects (README "Moving objects") */
/* Uploads the object models of the settings (none: nothing); between enter
 * and leave. */
int tw_objects_create(struct tw_world *w);
void tw_objects_destroy(struct tw_world *w);
/* Before a frame: the moves since the last one into the cells' groups and
 * BVHs, and the grid's common box. */
int tw_objects_apply(struct tw_world *w);
void tw_objects_stats(const struct tw_world *w, struct tw_frame_stats *st);
/* Heap bytes of the objects, their groups and composites. */
uint64_t tw_objects_bytes(const struct tw_world *w);
/* tile, the cell's (proto NULL: none), joined to the cell's objects, if
 * it has any. */
int tw_objects_tile(struct tw_world *w, struct tw_cell cell, struct tw_cull_tile *tile);
/* Forgets what was made of the tiles of [lo, hi] with objects. */
void tw_objects_invalidate(struct tw_world *w, struct tw_cell lo, struct tw_cell hi);

/* debug.c */
void tw_debug_finish(struct tw_world *w);
/* After the timed part of a frame: the boxes of the debug views that are on. */
int tw_debug_collect(struct tw_world *w, const struct method_state *ms, const struct tw_view *v);

/* The view states of w, the own first: *k from 0, NULL after the last. */
struct tw_view_state *tw_world_next_view(struct tw_world *w, struct tw_viewport **k,
                                         bool *started);
/* The first streaming frame whose draws the budget keeps: a tile drawn by
 * the latest frame of any view stays (each view draws in turn). */
uint64_t tw_world_keep_from(const struct tw_world *w);

/* The thread contract: every call that changes the world, draws or reads
 * its images begins with tw_world_enter(w, "render a frame", gl) and ends
 * with tw_world_leave(w, gl) when it returned TW_OK. Refused (TW_ERR_STATE,
 * one line logged: "cannot <what>: <why>"): a call while another runs on the
 * world (re-entered from a callback, or from a second thread); and with gl,
 * one whose thread does not have the world's context current. With gl the
 * renderer is entered too (the host's GL state saved). */
int tw_world_enter(struct tw_world *w, const char *call, bool gl);
void tw_world_leave(struct tw_world *w, bool gl);

#endif
