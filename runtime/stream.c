/*
 * Tile streaming (stream.h, DESIGN §12-§13): the entries of the cells with
 * tiles of their own, their uploads to the sink, the cache and its budget.
 * The worker pool is workers.c; what both share is stream-private.h.
 *
 * Under policy wait the render thread runs a job itself when no worker has
 * started it yet, so a frame never waits behind less urgent work.
 */
#include "runtime/stream-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

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
    const struct tw_tile_event e = {.cell = cell, .kind = kind, .bytes = bytes};
    if (s->on_event)
        s->on_event(s->event_user, &e);
}

/* The frame from which a tile refused for the attempt-th time in a row is
 * asked for again: retry_after frames later, twice as late each time; 0
 * after retry_max refusals (or with no retries). */
static uint64_t retry_frame(const struct tw_stream *s, uint32_t attempt)
{
    if (!s->set.retry_after || attempt > s->set.retry_max)
        return 0;
    const uint32_t shift = attempt - 1 < 20 ? attempt - 1 : 20;
    return s->frame + ((uint64_t)s->set.retry_after << shift);
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

/* Frees a job's result on the render thread: what the host made for it
 * too. */
static void drop_result(struct tw_stream *s, struct job_result *r)
{
    if (r->host_data && s->set.hooks.discard)
        s->set.hooks.discard(s->set.hooks.user, r->host_data);
    r->host_data = NULL;
    tw_stream_job_free(r);
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
    (void)tw_stream_jobs_push(s, *index);
    pthread_mutex_unlock(&s->pool->lock);
    return e;
}

/* Frees what a ready tile holds. */
static void drop_ready(struct tw_stream *s, struct entry *e)
{
    s->set.sink.release(s->set.sink.user, e->content);
    if (e->lods.levels)
        s->set.sink.release(s->set.sink.user, e->lod_content);
    tw_stream_job_free_levels(&e->lods, &e->lod_bvhs);
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
        r.err = s->set.sink.upload(s->set.sink.user, r.ts, bvhs, &e->content, &e->bytes_gpu);
        uint64_t lod_gpu = 0;
        if (!r.err && r.lods.levels) {
            r.err = s->set.sink.upload(s->set.sink.user, r.lods.levels,
                                       (const struct tw_bvh *const *)r.lod_bvhs, &e->lod_content,
                                       &lod_gpu);
            if (r.err)
                s->set.sink.release(s->set.sink.user, e->content);
            else
                s->set.sink.levels(s->set.sink.user, e->content, e->lod_content,
                                   r.lods.levels->prototype_count);
        }
        e->bytes_gpu += lod_gpu;
        if (!r.err && s->set.sink.ready) {
            e->bytes_gpu += s->set.sink.ready(s->set.sink.user, e->content, r.ts, r.lods.levels,
                                              r.host_data);
            r.host_data = NULL;     /* the sink's now */
        }
        if (r.err)
            snprintf(r.message, sizeof(r.message), "cannot upload it: %s",
                     tw_error_to_str(r.err));
    }
    if (r.empty) {
        /* Nothing there: kept, like a refusal, without the error. */
        e->rstate = R_EMPTY;
        e->attempts = 0;
        s->stats.loads_done++;
        s->totals.loads_done++;
        const struct tw_tile_event ev = {.cell = e->cell, .kind = TW_TILE_READY, .empty = true,
                                         .latency = (uint32_t)(s->frame - e->request_frame)};
        if (s->on_event)
            s->on_event(s->event_user, &ev);
        return TW_OK;
    }
    if (r.err) {
        const uint32_t attempt = r.err == TW_ERR_NOMEM ? 1 : e->attempts + 1;
        const uint64_t retry = r.err == TW_ERR_NOMEM ? s->frame + 1 : retry_frame(s, attempt);
        /* Out of memory comes tile after tile: one line, the rest counted. */
        if (r.err != TW_ERR_NOMEM || !s->quiet_nomem)
            tw_log_printf(s->set.log, TW_LOG_ERROR, "provider %s: cell (%lld, %lld): %s%s%s",
                          s->p->name ? s->p->name : "", (long long)e->cell.i,
                          (long long)e->cell.j, r.message,
                          r.err == TW_ERR_NOMEM ? " (further tiles refused for lack of memory "
                                                  "are counted, not logged)" : "",
                          r.err == TW_ERR_NOMEM ? ""
                          : retry ? " (asked again later)"
                                  : " (not asked again while in sight)");
        struct tw_tile_event ev = {.cell = e->cell, .kind = TW_TILE_REFUSED, .error = r.err,
                                   .attempt = attempt,
                                   .retry_in = retry ? (uint32_t)(retry - s->frame) : 0};
        snprintf(ev.message, sizeof(ev.message), "%s", r.message);
        drop_result(s, &r);
        s->stats.refused++;
        s->totals.refused++;
        if (r.err == TW_ERR_NOMEM) {
            /* The machine's failure, not the cell's: nothing is kept, the
             * cell is asked for again when it is next wanted, and a frame
             * that waits for it fails (its image would lack the tile). */
            s->quiet_nomem = true;
            tw_cell_map_remove(s->by_cell, e->cell);
            release_entry(s, k);
            if (s->on_event)
                s->on_event(s->event_user, &ev);
            return TW_ERR_NOMEM;
        }
        e->rstate = R_REFUSED;
        e->attempts = attempt;
        e->retry_frame = retry;
        if (s->on_event)
            s->on_event(s->event_user, &ev);
        return TW_OK;
    }
    e->ts = r.ts;
    e->bvh = r.bvh;
    e->lods = r.lods;
    e->lod_bvhs = r.lod_bvhs;
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
    const struct tw_tile_event ev = {.cell = e->cell, .kind = TW_TILE_READY,
                                     .bytes = e->bytes_cpu + e->bytes_gpu,
                                     .latency = (uint32_t)(s->frame - e->request_frame),
                                     .reload = e->reload};
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
            drop_result(s, &e->result);
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
    if (e->rstate == R_REFUSED || e->rstate == R_EMPTY) {
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
            drop_result(s, &e->result);
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

int tw_stream_create(const struct tw_stream_settings *set, struct tw_stream **out)
{
    if (!set->sink.upload || !set->sink.release)
        return TW_ERR_INVALID;
    struct tw_stream *s = calloc(1, sizeof(*s));
    if (!s)
        return TW_ERR_NOMEM;
    s->set = *set;
    s->p = set->provider;
    s->free_head = UINT32_MAX;
    if (s->set.cancel_after == 0)
        s->set.cancel_after = 2;
    if (s->set.evict_after == 0)
        s->set.evict_after = 60;
    s->views = 1;
    if (s->set.stop_ms == 0)
        s->set.stop_ms = TW_STREAM_STOP_MS;
    int err = tw_cell_map_create(&s->by_cell);
    if (!err)
        err = tw_cell_map_create(&s->generations);
    if (!err)
        err = tw_cell_map_create(&s->evicted);
    if (!err)
        err = tw_stream_workers_start(s);
    if (err) {
        tw_stream_destroy(s);
        return err;
    }
    *out = s;
    return TW_OK;
}

uint32_t tw_stream_destroy(struct tw_stream *s)
{
    if (!s)
        return 0;
    char cells[256];
    const uint32_t left = s->pool ? tw_stream_workers_stop(s, cells, sizeof(cells)) : 0;
    if (left > 0)
        tw_log_printf(s->set.log, TW_LOG_ERROR,
                      "provider %s: gave up after %.1f s waiting for %u tile worker%s still "
                      "generating%s%s%s when the world was destroyed: left running, detached; "
                      "the provider's code and user data must stay valid until generate() "
                      "returns",
                      s->p->name ? s->p->name : "(unnamed)", (double)s->set.stop_ms / 1000.0,
                      left, left == 1 ? "" : "s", cells[0] ? " (cells " : "", cells,
                      cells[0] ? ")" : "");
    for (uint32_t k = 0; k < s->entry_count; k++) {
        struct entry *e = &s->entries[k];
        if (e->rstate == R_READY)
            drop_ready(s, e);
        drop_result(s, &e->result);
    }
    free(s->entries);
    free(s->heap);
    free(s->finished);
    free(s->to_upload);
    tw_cell_map_destroy(s->by_cell);
    tw_cell_map_destroy(s->generations);
    tw_cell_map_destroy(s->evicted);
    if (s->pool)
        tw_stream_pool_unref(s->pool);
    free(s);
    return left;
}

void tw_stream_set_views(struct tw_stream *s, uint32_t views)
{
    s->views = views ? views : 1;
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
            e->wanted_frame + (uint64_t)s->set.cancel_after * s->views >= frame)
            continue;
        e->jstate = J_NONE;
        reorder = true;
        tw_cell_map_remove(s->by_cell, e->cell);
        s->loading--;
        release_entry(s, k);
    }
    if (reorder)
        tw_stream_jobs_rebuild(s);
    pthread_mutex_unlock(&s->pool->lock);

    /* Tiles unseen for evict_after frames retire, as tile instances do;
     * refused cells are asked again once they have been out of sight (and
     * when their retry is due: tw_stream_get). */
    for (uint32_t k = 0; k < s->entry_count; k++) {
        struct entry *e = &s->entries[k];
        if ((e->rstate != R_READY && e->rstate != R_REFUSED && e->rstate != R_EMPTY) ||
            e->wanted_frame + (uint64_t)s->set.evict_after * s->views >= frame)
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
        tw_stream_job_run(&s->inline_worker, cell, &r);
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

/* An instance key names the tile and its level: the level in the top bits. */
#define LEVEL_KEY_SHIFT 28

static void fill(const struct entry *e, float max_error, struct tw_cull_tile *out)
{
    out->key = e->key;
    if (e->rstate != R_READY) {
        out->proto = NULL;
        out->bvh = NULL;
        out->content = 0;
        return;
    }
    const uint32_t level = tw_lods_pick(&e->lods, 0, max_error);
    if (level == 0) {
        out->proto = &e->ts->prototypes[0];
        out->bvh = e->bvh;
        out->content = e->content;
        return;
    }
    out->proto = &e->lods.levels->prototypes[level - 1];
    out->bvh = e->lod_bvhs[level - 1];
    out->content = e->lod_content + level - 1;
    out->key = (e->key & ((1u << LEVEL_KEY_SHIFT) - 1u)) | level << LEVEL_KEY_SHIFT;
}

int tw_stream_get(struct tw_stream *s, struct tw_cell cell, float distance, unsigned flags,
                  float max_error, struct tw_cull_tile *out)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    const bool touch = !(flags & (TW_TILE_SOURCE_RESIDENT | TW_TILE_SOURCE_QUIET));
    if (e && e->rstate == R_REFUSED && e->retry_frame && e->retry_frame <= s->frame &&
        !(flags & TW_TILE_SOURCE_RESIDENT)) {
        /* Its retry is due: requested anew, its refusals still counted. */
        const uint32_t attempts = e->attempts;
        drop_entry(s, k);
        e = request(s, cell, distance, &k);
        if (!e)
            return TW_ERR_NOMEM;
        e->attempts = attempts;
    }
    if (e && (e->rstate == R_READY || e->rstate == R_REFUSED || e->rstate == R_EMPTY)) {
        if (touch)
            mark_used(s, e);
        fill(e, max_error, out);
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
    fill(e, max_error, out);
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

bool tw_stream_retry(struct tw_stream *s, struct tw_cell cell)
{
    uint32_t k;
    struct entry *e = find(s, cell, &k);
    if (!e || e->rstate != R_REFUSED)
        return false;
    drop_entry(s, k);
    return true;
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
