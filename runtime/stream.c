/*
 * Tile streaming (stream.h, DESIGN §12-§13).
 *
 * Every cell with a tile of its own has an entry. What the render thread
 * alone reads and writes (whether the tile is ready, its GL content, its
 * bytes, when it was wanted and drawn) lives beside what the workers touch
 * (the job: queued, running, done, and its result), which only ever changes
 * under the stream's one lock. Workers never see an entry's address: the
 * entry array may grow while they work, so they name entries by index.
 *
 * A job is a pure function of its cell: generate into a fresh tileset,
 * finish it, check it against the provider's bound, build its BVH. Under
 * policy wait the render thread runs a job itself when no worker has
 * started it yet, so a frame never waits behind less urgent work.
 *
 * A job runs on what its worker owns (a copy of the provider, its own BVH
 * builder, the result on its stack), so that a worker stuck in the
 * provider's generate() can be left behind when the stream is destroyed:
 * the lock and the conditions live in a block of their own (struct pool)
 * that the last of the stream and such workers frees, and a worker that
 * comes back to find itself left behind drops its result, frees what it
 * owns and ends without touching the stream again.
 */
#include "runtime/stream.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum render_state { R_FREE = 0, R_LOADING, R_READY, R_REFUSED };
enum job_state { J_NONE = 0, J_QUEUED, J_RUNNING, J_DONE };

struct job_result {
    struct tw_tileset *ts;
    struct tw_bvh *bvh;
    uint64_t bytes_cpu;          /* what ts and bvh cost (0 on failure) */
    int err;
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
    uint32_t next_free;
    bool reload;                 /* this cell's tile had been evicted before */
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
    bool quit;
    uint32_t refs;                       /* the stream's, and one per worker thread */
};

struct worker {
    struct tw_stream *s;                 /* (lock) NULL once left behind */
    struct pool *pool;
    struct tw_tile_provider provider;    /* a copy: the world's may be gone when a job
                                            left behind comes back */
    struct tw_bvh_settings bvh;
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
    struct tw_renderer *renderer;
    uint64_t frame;

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

/* ---- the job ------------------------------------------------------------------------ */

static void capture_log(void *user, enum tw_log_level level, const char *msg)
{
    struct worker *wk = user;
    if (level <= TW_LOG_WARN && wk->message[0] == '\0')
        snprintf(wk->message, sizeof(wk->message), "%s", msg);
}

static bool box_inside(const struct tw_box *b, const struct tw_box *bound)
{
    /* A hair of slack: a tile built to touch its bound exactly must not be
     * refused for the rounding of a transform. */
    for (int a = 0; a < 3; a++) {
        const float e = 1e-4f * fmaxf(1.0f, fabsf(bound->max[a] - bound->min[a]));
        if (b->min[a] < bound->min[a] - e || b->max[a] > bound->max[a] + e)
            return false;
    }
    return true;
}

static void fail(struct job_result *r, int err, const char *fmt, ...)
{
    r->err = err;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->message, sizeof(r->message), fmt, ap);
    va_end(ap);
}

/* Makes the tile of cell. Any thread; touches nothing but what wk owns
 * (the stream may be gone by the time generate() returns). */
static void run_job(struct worker *wk, struct tw_cell cell, struct job_result *r)
{
    const struct tw_tile_provider *p = &wk->provider;
    memset(r, 0, sizeof(*r));
    wk->message[0] = '\0';
    char name[64];
    snprintf(name, sizeof(name), "%lld,%lld", (long long)cell.i, (long long)cell.j);
    int err = tw_tileset_create(name, p->footprint[0], p->footprint[1], &r->ts);
    if (err) {
        fail(r, err, "cannot make a tileset: %s", tw_error_to_str(err));
        return;
    }
    err = p->generate(p->user, cell, r->ts);
    if (err) {
        fail(r, err, "the provider could not make it: %s", tw_error_to_str(err));
        goto out;
    }
    if (r->ts->prototype_count != 1) {
        fail(r, TW_ERR_INVALID, "the provider made %u prototypes for it (one is needed)",
             r->ts->prototype_count);
        goto out;
    }
    err = tw_tileset_finish(r->ts, p->max_cluster_triangles ? p->max_cluster_triangles : 2048);
    if (err) {
        fail(r, err, "the generated tile cannot be finished: %s", tw_error_to_str(err));
        goto out;
    }
    const struct tw_box *b = &r->ts->prototypes[0].box;
    if (!box_inside(b, &p->bound)) {
        fail(r, TW_ERR_LIMIT,
             "the tile's box [%g %g %g]-[%g %g %g] exceeds the provider's bound "
             "[%g %g %g]-[%g %g %g]",
             b->min[0], b->min[1], b->min[2], b->max[0], b->max[1], b->max[2], p->bound.min[0],
             p->bound.min[1], p->bound.min[2], p->bound.max[0], p->bound.max[1], p->bound.max[2]);
        goto out;
    }
    /* The tile lives long among the short-lived allocations that made it:
     * one block each for its tileset and its BVH, so that its eviction
     * returns whole pages (without: the heap kept 5-10 MiB of holes over
     * 10 km). Out of memory here leaves both as they are, still valid. */
    (void)tw_tileset_pack(&r->ts);
    err = tw_bvh_build(wk->builder, &r->ts->prototypes[0], &wk->bvh, &r->bvh);
    if (err) {
        fail(r, err, "its BVH cannot be built: %s", wk->message[0] ? wk->message
                                                                  : tw_error_to_str(err));
        goto out;
    }
    (void)tw_bvh_pack(&r->bvh);
    r->bytes_cpu = tw_tileset_bytes(r->ts) + r->bvh->bytes;
    return;
out:
    tw_bvh_destroy(r->bvh);
    r->bvh = NULL;
    tw_tileset_destroy(r->ts);
    r->ts = NULL;
}

static void free_result(struct job_result *r)
{
    tw_bvh_destroy(r->bvh);
    tw_tileset_destroy(r->ts);
    r->bvh = NULL;
    r->ts = NULL;
    r->bytes_cpu = 0;
}

/* ---- the job heap (lock held) ------------------------------------------------------- */

static bool before(const struct tw_stream *s, uint32_t a, uint32_t b)
{
    const struct entry *x = &s->entries[a], *y = &s->entries[b];
    if (x->priority != y->priority)
        return x->priority < y->priority;
    return x->seq < y->seq;
}

static void sift_down(struct tw_stream *s, uint32_t k)
{
    for (;;) {
        uint32_t m = k;
        const uint32_t l = 2 * k + 1, r = l + 1;
        if (l < s->heap_count && before(s, s->heap[l], s->heap[m]))
            m = l;
        if (r < s->heap_count && before(s, s->heap[r], s->heap[m]))
            m = r;
        if (m == k)
            return;
        const uint32_t t = s->heap[k];
        s->heap[k] = s->heap[m];
        s->heap[m] = t;
        k = m;
    }
}

static void sift_up(struct tw_stream *s, uint32_t k)
{
    while (k > 0) {
        const uint32_t parent = (k - 1) / 2;
        if (!before(s, s->heap[k], s->heap[parent]))
            return;
        const uint32_t t = s->heap[k];
        s->heap[k] = s->heap[parent];
        s->heap[parent] = t;
        k = parent;
    }
}

/* Keeps only queued entries, and restores the order after priorities changed. */
static void rebuild_heap(struct tw_stream *s)
{
    uint32_t n = 0;
    for (uint32_t k = 0; k < s->heap_count; k++)
        if (s->entries[s->heap[k]].jstate == J_QUEUED)
            s->heap[n++] = s->heap[k];
    /* An entry queued twice (queued, taken, queued again) keeps one place. */
    s->heap_count = n;
    for (uint32_t k = s->heap_count / 2; k-- > 0;)
        sift_down(s, k);
}

/* The next queued entry, or UINT32_MAX. Entries taken by the render thread
 * stay in the heap until popped (lazy deletion). */
static uint32_t pop_job(struct tw_stream *s)
{
    while (s->heap_count > 0) {
        const uint32_t top = s->heap[0];
        s->heap[0] = s->heap[--s->heap_count];
        sift_down(s, 0);
        if (s->entries[top].jstate == J_QUEUED)
            return top;
    }
    return UINT32_MAX;
}

/* Files a finished job's result (lock held). */
static void finish_job(struct tw_stream *s, uint32_t index, struct job_result *r)
{
    struct entry *e = &s->entries[index];
    e->result = *r;
    e->jstate = J_DONE;
    if (tw_array_reserve_u32((void **)&s->finished, &s->finished_cap, s->finished_count + 1,
                             sizeof(*s->finished), 64) == TW_OK) {
        s->finished[s->finished_count++] = index;
    } else {
        /* Out of memory to file it: the entry is collected when it is
         * waited on or invalidated; never lost. */
    }
    pthread_cond_broadcast(&s->pool->done);
}

static void pool_unref(struct pool *pool)
{
    pthread_mutex_lock(&pool->lock);
    const bool last = --pool->refs == 0;
    pthread_mutex_unlock(&pool->lock);
    if (!last)
        return;
    pthread_cond_destroy(&pool->work);
    pthread_cond_destroy(&pool->done);
    pthread_mutex_destroy(&pool->lock);
    free(pool);
}

static void *worker_main(void *arg)
{
    struct worker *wk = arg;
    struct pool *pool = wk->pool;
    pthread_mutex_lock(&pool->lock);
    for (;;) {
        uint32_t index = UINT32_MAX;
        /* quit is set before any worker is left behind: wk->s is valid here. */
        while (!pool->quit && (index = pop_job(wk->s)) == UINT32_MAX)
            pthread_cond_wait(&pool->work, &pool->lock);
        if (pool->quit)
            break;
        struct entry *e = &wk->s->entries[index];
        e->jstate = J_RUNNING;
        const struct tw_cell cell = e->cell;
        wk->cell = cell;
        wk->busy = true;
        pthread_mutex_unlock(&pool->lock);
        struct job_result r;
        run_job(wk, cell, &r);
        pthread_mutex_lock(&pool->lock);
        wk->busy = false;
        if (wk->left_behind) {
            free_result(&r);
            break;
        }
        finish_job(wk->s, index, &r);
    }
    const bool left_behind = wk->left_behind;
    wk->stopped = true;
    pthread_cond_broadcast(&pool->done);
    pthread_mutex_unlock(&pool->lock);
    if (left_behind) {
        /* Detached by tw_stream_destroy(): what is left is this thread's. */
        tw_bvh_builder_destroy(wk->builder);
        free(wk);
    }
    /* Otherwise joined by tw_stream_destroy(), which frees wk. */
    pool_unref(pool);
    return NULL;
}

/* ---- entries (render thread) ----------------------------------------------------------- */

static struct entry *find(const struct tw_stream *s, struct tw_cell cell, uint32_t *index)
{
    const uint64_t *v = tw_cell_map_find(s->by_cell, cell);
    if (!v)
        return NULL;
    *index = (uint32_t)*v;
    return &s->entries[*index];
}

static void event(struct tw_stream *s, struct tw_cell cell, enum tw_tile_event_kind kind,
                  uint64_t bytes)
{
    const struct tw_tile_event e = {cell, kind, bytes, 0, false};
    if (s->on_event)
        s->on_event(s->event_user, &e);
}

/* A fresh entry for cell (its map entry made too), or NULL. */
static struct entry *new_entry(struct tw_stream *s, struct tw_cell cell, uint32_t *index)
{
    uint32_t k;
    if (s->free_head != UINT32_MAX) {
        k = s->free_head;
        s->free_head = s->entries[k].next_free;
    } else {
        if (s->entry_count == s->entry_cap) {
            const uint32_t cap = s->entry_cap ? 2 * s->entry_cap : 64;
            pthread_mutex_lock(&s->pool->lock);
            struct entry *e = realloc(s->entries, sizeof(*e) * cap);
            if (e) {
                s->entries = e;
                s->entry_cap = cap;
            }
            pthread_mutex_unlock(&s->pool->lock);
            if (!e)
                return NULL;
        }
        k = s->entry_count++;
    }
    if (tw_cell_map_set(s->by_cell, cell, k)) {
        s->entries[k].next_free = s->free_head;
        s->free_head = k;
        return NULL;
    }
    struct entry *e = &s->entries[k];
    /* A worker may still compare this slot's old priority in the heap
     * (lazy deletion): the job fields change under the lock only. */
    pthread_mutex_lock(&s->pool->lock);
    memset(e, 0, sizeof(*e));
    pthread_mutex_unlock(&s->pool->lock);
    e->cell = cell;
    const uint64_t *gen = tw_cell_map_find(s->generations, cell);
    e->key = s->set.key_base + (gen ? (uint32_t)*gen : 0u);
    *index = k;
    return e;
}

/* Returns entry k to the free list (not in the map any more). */
static void release_entry(struct tw_stream *s, uint32_t k)
{
    struct entry *e = &s->entries[k];
    e->rstate = R_FREE;
    e->next_free = s->free_head;
    s->free_head = k;
}

/* Requests cell's tile: a new entry with its job queued. */
static struct entry *request(struct tw_stream *s, struct tw_cell cell, float distance,
                             uint32_t *index)
{
    struct entry *e = new_entry(s, cell, index);
    if (!e)
        return NULL;
    e->rstate = R_LOADING;
    e->request_frame = e->wanted_frame = s->frame;
    e->reload = tw_cell_map_find(s->evicted, cell) != NULL;
    s->loading++;
    s->stats.loads_requested++;
    s->totals.loads_requested++;
    pthread_mutex_lock(&s->pool->lock);
    e->priority = distance;
    e->seq = s->seq++;
    e->jstate = J_QUEUED;
    if (tw_array_reserve_u32((void **)&s->heap, &s->heap_cap, s->heap_count + 1, sizeof(*s->heap),
                             64) == TW_OK) {
        s->heap[s->heap_count] = *index;
        sift_up(s, s->heap_count++);
        pthread_cond_signal(&s->pool->work);
    }
    /* Without room in the heap the job stays queued for the render thread
     * to run when the tile is needed. */
    pthread_mutex_unlock(&s->pool->lock);
    return e;
}

/* Frees what a ready tile holds. */
static void drop_ready(struct tw_stream *s, struct entry *e)
{
    tw_renderer_release(s->renderer, e->content);
    tw_bvh_destroy(e->bvh);
    tw_tileset_destroy(e->ts);
    e->bvh = NULL;
    e->ts = NULL;
    s->bytes_cpu -= e->bytes_cpu;
    s->bytes_gpu -= e->bytes_gpu;
    s->ready--;
}

/* Takes a done job's result into the entry: uploaded and ready, or
 * refused. Render thread; between enter and leave. */
static int make_ready(struct tw_stream *s, uint32_t k)
{
    struct entry *e = &s->entries[k];
    if (e->rstate != R_LOADING)
        return TW_OK;
    pthread_mutex_lock(&s->pool->lock);
    struct job_result r = e->result;
    memset(&e->result, 0, sizeof(e->result));
    e->jstate = J_NONE;
    pthread_mutex_unlock(&s->pool->lock);
    s->loading--;
    const double t0 = tw_clock_monotonic_ms();
    if (!r.err) {
        const struct tw_bvh *bvhs[1] = {r.bvh};
        r.err = tw_renderer_upload(s->renderer, r.ts, bvhs, &e->content, &e->bytes_gpu);
        if (r.err)
            snprintf(r.message, sizeof(r.message), "cannot upload it: %s",
                     tw_error_to_str(r.err));
    }
    if (r.err) {
        /* Out of memory comes tile after tile: one line, the rest counted. */
        if (r.err != TW_ERR_NOMEM || !s->quiet_nomem)
            tw_log_printf(s->set.log, TW_LOG_ERROR, "provider %s: cell (%lld, %lld): %s%s",
                          s->p->name ? s->p->name : "", (long long)e->cell.i,
                          (long long)e->cell.j, r.message,
                          r.err == TW_ERR_NOMEM ? " (further tiles refused for lack of memory "
                                                  "are counted, not logged)" : "");
        free_result(&r);
        s->stats.refused++;
        s->totals.refused++;
        const struct tw_cell cell = e->cell;
        if (r.err == TW_ERR_NOMEM) {
            /* The machine's failure, not the cell's: nothing is kept, the
             * cell is asked for again when it is next wanted, and a frame
             * that waits for it fails (its image would lack the tile). */
            s->quiet_nomem = true;
            tw_cell_map_remove(s->by_cell, cell);
            release_entry(s, k);
            event(s, cell, TW_TILE_REFUSED, 0);
            return TW_ERR_NOMEM;
        }
        e->rstate = R_REFUSED;
        event(s, cell, TW_TILE_REFUSED, 0);
        return TW_OK;
    }
    e->ts = r.ts;
    e->bvh = r.bvh;
    e->bytes_cpu = r.bytes_cpu;
    e->rstate = R_READY;
    s->bytes_cpu += e->bytes_cpu;
    s->bytes_gpu += e->bytes_gpu;
    s->ready++;
    s->stats.loads_done++;
    s->totals.loads_done++;
    s->totals.latency_frames_sum += s->frame - e->request_frame;
    if (e->reload) {
        s->totals.reloads++;
        tw_cell_map_remove(s->evicted, e->cell);
    }
    s->stats.ms_upload += tw_clock_monotonic_ms() - t0;
    const struct tw_tile_event ev = {e->cell, TW_TILE_READY, e->bytes_cpu + e->bytes_gpu,
                                     (uint32_t)(s->frame - e->request_frame), e->reload};
    if (s->on_event)
        s->on_event(s->event_user, &ev);
    return TW_OK;
}

/* Moves the workers' finished jobs to the upload list; drops the results
 * of discarded ones. */
static void collect(struct tw_stream *s)
{
    pthread_mutex_lock(&s->pool->lock);
    uint32_t n = s->finished_count;
    if (tw_array_reserve_u32((void **)&s->to_upload, &s->to_upload_cap, s->to_upload_count + n,
                             sizeof(*s->to_upload), 64) != TW_OK)
        n = 0;      /* collected another frame */
    for (uint32_t k = 0; k < n; k++) {
        const uint32_t index = s->finished[k];
        struct entry *e = &s->entries[index];
        if (e->discard) {
            free_result(&e->result);
            e->jstate = J_NONE;
            e->discard = false;
            e->next_free = s->free_head;
            s->free_head = index;
            e->rstate = R_FREE;
        } else if (e->jstate == J_DONE) {
            s->to_upload[s->to_upload_count++] = index;
        }
    }
    if (n > 0 && n < s->finished_count)
        memmove(s->finished, s->finished + n, sizeof(*s->finished) * (s->finished_count - n));
    s->finished_count -= n;
    pthread_mutex_unlock(&s->pool->lock);
}

/* Drops entry k wherever its job is; the cell is out of the map after. */
static void drop_entry(struct tw_stream *s, uint32_t k)
{
    struct entry *e = &s->entries[k];
    tw_cell_map_remove(s->by_cell, e->cell);
    if (e->rstate == R_READY) {
        drop_ready(s, e);
        release_entry(s, k);
        return;
    }
    if (e->rstate == R_REFUSED) {
        release_entry(s, k);
        return;
    }
    /* Loading: queued (left in the heap, skipped there), running or done
     * but not collected (its result is discarded when collected, and the
     * slot freed then), or done and collected (waiting for its upload). */
    s->loading--;
    pthread_mutex_lock(&s->pool->lock);
    bool later = e->jstate == J_RUNNING;
    if (e->jstate == J_DONE) {
        for (uint32_t q = 0; q < s->finished_count && !later; q++)
            later = s->finished[q] == k;
        if (!later)
            free_result(&e->result);
    }
    if (later)
        e->discard = true;
    else
        e->jstate = J_NONE;
    pthread_mutex_unlock(&s->pool->lock);
    e->rstate = R_FREE;
    if (later)
        return;
    for (uint32_t q = 0; q < s->to_upload_count; q++)
        if (s->to_upload[q] == k) {
            s->to_upload[q] = s->to_upload[--s->to_upload_count];
            break;
        }
    release_entry(s, k);
}

/* ---- the API ---------------------------------------------------------------------------- */

static int pool_create(struct pool **out)
{
    struct pool *pool = calloc(1, sizeof(*pool));
    if (!pool)
        return TW_ERR_NOMEM;
    pthread_condattr_t attr;
    pthread_condattr_init(&attr);
    pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->work, NULL);
    pthread_cond_init(&pool->done, &attr);
    pthread_condattr_destroy(&attr);
    pool->refs = 1;
    *out = pool;
    return TW_OK;
}

int tw_stream_create(const struct tw_stream_settings *set, struct tw_renderer *r,
                     struct tw_stream **out)
{
    struct tw_stream *s = calloc(1, sizeof(*s));
    if (!s)
        return TW_ERR_NOMEM;
    s->set = *set;
    s->p = set->provider;
    s->renderer = r;
    s->free_head = UINT32_MAX;
    if (s->set.cancel_after == 0)
        s->set.cancel_after = 2;
    if (s->set.evict_after == 0)
        s->set.evict_after = 60;
    if (s->set.stop_ms == 0)
        s->set.stop_ms = TW_STREAM_STOP_MS;
    int err = pool_create(&s->pool);
    if (err) {
        free(s);
        return err;
    }
    err = tw_cell_map_create(&s->by_cell);
    if (!err)
        err = tw_cell_map_create(&s->generations);
    if (!err)
        err = tw_cell_map_create(&s->evicted);
    s->inline_worker.s = s;
    s->inline_worker.pool = s->pool;
    s->inline_worker.provider = *s->p;
    s->inline_worker.bvh = s->set.bvh;
    if (!err)
        err = tw_bvh_builder_create_ex(&(struct tw_log){capture_log, &s->inline_worker}, 0,
                                       &s->inline_worker.builder);
    if (!err && set->workers > 0) {
        s->workers = calloc(set->workers, sizeof(*s->workers));
        if (!s->workers)
            err = TW_ERR_NOMEM;
    }
    for (uint32_t k = 0; !err && k < set->workers; k++) {
        struct worker *wk = calloc(1, sizeof(*wk));
        if (!wk) {
            err = TW_ERR_NOMEM;
            break;
        }
        s->workers[k] = wk;
        s->worker_count = k + 1;
        *wk = s->inline_worker;
        wk->builder = NULL;
        /* One build thread each: the pool is the parallelism. */
        err = tw_bvh_builder_create_ex(&(struct tw_log){capture_log, wk}, 1, &wk->builder);
        if (err)
            break;
        pthread_mutex_lock(&s->pool->lock);
        s->pool->refs++;
        pthread_mutex_unlock(&s->pool->lock);
        if (pthread_create(&wk->thread, NULL, worker_main, wk) != 0) {
            pool_unref(s->pool);
            tw_log_printf(set->log, TW_LOG_ERROR, "cannot start tile worker thread %u", k);
            err = TW_ERR_NOMEM;
            break;
        }
        wk->started = true;
    }
    if (err) {
        tw_stream_destroy(s);
        return err;
    }
    *out = s;
    return TW_OK;
}

/* Stops the workers: waits up to stop_ms for those in a job, then leaves
 * the ones still in it behind (detached, owning their worker record).
 * Returns how many were left behind; their cells in *cells. */
static uint32_t stop_workers(struct tw_stream *s, char *cells, size_t cells_size)
{
    struct pool *pool = s->pool;
    struct timespec deadline;
    clock_gettime(CLOCK_MONOTONIC, &deadline);
    deadline.tv_sec += (time_t)(s->set.stop_ms / 1000u);
    deadline.tv_nsec += (long)(s->set.stop_ms % 1000u) * 1000000L;
    if (deadline.tv_nsec >= 1000000000L) {
        deadline.tv_sec++;
        deadline.tv_nsec -= 1000000000L;
    }
    uint32_t left = 0;
    size_t at = 0;
    cells[0] = '\0';
    pthread_mutex_lock(&pool->lock);
    pool->quit = true;
    pthread_cond_broadcast(&pool->work);
    for (bool timed_out = false;;) {
        bool running = false;
        for (uint32_t k = 0; k < s->worker_count && !running; k++)
            running = s->workers[k] && s->workers[k]->started && !s->workers[k]->stopped;
        if (!running || timed_out)
            break;
        timed_out = pthread_cond_timedwait(&pool->done, &pool->lock, &deadline) == ETIMEDOUT;
    }
    for (uint32_t k = 0; k < s->worker_count; k++) {
        struct worker *wk = s->workers[k];
        if (!wk || !wk->started || wk->stopped)
            continue;
        /* From here the thread owns wk; it takes the lock before it looks
         * at anything, so it cannot free wk before this loop is done. */
        wk->left_behind = true;
        wk->s = NULL;
        pthread_detach(wk->thread);
        s->workers[k] = NULL;
        if (wk->busy && at + 48 < cells_size)
            at += (size_t)snprintf(cells + at, cells_size - at, "%s(%lld, %lld)",
                                   left ? ", " : "", (long long)wk->cell.i,
                                   (long long)wk->cell.j);
        left++;
    }
    pthread_mutex_unlock(&pool->lock);
    return left;
}

uint32_t tw_stream_destroy(struct tw_stream *s)
{
    if (!s)
        return 0;
    char cells[256];
    const uint32_t left = stop_workers(s, cells, sizeof(cells));
    if (left > 0)
        tw_log_printf(s->set.log, TW_LOG_ERROR,
                      "provider %s: gave up after %.1f s waiting for %u tile worker%s still "
                      "generating%s%s%s when the world was destroyed: left running, detached; "
                      "the provider's code and user data must stay valid until generate() "
                      "returns",
                      s->p->name ? s->p->name : "(unnamed)", (double)s->set.stop_ms / 1000.0,
                      left, left == 1 ? "" : "s", cells[0] ? " (cells " : "", cells,
                      cells[0] ? ")" : "");
    for (uint32_t k = 0; k < s->worker_count; k++) {
        struct worker *wk = s->workers[k];
        if (!wk)
            continue;
        if (wk->started)
            pthread_join(wk->thread, NULL);
        tw_bvh_builder_destroy(wk->builder);
        free(wk);
    }
    free(s->workers);
    tw_bvh_builder_destroy(s->inline_worker.builder);
    for (uint32_t k = 0; k < s->entry_count; k++) {
        struct entry *e = &s->entries[k];
        if (e->rstate == R_READY)
            drop_ready(s, e);
        free_result(&e->result);
    }
    free(s->entries);
    free(s->heap);
    free(s->finished);
    free(s->to_upload);
    tw_cell_map_destroy(s->by_cell);
    tw_cell_map_destroy(s->generations);
    tw_cell_map_destroy(s->evicted);
    pool_unref(s->pool);
    free(s);
    return left;
}

void tw_stream_set_events(struct tw_stream *s, tw_stream_event_fn fn, void *user)
{
    s->on_event = fn;
    s->event_user = user;
}

/* Frames an eviction is remembered for, to count a later load as a
 * reload, and how many evictions at most. */
#define EVICTED_MEMORY 600
#define EVICTED_CELLS 2048

static bool forget_evicted(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    return value < *(const uint64_t *)user;
}

void tw_stream_begin_frame(struct tw_stream *s, uint64_t frame)
{
    s->frame = frame;
    memset(&s->stats, 0, sizeof(s->stats));
    collect(s);
    /* Uploads of tiles not yet needed, oldest request first, within the
     * frame's budget. */
    if (s->to_upload_count > 1) {
        /* Insertion sort by request order: a handful a frame. */
        for (uint32_t k = 1; k < s->to_upload_count; k++) {
            const uint32_t v = s->to_upload[k];
            uint32_t q = k;
            while (q > 0 && s->entries[s->to_upload[q - 1]].request_frame >
                                s->entries[v].request_frame) {
                s->to_upload[q] = s->to_upload[q - 1];
                q--;
            }
            s->to_upload[q] = v;
        }
    }
    uint64_t bytes = 0;
    const double t0 = tw_clock_monotonic_ms();
    uint32_t done = 0;
    while (done < s->to_upload_count) {
        if (done > 0 && (bytes >= s->set.upload_bytes ||
                         tw_clock_monotonic_ms() - t0 >= s->set.upload_ms))
            break;
        const uint32_t k = s->to_upload[done++];
        /* Out of memory drops the tile (asked for again when wanted). */
        if (make_ready(s, k) == TW_OK)
            bytes += s->entries[k].bytes_cpu;
    }
    if (done > 0 && done < s->to_upload_count)
        memmove(s->to_upload, s->to_upload + done,
                sizeof(*s->to_upload) * (s->to_upload_count - done));
    s->to_upload_count -= done;
    for (uint32_t k = 0; k < s->to_upload_count; k++)
        s->stats.bytes_loading += s->entries[s->to_upload[k]].result.bytes_cpu;
    s->stats.tiles_loading = s->to_upload_count;

    /* Requests nobody wanted lately: cancelled if no worker took them yet. */
    pthread_mutex_lock(&s->pool->lock);
    bool reorder = false;
    for (uint32_t k = 0; k < s->entry_count; k++) {
        struct entry *e = &s->entries[k];
        if (e->rstate != R_LOADING || e->jstate != J_QUEUED ||
            e->wanted_frame + s->set.cancel_after >= frame)
            continue;
        e->jstate = J_NONE;
        reorder = true;
        tw_cell_map_remove(s->by_cell, e->cell);
        s->loading--;
        release_entry(s, k);
    }
    if (reorder)
        rebuild_heap(s);
    pthread_mutex_unlock(&s->pool->lock);

    /* Tiles unseen for evict_after frames retire, as tile instances do;
     * refused cells are asked again once they have been out of sight. */
    for (uint32_t k = 0; k < s->entry_count; k++) {
        struct entry *e = &s->entries[k];
        if ((e->rstate != R_READY && e->rstate != R_REFUSED) ||
            e->wanted_frame + s->set.evict_after >= frame)
            continue;
        const bool ready = e->rstate == R_READY;
        const struct tw_cell cell = e->cell;
        const uint64_t freed_bytes = e->bytes_cpu + e->bytes_gpu;
        drop_entry(s, k);
        if (ready) {
            tw_cell_map_set(s->evicted, cell, frame);
            s->stats.evictions++;
            s->totals.evictions++;
            event(s, cell, TW_TILE_EVICTED, freed_bytes);
        }
    }
    /* What "a reload" remembers is bounded: evictions of the last
     * EVICTED_MEMORY frames, and at most EVICTED_CELLS of them (the most
     * recent), so that it follows neither distance nor speed. */
    uint64_t window = EVICTED_MEMORY;
    if (frame % 64 == 0 || tw_cell_map_count(s->evicted) >= EVICTED_CELLS)
        while (window > 0) {
            const uint64_t since = frame > window ? frame - window : 0;
            tw_cell_map_filter(s->evicted, forget_evicted, (void *)&since);
            if (tw_cell_map_count(s->evicted) < EVICTED_CELLS / 2)
                break;
            window /= 2;
        }
}

/* Makes entry k ready now (policy wait): runs its job here if no worker
 * has started it, else waits for the worker. */
static int complete_now(struct tw_stream *s, uint32_t k)
{
    const double t0 = tw_clock_monotonic_ms();
    s->stats.waits++;
    pthread_mutex_lock(&s->pool->lock);
    struct entry *e = &s->entries[k];
    if (e->jstate == J_QUEUED || e->jstate == J_NONE) {
        e->jstate = J_RUNNING;
        const struct tw_cell cell = e->cell;
        pthread_mutex_unlock(&s->pool->lock);
        struct job_result r;
        run_job(&s->inline_worker, cell, &r);
        pthread_mutex_lock(&s->pool->lock);
        e = &s->entries[k];
        e->result = r;
        e->jstate = J_DONE;
    }
    while (s->entries[k].jstate == J_RUNNING)
        pthread_cond_wait(&s->pool->done, &s->pool->lock);
    /* Done: if a worker filed it, take it off the finished list. */
    for (uint32_t q = 0; q < s->finished_count; q++)
        if (s->finished[q] == k) {
            s->finished[q] = s->finished[--s->finished_count];
            break;
        }
    pthread_mutex_unlock(&s->pool->lock);
    for (uint32_t q = 0; q < s->to_upload_count; q++)
        if (s->to_upload[q] == k) {
            s->to_upload[q] = s->to_upload[--s->to_upload_count];
            break;
        }
    const int err = make_ready(s, k);
    s->stats.ms_wait += tw_clock_monotonic_ms() - t0;
    return err;
}

/* The tile is used by this frame: kept against eviction, and counted in
 * what the frame needs. */
static void mark_used(struct tw_stream *s, struct entry *e)
{
    if (e->drawn_frame != s->frame)
        s->stats.bytes_used += e->bytes_cpu + e->bytes_gpu;
    e->wanted_frame = e->drawn_frame = s->frame;
}

static void fill(const struct entry *e, struct tw_cull_tile *out)
{
    if (e->rstate == R_READY) {
        out->proto = &e->ts->prototypes[0];
        out->bvh = e->bvh;
        out->content = e->content;
    } else {
        out->proto = NULL;
        out->bvh = NULL;
        out->content = 0;
    }
    out->key = e->key;
}

int tw_stream_get(struct tw_stream *s, struct tw_cell cell, float distance, unsigned flags,
                  struct tw_cull_tile *out)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    const bool touch = !(flags & (TW_TILE_SOURCE_RESIDENT | TW_TILE_SOURCE_QUIET));
    if (e && (e->rstate == R_READY || e->rstate == R_REFUSED)) {
        if (touch)
            mark_used(s, e);
        fill(e, out);
        return TW_OK;
    }
    if (flags & TW_TILE_SOURCE_RESIDENT)
        return TW_TILE_PENDING;
    if (!e) {
        e = request(s, cell, distance, &k);
        if (!e)
            return TW_ERR_NOMEM;
    }
    e->wanted_frame = s->frame;
    if (s->set.policy == TW_STREAM_SKIP && !(flags & TW_TILE_SOURCE_WAIT)) {
        pthread_mutex_lock(&s->pool->lock);
        if (e->jstate == J_QUEUED && distance < e->priority)
            e->priority = distance;
        pthread_mutex_unlock(&s->pool->lock);
        return TW_TILE_PENDING;
    }
    const int err = complete_now(s, k);
    if (err)
        return err;
    e = &s->entries[k];
    if (touch)
        mark_used(s, e);
    fill(e, out);
    return TW_OK;
}

/* Would one more tile on its way overfill the budget? The tiles on their
 * way are counted at the mean size of those held. Under a budget smaller
 * than what the camera wants (what it draws, plus what it will want soon),
 * a tile made ahead of need evicts one that is needed a few frames later,
 * which is then made again: prefetching stops before that. */
static bool budget_full(const struct tw_stream *s)
{
    if (!s->set.budget || s->ready == 0)
        return false;
    const uint64_t held = s->bytes_cpu + s->bytes_gpu;
    const uint64_t mean = held / s->ready;
    return held + mean * ((uint64_t)s->loading + 1) > s->set.budget;
}

void tw_stream_prefetch(struct tw_stream *s, struct tw_cell cell, float distance)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    if (!e) {
        if (!budget_full(s))
            request(s, cell, distance, &k);
        return;
    }
    e->wanted_frame = s->frame;
}

void tw_stream_touch(struct tw_stream *s, struct tw_cell cell)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    if (e && e->rstate == R_READY)
        mark_used(s, e);
}

bool tw_stream_has(const struct tw_stream *s, struct tw_cell cell)
{
    return tw_cell_map_find(s->by_cell, cell) != NULL;
}

void tw_stream_invalidate(struct tw_stream *s, struct tw_cell cell)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    /* A new key: the cell's culling state, made for the old content, goes. */
    uint64_t *gen = tw_cell_map_find(s->generations, cell);
    const uint64_t next = gen ? *gen + 1 : 1;
    tw_cell_map_set(s->generations, cell, next);
    if (!e)
        return;
    const uint64_t bytes = e->rstate == R_READY ? e->bytes_cpu + e->bytes_gpu : 0;
    const bool was_ready = e->rstate == R_READY;
    drop_entry(s, k);
    if (was_ready) {
        s->stats.evictions++;
        s->totals.evictions++;
        event(s, cell, TW_TILE_EVICTED, bytes);
    }
}

void tw_stream_invalidate_rect(struct tw_stream *s, struct tw_cell lo, struct tw_cell hi)
{
    for (uint32_t k = 0; k < s->entry_count; k++) {
        const struct entry *e = &s->entries[k];
        if (e->rstate == R_FREE)
            continue;
        if (e->cell.i >= lo.i && e->cell.i <= hi.i && e->cell.j >= lo.j && e->cell.j <= hi.j)
            tw_stream_invalidate(s, e->cell);
    }
}

uint64_t tw_stream_tile_bytes(const struct tw_stream *s)
{
    return s->bytes_cpu + s->bytes_gpu;
}

void tw_stream_bytes(struct tw_stream *s, uint64_t *cpu, uint64_t *gpu)
{
    /* The job lists grow under the lock, from the workers too. */
    pthread_mutex_lock(&s->pool->lock);
    const uint64_t jobs = (uint64_t)s->heap_cap + s->finished_cap;
    pthread_mutex_unlock(&s->pool->lock);
    *cpu = s->bytes_cpu + sizeof(*s) + (uint64_t)sizeof(*s->entries) * s->entry_cap +
           tw_cell_map_bytes(s->by_cell) + tw_cell_map_bytes(s->generations) +
           tw_cell_map_bytes(s->evicted) + sizeof(uint32_t) * (jobs + s->to_upload_cap);
    *gpu = s->bytes_gpu;
}

static bool evict_before(const struct entry *a, const struct entry *b)
{
    if (a->wanted_frame != b->wanted_frame)
        return a->wanted_frame < b->wanted_frame;
    return a->drawn_frame < b->drawn_frame;
}

uint64_t tw_stream_trim(struct tw_stream *s, uint64_t excess, uint64_t frame,
                        tw_stream_evicted_fn evicted, void *user)
{
    uint64_t freed = 0;
    while (freed < excess) {
        /* The least recently wanted ready tile not drawn this frame, of
         * those the least recently drawn. Wanted, not drawn: a tile
         * prefetched ahead of the camera has not been drawn yet, and
         * evicting it first would throw away the load it just made, to be
         * requested again the next frame. */
        uint32_t best = UINT32_MAX;
        for (uint32_t k = 0; k < s->entry_count; k++) {
            const struct entry *e = &s->entries[k];
            if (e->rstate != R_READY || e->drawn_frame >= frame)
                continue;
            if (best == UINT32_MAX || evict_before(e, &s->entries[best]))
                best = k;
        }
        if (best == UINT32_MAX)
            break;
        struct entry *e = &s->entries[best];
        const struct tw_cell cell = e->cell;
        const uint64_t bytes = e->bytes_cpu + e->bytes_gpu;
        drop_entry(s, best);
        tw_cell_map_set(s->evicted, cell, frame);
        freed += bytes;
        s->stats.evictions++;
        s->totals.evictions++;
        event(s, cell, TW_TILE_EVICTED, bytes);
        if (evicted)
            evicted(user, cell, bytes);
    }
    return freed;
}

const struct tw_stream_stats *tw_stream_stats(const struct tw_stream *s)
{
    return &s->stats;
}

const struct tw_stream_totals *tw_stream_totals(const struct tw_stream *s)
{
    return &s->totals;
}

uint32_t tw_stream_ready_count(const struct tw_stream *s)
{
    return s->ready;
}

uint32_t tw_stream_loading_count(const struct tw_stream *s)
{
    return s->loading;
}
