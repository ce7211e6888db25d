/*
 * Tile streaming (DESIGN §12, §13): the tiles a provider makes for cells of
 * their own, generated, finished and given a BVH on a pool of worker
 * threads, uploaded on the render thread under a per-frame budget, held in
 * a byte-budgeted cache. Private to runtime/. The stream knows no GL: a
 * finished tile goes to a sink (the world's GPU store), which gives back
 * the number the tile is drawn by.
 *
 * Threads: one render thread owns the stream and calls every function here;
 * workers only run provider->generate(), tw_tileset_finish() and the BVH
 * build on plain data, and hand results back through one lock.
 */
#ifndef TW_RUNTIME_STREAM_H
#define TW_RUNTIME_STREAM_H

#include "bvh/bvh.h"
#include "cull/cull.h"
#include "tileworld/runtime.h"

#include <stdatomic.h>

struct tw_lods;

/* Where finished tiles go, on the render thread. upload() takes a finished
 * tileset and one BVH per prototype (all stay the stream's) and returns the
 * content number its first prototype is drawn by (the others follow) and
 * the GPU bytes it holds, or an error (the tile is then refused); release()
 * frees what upload() made. A tile is one upload, its levels of detail
 * another. */
struct tw_tile_sink {
    int (*upload)(void *user, const struct tw_tileset *ts, const struct tw_bvh *const *bvhs,
                  uint32_t *content, uint64_t *bytes_gpu);
    void (*release)(void *user, uint32_t content);
    /* Contents first .. first + count - 1 are base's levels of detail. */
    void (*levels)(void *user, uint32_t base, uint32_t first, uint32_t count);
    /* May be NULL. The tile uploaded as content (and its levels, NULL
     * without) is ready; data: what the hooks' prepare_worker made for it.
     * Returns more GPU bytes the tile holds (the host's). */
    uint64_t (*ready)(void *user, uint32_t content, const struct tw_tileset *ts,
                      const struct tw_tileset *levels, void *data);
    void *user;
};

/* A host's part in making tiles: prepare_worker runs on the worker at the
 * end of a job that made its tile (never for a worker left behind);
 * discard frees what it made for a tile dropped before its upload (render
 * thread). */
struct tw_stream_hooks {
    void *(*prepare_worker)(void *user, struct tw_cell cell, const struct tw_tileset *ts,
                            const struct tw_tileset *levels);
    void (*discard)(void *user, void *data);
    void *user;
};

struct tw_stream_settings {
    const struct tw_tile_provider *provider;   /* borrowed */
    struct tw_tile_sink sink;
    struct tw_bvh_settings bvh;
    uint32_t workers;                /* threads; 0: none, every tile is made on the render thread */
    enum tw_stream_policy policy;
    uint64_t upload_bytes;           /* per frame, of finished tiles not yet needed */
    double upload_ms;                /* per frame, likewise */
    uint32_t cancel_after;           /* a request unwanted for this many frames is dropped */
    uint32_t evict_after;            /* a tile unwanted for this many frames is evicted */
    uint64_t budget;                 /* the cache's budget (0: none): prefetches stop
                                        when the tiles held and on their way would
                                        fill it */
    uint32_t key_base;               /* instance keys of own tiles start here (above the
                                        shared contents' numbers) */
    bool lods;                       /* build each tile's levels of detail (DESIGN §17) */
    struct tw_file_cache *lods_store; /* where they are kept on disk (tw_lods_store());
                                        NULL: nowhere */
    /* Makes a tile's levels of detail instead of tw_lods_build() (with
     * lods; NULL: that), on the worker, for the tile of cell that ts
     * holds; levels_user its user. Same contract as tw_lods_build(): out
     * zeroed on an error, TW_ERR_STATE when stop is set. */
    int (*levels)(void *user, struct tw_cell cell, const struct tw_tileset *ts,
                  const atomic_bool *stop, struct tw_lods *out);
    void *levels_user;
    uint32_t stop_ms;                /* how long destroy waits for jobs still running;
                                        0: TW_STREAM_STOP_MS */
    uint32_t retry_after;            /* a refused tile is asked again this many frames
                                        later, twice as late each time (0: never) */
    uint32_t retry_max;              /* at most this many times while in sight */
    uint64_t max_triangles;          /* a tile with more triangles is refused (0: none) */
    uint64_t max_bytes;              /* a tile whose CPU bytes exceed this is refused
                                        (0: none) */
    struct tw_stream_hooks hooks;    /* all NULL: none */
    const struct tw_log *log;        /* borrowed; called on the render thread only */
};

/* Counters of one frame (reset by tw_stream_begin_frame). */
struct tw_stream_stats {
    uint32_t loads_requested;        /* requests made (get or prefetch of an absent tile) */
    uint32_t loads_done;             /* tiles that became ready */
    uint32_t evictions;
    uint32_t refused;                /* tiles out of bound or whose generation failed */
    uint32_t waits;                  /* get() that blocked for a tile (policy wait) */
    double ms_upload;                /* on the render thread, uploading */
    double ms_wait;                  /* on the render thread, blocked on or making tiles */
    uint64_t bytes_used;             /* of the ready tiles this frame used (CPU + GPU) */
    uint64_t bytes_loading;          /* CPU bytes of tiles made and waiting for their upload */
    uint32_t tiles_loading;          /* and their number */
};

/* Totals since the stream was created, and latencies. */
struct tw_stream_totals {
    uint64_t loads_requested, loads_done, evictions, reloads, refused;
    uint64_t latency_frames_sum;     /* request to ready, in frames */
};

struct tw_stream;

/* The default of tw_stream_settings.stop_ms. */
#define TW_STREAM_STOP_MS 5000u

int tw_stream_create(const struct tw_stream_settings *s, struct tw_stream **out);
/* Stops the workers, frees every tile (GL buffers too: between enter and
 * leave). A worker still in a job after stop_ms is left behind: logged,
 * detached, and from then on it touches only what it owns (its copy of
 * the provider, its builder, its result), and the provider's own code and
 * user data. Returns how many were left behind. Accepts NULL (0). */
uint32_t tw_stream_destroy(struct tw_stream *s);

/* Starts frame: collects finished tiles, uploads what the per-frame budget
 * allows (oldest request first), cancels requests no longer wanted.
 * Between enter and leave. */
void tw_stream_begin_frame(struct tw_stream *s, uint64_t frame);

/* The tile of cell (content TW_TILE_OWN): TW_OK with *out filled; or
 * TW_TILE_PENDING (requested; under policy skip, or with
 * TW_TILE_SOURCE_RESIDENT); or a negative error. Under policy wait the call
 * makes the tile ready before it returns (running its job here if no
 * worker has started it). A refused tile reads as an empty one: TW_OK with
 * out->proto NULL. The tile is given at the coarsest of its levels of
 * detail whose error is at most max_error metres (0: full detail); each
 * level has its own key. Between enter and leave. */
int tw_stream_get(struct tw_stream *s, struct tw_cell cell, float distance, unsigned flags,
                  float max_error, struct tw_cull_tile *out);
/* Requests cell's tile unless it is there or on its way. */
void tw_stream_prefetch(struct tw_stream *s, struct tw_cell cell, float distance);
/* Marks the tile of cell drawn this frame (kept against eviction). */
void tw_stream_touch(struct tw_stream *s, struct tw_cell cell);
/* True if the stream holds (or is making) a tile for cell. */
bool tw_stream_has(const struct tw_stream *s, struct tw_cell cell);
/* Drops cell's tile (and a request or a job in flight: its result is
 * discarded); the next get() makes it afresh with a new instance key.
 * Between enter and leave. */
void tw_stream_invalidate(struct tw_stream *s, struct tw_cell cell);
/* A refused cell's tile is asked for again when next wanted; false if the
 * cell's tile was not refused. Between enter and leave. */
bool tw_stream_retry(struct tw_stream *s, struct tw_cell cell);
/* Drops the tile of every cell in [lo, hi] (inclusive) that the stream holds. */
void tw_stream_invalidate_rect(struct tw_stream *s, struct tw_cell lo, struct tw_cell hi);

/* Bytes of the ready tiles alone, CPU + GPU. */
uint64_t tw_stream_tile_bytes(const struct tw_stream *s);
/* Bytes of the ready tiles and the stream's own tables, on the CPU
 * (geometry, clusters, BVHs, tables) and the GPU (their buffers). */
void tw_stream_bytes(struct tw_stream *s, uint64_t *cpu, uint64_t *gpu);

/* Evicts the least recently drawn ready tiles (never one drawn in frame,
 * never one loading) while excess > 0 bytes; returns the bytes freed. Each
 * eviction is reported through evicted (may be NULL). Between enter and
 * leave. */
typedef void (*tw_stream_evicted_fn)(void *user, struct tw_cell cell, uint64_t bytes);
uint64_t tw_stream_trim(struct tw_stream *s, uint64_t excess, uint64_t frame,
                        tw_stream_evicted_fn evicted, void *user);

/* Views whose frames take turns on the stream: a request or a tile is kept
 * as many frames longer (cancel_after, evict_after count one view's frames). */
void tw_stream_set_views(struct tw_stream *s, uint32_t views);

/* Ready events: tiles that became ready in the current frame, and refusals. */
typedef void (*tw_stream_event_fn)(void *user, const struct tw_tile_event *e);
void tw_stream_set_events(struct tw_stream *s, tw_stream_event_fn fn, void *user);

const struct tw_stream_stats *tw_stream_stats(const struct tw_stream *s);
const struct tw_stream_totals *tw_stream_totals(const struct tw_stream *s);
/* Tiles ready, and requests queued or running. */
uint32_t tw_stream_ready_count(const struct tw_stream *s);
uint32_t tw_stream_loading_count(const struct tw_stream *s);

#endif
