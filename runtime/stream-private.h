/*
 * The stream's insides, shared by stream.c (the entries, the cache, the
 * frame) and workers.c (the worker pool and the job each worker runs).
 * Private to runtime/.
 *
 * Every cell with a tile of its own has an entry. What the render thread
 * alone reads and writes (whether the tile is ready, its GPU content, its
 * bytes, when it was wanted and drawn) lives beside what the workers touch
 * (the job: queued, running, done, and its result), which only ever changes
 * under the pool's one lock. Workers never see an entry's address: the
 * entry array may grow while they work, so they name entries by index.
 */
#ifndef TW_RUNTIME_STREAM_PRIVATE_H
#define TW_RUNTIME_STREAM_PRIVATE_H

#include <pthread.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "runtime/stream.h"

/* R_EMPTY: the provider's generate() found nothing there (TW_GENERATE_EMPTY). */
enum render_state { R_FREE = 0, R_LOADING, R_READY, R_REFUSED, R_EMPTY };
enum job_state { J_NONE = 0, J_QUEUED, J_RUNNING, J_DONE };

struct job_result {
    struct tw_tileset *ts;
    struct tw_bvh *bvh;
    struct tw_lods lods;         /* its levels of detail (none unless the stream's lods) */
    struct tw_bvh **lod_bvhs;    /* one per level */
    uint64_t bytes_cpu;          /* what ts, bvh and the levels cost (0 on failure) */
    int err;
    bool empty;                  /* generate() found the cell empty: no ts */
    void *host_data;             /* what the hooks' prepare_worker made (NULL: none) */
    char message[256];
};

struct entry {
    /* Render thread only. */
    struct tw_cell cell;
    enum render_state rstate;
    uint32_t key;
    uint32_t content;            /* R_READY: the renderer's content */
    uint64_t bytes_cpu, bytes_gpu;
    uint64_t request_frame, wanted_frame, drawn_frame;
    struct tw_tileset *ts;       /* R_READY: owned */
    struct tw_bvh *bvh;
    struct tw_lods lods;         /* R_READY: owned; levels of detail */
    struct tw_bvh **lod_bvhs;
    uint32_t lod_content;        /* R_READY with levels: the renderer's content of level 1 */
    uint32_t next_free;
    bool reload;                 /* this cell's tile had been evicted before */
    uint32_t attempts;           /* R_REFUSED: refusals in a row while in sight */
    uint64_t retry_frame;        /* R_REFUSED: asked again from this frame (0: never) */
    /* Under the lock. */
    enum job_state jstate;
    bool discard;                /* invalidated or cancelled while running: drop the result */
    float priority;
    uint64_t seq;
    struct job_result result;
};

/* What the workers share with the stream (see the top of the file). */
struct pool {
    pthread_mutex_t lock;
    pthread_cond_t work;                 /* a job was queued, or quit */
    pthread_cond_t done;                 /* a job finished, or a worker stopped
                                            (CLOCK_MONOTONIC, for the wait at destroy) */
    atomic_bool quit;                    /* set under the lock; a running job's levels
                                            read it without (tw_lods_build's stop) */
    uint32_t refs;                       /* the stream's, and one per worker thread */
};

struct worker {
    struct tw_stream *s;                 /* (lock) NULL once left behind */
    struct pool *pool;
    struct tw_tile_provider provider;    /* a copy: the world's may be gone when a job
                                            left behind comes back */
    struct tw_bvh_settings bvh;
    bool lods;                           /* build the tiles' levels of detail */
    struct tw_file_cache *lods_store;    /* and keep them there (may be NULL) */
    int (*levels)(void *user, struct tw_cell cell, const struct tw_tileset *ts,
                  const atomic_bool *stop, struct tw_lods *out);   /* or NULL */
    void *levels_user;
    uint64_t max_triangles, max_bytes;   /* caps of a tile (0: none) */
    struct tw_stream_hooks hooks;
    pthread_t thread;
    bool started;
    /* Under the lock. */
    bool busy;                           /* running a job on cell */
    struct tw_cell cell;
    bool stopped;                        /* out of its loop: can be joined */
    bool left_behind;                    /* the stream is gone: the thread owns this */
    /* The worker's own. */
    struct tw_bvh_builder *builder;
    char message[256];                   /* what the builder logged last */
};

struct tw_stream {
    struct tw_stream_settings set;
    const struct tw_tile_provider *p;
    uint64_t frame;
    uint32_t views;                      /* frames of this many views take turns: the
                                            frame counts (cancel, evict) stretch by it */

    /* Entries: render thread, except their job fields (lock). The array is
     * reallocated only under the lock. */
    struct entry *entries;
    uint32_t entry_count, entry_cap, free_head;
    struct tw_cell_map *by_cell;         /* cell -> entry */
    struct tw_cell_map *generations;     /* cell -> times invalidated (only cells ever invalidated) */
    struct tw_cell_map *evicted;         /* cells whose tile was evicted: a later load is a reload */
    uint32_t ready, loading;
    uint64_t bytes_cpu, bytes_gpu;

    /* Jobs (under pool->lock). */
    struct pool *pool;
    uint32_t *heap;                      /* queued entries, by priority then seq */
    uint32_t heap_count, heap_cap;
    uint32_t *finished;                  /* entries whose job is done, not yet collected */
    uint32_t finished_count, finished_cap;
    uint64_t seq;

    /* Done, collected, waiting for their upload (render thread). */
    uint32_t *to_upload;
    uint32_t to_upload_count, to_upload_cap;

    struct worker **workers;             /* NULL where one was left behind */
    uint32_t worker_count;
    struct worker inline_worker;         /* the render thread's own builder */

    tw_stream_event_fn on_event;
    void *event_user;
    bool quiet_nomem;                    /* a refusal for lack of memory was logged: the
                                            next ones are only counted */
    struct tw_stream_stats stats;
    struct tw_stream_totals totals;
};

/* ---- workers.c ---------------------------------------------------------------------- */

/* Makes the tile of cell: generate into a fresh tileset, finish it, check it
 * against the provider's bound, pack it, build and pack its BVH. Any
 * thread; touches nothing but what wk owns. */
void tw_stream_job_run(struct worker *wk, struct tw_cell cell, struct job_result *r);
/* Frees what a result holds and zeroes it. */
void tw_stream_job_free(struct job_result *r);
/* Frees levels of detail and their BVHs, and zeroes them. */
void tw_stream_job_free_levels(struct tw_lods *lods, struct tw_bvh ***bvhs);
/* Queues entry index (lock held): false when the heap has no room (the job
 * then stays queued for the render thread to run when it is needed). */
bool tw_stream_jobs_push(struct tw_stream *s, uint32_t index);
/* Keeps only queued entries in the heap and restores its order after
 * priorities changed (lock held). */
void tw_stream_jobs_rebuild(struct tw_stream *s);
/* Makes the pool, the render thread's own builder (s->inline_worker) and
 * s->set.workers threads. On error what was made stays for
 * tw_stream_workers_stop() and tw_stream_pool_unref(). */
int tw_stream_workers_start(struct tw_stream *s);
/* Stops the workers: waits up to stop_ms for those in a job, then leaves
 * the ones still in it behind (detached, owning their worker record); joins
 * and frees the others and the render thread's builder. Returns how many
 * were left behind; their cells in cells. */
uint32_t tw_stream_workers_stop(struct tw_stream *s, char *cells, size_t cells_size);
/* Drops the stream's reference to the pool (the last reference frees it). */
void tw_stream_pool_unref(struct pool *pool);

#endif
