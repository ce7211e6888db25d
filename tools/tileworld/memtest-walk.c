/* tileworld memtest: the memory figures, one walk through the world into
 * memory.csv (memtest-private.h). */
#include <malloc.h> /* mallinfo2: heap_figures() */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "tiles/tiles-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/outfile.h"
#include "tools/progress.h"
#include "tools/tileworld/memtest-private.h"
#include "tools/tileworld/report.h"

/* The process's resident set in bytes; 0 where /proc cannot say. */
static uint64_t rss_bytes(void)
{
    FILE *f = fopen("/proc/self/statm", "r");
    if (!f)
        return 0;
    unsigned long long size = 0, resident = 0;
    const int n = fscanf(f, "%llu %llu", &size, &resident);
    fclose(f);
    const long page = sysconf(_SC_PAGESIZE);
    return n == 2 && page > 0 ? (uint64_t)resident * (uint64_t)page : 0;
}

/* What the C library's allocator holds: bytes in use by the program, and bytes
 * it keeps free (returned by free() but not to the system). Their sum against
 * the RSS tells a growth of live memory from memory the allocator retains. 0 where
 * the C library cannot say (not glibc 2.33 or newer). malloc is left with its own
 * settings: a host should not have to tune it, and the library maps a streamed
 * tile's large packed blocks itself (not counted here), so that evicting a tile
 * returns its pages. */
struct heap_figures {
    uint64_t used, held_free;
};

static struct heap_figures heap_figures(void)
{
    struct heap_figures h = { 0, 0 };
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
    const struct mallinfo2 m = mallinfo2();
    h.used = (uint64_t)m.uordblks + (uint64_t)m.hblkhd;
    h.held_free = (uint64_t)m.fordblks;
#endif
    return h;
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* A growable array of doubles. */
struct values {
    double *v;
    uint32_t n, cap;
};

static int values_push(struct values *a, double x)
{
    if (a->n == a->cap) {
        const uint32_t cap = a->cap ? a->cap * 2 : 256;
        double *v = realloc(a->v, sizeof(*v) * cap);
        if (!v)
            return TW_ERR_NOMEM;
        a->v = v;
        a->cap = cap;
    }
    a->v[a->n++] = x;
    return TW_OK;
}

/* One record interval of memory.csv. */
struct interval {
    uint32_t frames;
    uint64_t loads_requested, loads_done, evictions, reloads, holes;
    double ms, cpu_ms, ms_max;
    struct values latency;
};

static const char memory_header[] =
    "distance_m,frame,bytes_state,bytes_geometry,bytes_gpu,bytes_total,bytes_needed,budget,"
    "tiles_cached,tiles_ready,loads_requested,loads_done,evictions,reloads,latency_median,"
    "latency_p99,holes,rss_bytes,ms_frame,cpu_ms,ms_frame_max,heap_used_bytes,heap_free_bytes,bytes_loading,tiles_loading\n";

/* One walk through the world: what the steps of tw_memtest_walk_once share. */
struct walk_run {
    const struct tw_memtest_options *o;
    struct tw_memtest_walk *walk;
    struct tw_memtest_result *r;
    const struct tw_memtest_progress *progress;
    struct tw_world *world;
    struct tw_cell_map *evicted;    /* the cells evicted so far: a load of one is a reload */
    struct tw_outfile csv;          /* memory.csv */
    struct values frame_ms, latency;
    struct interval iv;             /* the row of memory.csv being gathered */
    uint32_t km_cap;                /* entries of r->rss_km */
    double distance, next_record, total_ms, cpu_total;
    /* The tiles made ready and evicted, from the tile events. */
    uint64_t ready_bytes, evicted_bytes;
    uint32_t ready_tiles, evicted_tiles;
};

/* The world with the run's budget, the evicted cells, memory.csv with its
 * header, r->rss_km; the walk back at its first key. */
static int walk_setup(struct walk_run *run, const struct tw_cli_world *shown,
                      struct tw_context *ctx, const char *dir, int *world_error, char *err,
                      size_t err_size)
{
    const struct tw_memtest_options *o = run->o;
    struct tw_memtest_result *r = run->r;
    struct tw_world_settings ws = o->cli.world;
    tw_cli_world_apply(shown, &ws);
    ws.cache_budget_bytes = r->budget;
    ws.get_proc = tw_context_get_proc(ctx);
    ws.log = (struct tw_log){tw_cli_log, (void *)&o->cli};
    int rc = tw_world_create_tuned(&ws, &o->cli.tuning, &run->world);
    if (rc) {
        *world_error = rc;
        snprintf(err, err_size, "cannot create the world: %s", tw_error_to_str(rc));
        return rc;
    }
    rc = tw_cell_map_create(&run->evicted);
    if (rc) {
        snprintf(err, err_size, "out of memory");
        return rc;
    }
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/memory.csv", dir);
    rc = tw_outfile_open(&run->csv, file, err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&run->csv, "%s", memory_header);

    run->km_cap = (uint32_t)(o->distance_m / 1000.0) + 2;
    r->rss_km = calloc(run->km_cap, sizeof(*r->rss_km));
    if (!r->rss_km) {
        snprintf(err, err_size, "out of memory");
        return TW_ERR_NOMEM;
    }
    tw_memtest_walk_restart(run->walk);
    return TW_OK;
}

/* Frame f's tile events: loads with their latency, reloads (a cell loaded
 * again after its eviction), evictions, refusals. */
static int count_tile_events(struct walk_run *run, uint32_t f)
{
    struct tw_memtest_result *r = run->r;
    size_t event_count = 0;
    const struct tw_tile_event *events = tw_world_tile_events(run->world, &event_count);
    int rc = TW_OK;
    for (size_t k = 0; k < event_count && !rc; k++) {
        const struct tw_tile_event *e = &events[k];
        if (e->kind == TW_TILE_READY) {
            run->ready_tiles++;
            run->ready_bytes += e->bytes;
            r->loads_done++;
            r->reloads_library += e->reload;
            if (tw_cell_map_find(run->evicted, e->cell)) {
                r->reloads++;
                run->iv.reloads++;
            }
            rc = values_push(&run->latency, e->latency);
            if (!rc)
                rc = values_push(&run->iv.latency, e->latency);
        } else if (e->kind == TW_TILE_EVICTED) {
            run->evicted_tiles++;
            run->evicted_bytes += e->bytes;
            r->tile_evictions++;
            rc = tw_cell_map_set(run->evicted, e->cell, f);
        } else {
            r->refused++;
        }
    }
    return rc;
}

/* Frame f's cache bytes (total) against the budget: over it because the
 * view needed more, or otherwise (the worst of those kept). */
static void count_over_budget(struct tw_memtest_result *r, uint32_t f, uint64_t total,
                              uint64_t needed)
{
    if (!r->budget || total <= r->budget)
        return;
    r->frames_over++;
    if (needed > r->budget) {
        r->frames_over_needed++;
    } else {
        r->frames_over_other++;
        if (total - r->budget > r->worst_over) {
            r->worst_over = total - r->budget;
            r->worst_over_frame = f + 1;
        }
    }
}

/* Frame f's figures into the run's: the cache's accounting against the tile
 * events, the peaks, the budget, the loads, the RSS (returned) and the RSS
 * at each whole km. */
static uint64_t sample_frame(struct walk_run *run, uint32_t f, const struct tw_frame_stats *st,
                             const struct tw_cache_totals *totals)
{
    struct tw_memtest_result *r = run->r;
    if (totals->tiles_ready != run->ready_tiles - run->evicted_tiles ||
        totals->tile_bytes != run->ready_bytes - run->evicted_bytes)
        r->accounting_mismatch_frames++;

    const uint64_t total = st->bytes_cpu + st->bytes_gpu;
    r->frames++;
    if (total > r->peak_total)
        r->peak_total = total;
    if (st->bytes_needed > r->peak_needed)
        r->peak_needed = st->bytes_needed;
    count_over_budget(r, f, total, st->bytes_needed);
    r->loads_requested += st->loads_requested;
    r->evictions += st->evictions;
    r->holes += st->tiles_pending;
    const uint64_t rss = rss_bytes();
    if (f == 0)
        r->rss_start = rss;
    if (rss > r->peak_rss)
        r->peak_rss = rss;
    r->final_rss = rss;
    while (r->rss_km_count < run->km_cap && run->distance >= 1000.0 * r->rss_km_count)
        r->rss_km[r->rss_km_count++] = rss;
    return rss;
}

/* A frame's figures into the interval's and the run's sums. */
static void add_to_interval(struct walk_run *run, const struct tw_frame_stats *st)
{
    struct interval *iv = &run->iv;
    iv->frames++;
    iv->loads_requested += st->loads_requested;
    iv->loads_done += st->loads_done;
    iv->evictions += st->evictions;
    iv->holes += st->tiles_pending;
    iv->ms += st->ms_frame;
    iv->cpu_ms += st->cpu_ms;
    if (st->ms_frame > iv->ms_max)
        iv->ms_max = st->ms_frame;
    run->total_ms += st->ms_frame;
    run->cpu_total += st->cpu_ms;
}

/* Check 2 reads the recorded rows, the series memory.csv and the chart
 * show: a frame's RSS also holds the tiles being made at that moment (the
 * arrays a worker builds a tile in, until it is packed), and the peak of
 * single frames is in the figures, not in the trend. */
static void note_rss_row(struct tw_memtest_result *r, double distance, double distance_m,
                         uint64_t rss)
{
    if (distance >= 0.4 * distance_m - 1e-3 && distance <= 0.5 * distance_m + 1e-3) {
        r->rss_first_rows++;
        if (rss > r->rss_first)
            r->rss_first = rss;
    }
    if (distance >= 0.9 * distance_m - 1e-3) {
        r->rss_last_rows++;
        if (rss > r->rss_last)
            r->rss_last = rss;
    }
}

/* The row of memory.csv for the interval that ends at frame f; the heap
 * figures; a new interval. */
static void record_interval(struct walk_run *run, uint32_t f, const struct tw_frame_stats *st,
                            const struct tw_cache_totals *totals, uint64_t rss)
{
    struct tw_memtest_result *r = run->r;
    struct interval *iv = &run->iv;
    const uint64_t total = st->bytes_cpu + st->bytes_gpu;
    const double lat_median = tw_report_percentile(iv->latency.v, iv->latency.n, 50.0);
    const double lat_p99 = tw_report_percentile(iv->latency.v, iv->latency.n, 99.0);
    const struct heap_figures heap = heap_figures();
    note_rss_row(r, run->distance, run->o->distance_m, rss);
    r->heap_used = heap.used;
    r->heap_free = heap.held_free;
    if (heap.held_free > r->heap_free_peak)
        r->heap_free_peak = heap.held_free;
    tw_outfile_printf(&run->csv, "%.1f,%u,%llu,%llu,%llu,%llu,%llu,%llu,%u,%u,%llu,%llu,%llu,"
                      "%llu,%.0f,%.0f,%llu,%llu,%.3f,%.3f,%.3f,%llu,%llu,%llu,%u\n",
                      run->distance, f + 1, (unsigned long long)st->bytes_state,
                      (unsigned long long)(st->bytes_cpu - st->bytes_state),
                      (unsigned long long)st->bytes_gpu, (unsigned long long)total,
                      (unsigned long long)st->bytes_needed, (unsigned long long)r->budget,
                      st->tiles_cached, totals->tiles_ready,
                      (unsigned long long)iv->loads_requested,
                      (unsigned long long)iv->loads_done, (unsigned long long)iv->evictions,
                      (unsigned long long)iv->reloads, lat_median, lat_p99,
                      (unsigned long long)iv->holes, (unsigned long long)rss,
                      iv->ms / iv->frames, iv->cpu_ms / iv->frames, iv->ms_max,
                      (unsigned long long)heap.used, (unsigned long long)heap.held_free,
                      (unsigned long long)st->bytes_loading, st->tiles_loading);
    const struct values keep = iv->latency;
    memset(iv, 0, sizeof(*iv));
    iv->latency = keep;
    iv->latency.n = 0;
    while (run->next_record <= run->distance + 1e-3)
        run->next_record += run->o->every_m;
}

/* The last frame's figures: the cache at the end, by its own count and by
 * the tile events. */
static void take_final(struct walk_run *run, const struct tw_frame_stats *st,
                       const struct tw_cache_totals *totals)
{
    struct tw_memtest_result *r = run->r;
    r->final_total = st->bytes_cpu + st->bytes_gpu;
    r->live_tiles = totals->tiles_ready;
    r->live_bytes = totals->tile_bytes;
    r->event_tiles = run->ready_tiles - run->evicted_tiles;
    r->event_bytes = run->ready_bytes - run->evicted_bytes;
    r->totals_loads_done = totals->loads_done;
    r->totals_evictions = totals->evictions;
    r->totals_reloads = totals->reloads;
}

/* Frame f: the camera moves on, the world draws, the figures are taken, a
 * row of memory.csv when one is due. *done: the distance is covered. */
static int walk_frame(struct walk_run *run, uint32_t f, bool *done, char *err, size_t err_size)
{
    const double distance_m = run->o->distance_m;
    struct tw_camera cam;
    double moved = 0.0;
    int rc = tw_memtest_walk_next(run->walk, &cam, &moved);
    if (rc) {
        snprintf(err, err_size, "--path: the repeated path leaves the grid");
        return rc;
    }
    run->distance += moved;
    struct tw_frame_stats st;
    rc = tw_world_frame(run->world, &cam, &st);
    if (!rc)
        rc = tw_world_finish(run->world, &st);
    if (rc) {
        snprintf(err, err_size, "frame %u failed: %s", f + 1, tw_error_to_str(rc));
        return rc;
    }
    rc = count_tile_events(run, f);
    if (!rc)
        rc = values_push(&run->frame_ms, st.ms_frame);
    if (rc) {
        snprintf(err, err_size, "out of memory");
        return rc;
    }
    struct tw_cache_totals totals;
    tw_world_cache_totals(run->world, &totals);
    const uint64_t rss = sample_frame(run, f, &st, &totals);
    add_to_interval(run, &st);

    *done = run->distance >= distance_m - 1e-3;
    if (*done || run->distance >= run->next_record - 1e-3)
        record_interval(run, f, &st, &totals, rss);
    char note[128];
    snprintf(note, sizeof(note), "%s%.1f ms/frame", run->progress->what, run->total_ms / (f + 1));
    tw_progress_update(run->progress->line,
                       run->progress->done_before + fmin(run->distance, distance_m), note);
    if (*done)
        take_final(run, &st, &totals);
    return TW_OK;
}

/* The whole walk's figures: distance, load latency, frame times, wall time
 * since t0. */
static void summarise(struct walk_run *run, double t0)
{
    struct tw_memtest_result *r = run->r;
    const struct values *latency = &run->latency, *frame_ms = &run->frame_ms;
    r->distance_m = run->distance;
    r->lat_count = latency->n;
    r->lat_median = tw_report_percentile(latency->v, latency->n, 50.0);
    r->lat_p99 = tw_report_percentile(latency->v, latency->n, 99.0);
    r->lat_max = tw_report_percentile(latency->v, latency->n, 100.0);
    double sum = 0.0;
    for (uint32_t k = 0; k < frame_ms->n; k++)
        sum += frame_ms->v[k];
    r->mean_cpu_ms = r->frames ? run->cpu_total / r->frames : 0.0;
    r->mean_ms = frame_ms->n ? sum / frame_ms->n : 0.0;
    r->median_ms = tw_report_percentile(frame_ms->v, frame_ms->n, 50.0);
    r->p99_ms = tw_report_percentile(frame_ms->v, frame_ms->n, 99.0);
    r->wall_s = now_s() - t0;
}

/* Frees what walk_setup and the frames made; memory.csv, when not committed,
 * leaves no file. */
static void walk_teardown(struct walk_run *run)
{
    tw_outfile_discard(&run->csv);
    tw_cli_world_destroy(run->world);
    tw_cell_map_destroy(run->evicted);
    free(run->frame_ms.v);
    free(run->latency.v);
    free(run->iv.latency.v);
}

int tw_memtest_walk_once(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                         struct tw_memtest_walk *walk, struct tw_context *ctx, const char *dir,
                         struct tw_memtest_result *r, const struct tw_memtest_progress *progress,
                         int *world_error, char *err, size_t err_size)
{
    const double t0 = now_s();
    struct walk_run run = {.o = o, .walk = walk, .r = r, .progress = progress};
    int rc = walk_setup(&run, shown, ctx, dir, world_error, err, err_size);
    bool done = false;
    for (uint32_t f = 0; !rc && !done; f++)
        rc = walk_frame(&run, f, &done, err, err_size);
    if (!rc)
        rc = tw_outfile_commit(&run.csv, err, err_size);
    if (!rc)
        summarise(&run, t0);
    walk_teardown(&run);
    return rc;
}
