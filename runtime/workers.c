/*
 * The stream's worker pool (stream-private.h): the job a worker runs, the
 * heap of queued jobs, the threads, and stopping them.
 *
 * A job runs on what its worker owns (a copy of the provider, its own BVH
 * builder, the result on its stack), so that a worker stuck in the
 * provider's generate() can be left behind when the stream is destroyed:
 * the lock and the conditions live in a block of their own (struct pool)
 * that the last of the stream and such workers frees, and a worker that
 * comes back to find itself left behind drops its result, frees what it
 * owns and ends without touching the stream again.
 */
#include "runtime/runtime-internal.h"
#include "runtime/stream-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

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

static int refuse(char *why, size_t why_size, int err, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(why, why_size, fmt, ap);
    va_end(ap);
    return err;
}

int tw_provider_make_tile(const struct tw_tile_provider *p, struct tw_cell cell,
                          uint64_t max_triangles, struct tw_tileset **out, char *why,
                          size_t why_size)
{
    *out = NULL;
    why[0] = '\0';
    char name[64];
    snprintf(name, sizeof(name), "%lld,%lld", (long long)cell.i, (long long)cell.j);
    struct tw_tileset *ts = NULL;
    int err = tw_tileset_create(name, p->footprint[0], p->footprint[1], &ts);
    if (err)
        return refuse(why, why_size, err, "cannot make a tileset: %s", tw_error_to_str(err));
    err = p->generate(p->user, cell, ts);
    if (err == TW_GENERATE_EMPTY)
        goto out;
    if (err > 0) {
        err = refuse(why, why_size, TW_ERR_INVALID, "the provider's generate() returned %d: "
                     "neither TW_OK, TW_GENERATE_EMPTY nor an error", err);
        goto out;
    }
    if (err) {
        const char *reason = tw_tileset_failure(ts);
        if (reason)
            refuse(why, why_size, err, "the provider could not make it: %s (%s)", reason,
                   tw_error_to_str(err));
        else
            refuse(why, why_size, err, "the provider could not make it: %s",
                   tw_error_to_str(err));
        goto out;
    }
    uint64_t triangles = 0;
    for (uint32_t k = 0; k < ts->prototype_count; k++)
        for (uint32_t q = 0; q < ts->prototypes[k].instance_count; q++)
            triangles += ts->meshes[ts->prototypes[k].instances[q].mesh].triangle_count;
    if (max_triangles && triangles > max_triangles) {
        err = refuse(why, why_size, TW_ERR_LIMIT, "the tile has %llu triangles, over the cap of "
                     "%llu a tile (max_tile_triangles)", (unsigned long long)triangles,
                     (unsigned long long)max_triangles);
        goto out;
    }
    if (ts->prototype_count != 1) {
        err = refuse(why, why_size, TW_ERR_INVALID,
                     "the provider made %u prototypes for it (one is needed)",
                     ts->prototype_count);
        goto out;
    }
    err = tw_tileset_finish(ts, p->max_cluster_triangles ? p->max_cluster_triangles : 2048);
    if (err) {
        refuse(why, why_size, err, "the generated tile cannot be finished: %s",
               tw_error_to_str(err));
        goto out;
    }
    const struct tw_box *b = &ts->prototypes[0].box;
    if (!box_inside(b, &p->bound)) {
        err = refuse(why, why_size, TW_ERR_LIMIT,
                     "the tile's box [%g %g %g]-[%g %g %g] exceeds the provider's bound "
                     "[%g %g %g]-[%g %g %g]",
                     b->min[0], b->min[1], b->min[2], b->max[0], b->max[1], b->max[2],
                     p->bound.min[0], p->bound.min[1], p->bound.min[2], p->bound.max[0],
                     p->bound.max[1], p->bound.max[2]);
        goto out;
    }
    *out = ts;
    return TW_OK;
out:
    tw_tileset_destroy(ts);
    return err;
}

static void fail(struct job_result *r, int err, const char *fmt, ...)
{
    r->err = err;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->message, sizeof(r->message), fmt, ap);
    va_end(ap);
}

/* The stream may be gone by the time generate() returns: nothing here
 * touches it. */
void tw_stream_job_run(struct worker *wk, struct tw_cell cell, struct job_result *r)
{
    const struct tw_tile_provider *p = &wk->provider;
    memset(r, 0, sizeof(*r));
    wk->message[0] = '\0';
    char why[sizeof(r->message)];
    int err = tw_provider_make_tile(p, cell, wk->max_triangles, &r->ts, why, sizeof(why));
    if (err == TW_GENERATE_EMPTY) {
        r->empty = true;
        goto out;
    }
    if (err) {
        fail(r, err, "%s", why);
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
    if (wk->max_bytes && r->bytes_cpu > wk->max_bytes) {
        fail(r, TW_ERR_LIMIT, "the tile takes %llu bytes (geometry, clusters, BVH), over the "
             "cap of %llu a tile (max_tile_bytes)", (unsigned long long)r->bytes_cpu,
             (unsigned long long)wk->max_bytes);
        goto out;
    }
    if (wk->lods) {
        /* Its levels of detail (DESIGN §17), made here with the tile. */
        err = wk->levels
                  ? wk->levels(wk->levels_user, cell, r->ts, &wk->pool->quit, &r->lods)
                  : tw_lods_build(r->ts, p->max_cluster_triangles ? p->max_cluster_triangles : 2048,
                                  wk->lods_store, &wk->pool->quit, &r->lods);
        const uint32_t n = r->lods.levels ? r->lods.levels->prototype_count : 0;
        if (!err && n > 0 && !(r->lod_bvhs = calloc(n, sizeof(*r->lod_bvhs))))
            err = TW_ERR_NOMEM;
        for (uint32_t k = 0; k < n && !err; k++) {
            if (atomic_load_explicit(&wk->pool->quit, memory_order_relaxed)) {
                err = TW_ERR_STATE;     /* the stream is stopping: nobody will use them */
                break;
            }
            err = tw_bvh_build(wk->builder, &r->lods.levels->prototypes[k], &wk->bvh,
                               &r->lod_bvhs[k]);
            if (!err)
                (void)tw_bvh_pack(&r->lod_bvhs[k]);
        }
        if (err) {
            fail(r, err, "its levels of detail cannot be built: %s", tw_error_to_str(err));
            goto out;
        }
        r->bytes_cpu += tw_lods_bytes(&r->lods) + (uint64_t)n * sizeof(*r->lod_bvhs);
        for (uint32_t k = 0; k < n; k++)
            r->bytes_cpu += r->lod_bvhs[k]->bytes;
    }
    if (wk->hooks.prepare_worker) {
        /* The host's part, unless the stream left this worker behind while
         * generate() ran (the host may be gone). */
        pthread_mutex_lock(&wk->pool->lock);
        const bool gone = wk->left_behind;
        pthread_mutex_unlock(&wk->pool->lock);
        if (!gone)
            r->host_data = wk->hooks.prepare_worker(wk->hooks.user, cell, r->ts, r->lods.levels);
    }
    return;
out:
    r->bytes_cpu = 0;
    tw_stream_job_free_levels(&r->lods, &r->lod_bvhs);
    tw_bvh_destroy(r->bvh);
    r->bvh = NULL;
    tw_tileset_destroy(r->ts);
    r->ts = NULL;
}

void tw_stream_job_free_levels(struct tw_lods *lods, struct tw_bvh ***bvhs)
{
    const uint32_t n = lods->levels ? lods->levels->prototype_count : 0;
    for (uint32_t k = 0; *bvhs && k < n; k++)
        tw_bvh_destroy((*bvhs)[k]);
    free(*bvhs);
    *bvhs = NULL;
    tw_lods_free(lods);
}

void tw_stream_job_free(struct job_result *r)
{
    tw_stream_job_free_levels(&r->lods, &r->lod_bvhs);
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

bool tw_stream_jobs_push(struct tw_stream *s, uint32_t index)
{
    if (tw_array_reserve_u32((void **)&s->heap, &s->heap_cap, s->heap_count + 1, sizeof(*s->heap),
                             64) != TW_OK)
        return false;
    s->heap[s->heap_count] = index;
    sift_up(s, s->heap_count++);
    pthread_cond_signal(&s->pool->work);
    return true;
}

void tw_stream_jobs_rebuild(struct tw_stream *s)
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

void tw_stream_pool_unref(struct pool *pool)
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
        while (!atomic_load(&pool->quit) && (index = pop_job(wk->s)) == UINT32_MAX)
            pthread_cond_wait(&pool->work, &pool->lock);
        if (atomic_load(&pool->quit))
            break;
        struct entry *e = &wk->s->entries[index];
        e->jstate = J_RUNNING;
        const struct tw_cell cell = e->cell;
        wk->cell = cell;
        wk->busy = true;
        pthread_mutex_unlock(&pool->lock);
        struct job_result r;
        tw_stream_job_run(wk, cell, &r);
        pthread_mutex_lock(&pool->lock);
        wk->busy = false;
        if (wk->left_behind) {
            tw_stream_job_free(&r);
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
    tw_stream_pool_unref(pool);
    return NULL;
}

/* ---- the threads ------------------------------------------------------------------ */

static int pool_create(struct pool **out)
{
    struct pool *pool = calloc(1, sizeof(*pool));
    if (!pool)
        return TW_ERR_NOMEM;
    atomic_init(&pool->quit, false);
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

int tw_stream_workers_start(struct tw_stream *s)
{
    int err = pool_create(&s->pool);
    if (err)
        return err;
    s->inline_worker.s = s;
    s->inline_worker.pool = s->pool;
    s->inline_worker.provider = *s->p;
    s->inline_worker.bvh = s->set.bvh;
    s->inline_worker.lods = s->set.lods;
    s->inline_worker.lods_store = s->set.lods_store;
    s->inline_worker.levels = s->set.levels;
    s->inline_worker.levels_user = s->set.levels_user;
    s->inline_worker.max_triangles = s->set.max_triangles;
    s->inline_worker.max_bytes = s->set.max_bytes;
    s->inline_worker.hooks = s->set.hooks;
    err = tw_bvh_builder_create(&(struct tw_log){capture_log, &s->inline_worker}, 0,
                                &s->inline_worker.builder);
    if (!err && s->set.workers > 0) {
        s->workers = calloc(s->set.workers, sizeof(*s->workers));
        if (!s->workers)
            err = TW_ERR_NOMEM;
    }
    for (uint32_t k = 0; !err && k < s->set.workers; k++) {
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
        err = tw_bvh_builder_create(&(struct tw_log){capture_log, wk}, 1, &wk->builder);
        if (err)
            break;
        pthread_mutex_lock(&s->pool->lock);
        s->pool->refs++;
        pthread_mutex_unlock(&s->pool->lock);
        if (pthread_create(&wk->thread, NULL, worker_main, wk) != 0) {
            tw_stream_pool_unref(s->pool);
            tw_log_printf(s->set.log, TW_LOG_ERROR, "cannot start tile worker thread %u", k);
            err = TW_ERR_NOMEM;
            break;
        }
        wk->started = true;
    }
    return err;
}

uint32_t tw_stream_workers_stop(struct tw_stream *s, char *cells, size_t cells_size)
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
    atomic_store(&pool->quit, true);
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
    s->workers = NULL;
    s->worker_count = 0;
    tw_bvh_builder_destroy(s->inline_worker.builder);
    s->inline_worker.builder = NULL;
    return left;
}
