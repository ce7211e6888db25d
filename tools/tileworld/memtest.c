/* tileworld memtest: memory against distance travelled (memtest.h). */
#include "tiles/tiles-internal.h"
#include "tools/tileworld/memtest.h"

#include <errno.h>
#include <malloc.h> /* mallinfo2: heap_figures() */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <json-c/json.h>

#include "tileworld/context.h"
#include "tools/tileworld/glcontext.h"
#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/memtest-gp.h"   /* TW_MEMTEST_GP: tools/tileworld/memtest.gp, built in */
#include "tools/outfile.h"
#include "tools/progress.h"
#include "tools/tileworld/charts.h"
#include "tools/tileworld/outputs.h"
#include "tools/tileworld/report.h"

static const char program[] = "tileworld";

#define MAX_SWEEP 16
#define MIB (1024.0 * 1024.0)

/* Check 4: the p99 of load latency (frames from a tile's request to its
 * being ready) over the run, at the default speed (2 m a frame). Measured
 * on llvmpipe, two shared cores, city-gen, straight, 320x180, policy wait,
 * default workers (1), 5 km (tileworld memtest --distance 5 --budget B):
 * median 2 frames at every budget; p99 32 at 64M, 57 at 64M with a test
 * running beside it, 79 at 16M, 103 at 4M (a budget below what one view
 * needs: nearly every load is a reload and the queue backs up); max 141-226.
 * Most tiles are requested by the look-ahead, well before they are needed,
 * and a tile a frame needs is made on the spot, so a long latency means the
 * workers are behind. 90 frames is 180 m of walking, more than two tiles:
 * a queue that keeps up stays under it, one that backs up does not. */
#define LATENCY_P99_BOUND 90.0
/* Check 2: RSS flat in distance. */
#define RSS_GROWTH_BOUND 1.05
/* What one run may cost, refused before it starts: as many frames as walk's
 * --frames allows (weeks of rendering on a CPU), and rows of memory.csv
 * (about 250 bytes each). */
#define MAX_FRAMES 10000000.0
#define MAX_ROWS 1000000.0

struct options {
    struct tw_cli cli;
    double distance_m;
    double every_m;
    const char *out;
    uint64_t sweep[MAX_SWEEP];
    char sweep_text[MAX_SWEEP][32];
    uint32_t sweep_count;
    struct tw_context_settings gl; /* --gl, --gpu */
};

static void usage(FILE *f)
{
    fputs("usage: tileworld memtest [--tileset NAME|FILE.json] [--path straight|wander|FILE.csv]\n"
          "                         [--distance KM] [--every METRES] [--budget BYTES]\n"
          "                         [--sweep budget=B1,B2,...] [--size WxH] [--workers N]\n"
          "                         [--policy wait|skip] [--method M] [--view-distance M]\n"
          "                         [--upload-budget BYTES] [--start-cell I,J] [--repeat P]\n"
          "                         [--seed N] [--out DIR] [--quiet]\n"
          "                         [--gl auto|egl|osmesa] [--gpu N]\n"
          "\n"
          "Walks a long path through a tileset and records the tile cache's memory against\n"
          "the distance travelled: every --every metres a row of DIR/memory.csv (the cache's\n"
          "bytes, tiles, loads, evictions, reloads, load latency, holes, the process's RSS,\n"
          "the frame time), then DIR/summary.json, DIR/summary.md and charts (with gnuplot).\n"
          "Exit status 0 when every check held or was not applicable, 3 when one did not\n"
          "(cache bytes within the budget except where the view alone needs more, RSS flat\n"
          "in distance, no leak, load latency bounded), 2 for bad input, 1 for a failure.\n"
          "--tileset NAME|FILE.json  what the world shows (default city-gen): the providers\n"
          "                      city-gen and forest-gen, the built-in city, forest, hybrid,\n"
          "                      or a manifest\n"
          "--path straight|wander|FILE.csv  the walk (default straight: along one street;\n"
          "                      wander turns at crossings, seeded by --seed; a CSV is\n"
          "                      repeated end to end)\n"
          "--distance KM         kilometres to walk, 0.001..10000 (default 5; about 2500\n"
          "                      frames, tens of minutes on a CPU: the progress line says)\n"
          "--every METRES        a row of memory.csv every METRES metres, 1..1000000\n"
          "                      (default 100)\n"
          "--budget BYTES        the tile cache's budget, CPU and GPU bytes, with an optional\n"
          "                      binary suffix K, M, G, T (64M = 64 MiB); 0: none (the default)\n"
          "--sweep budget=B1,B2,...  one run per budget into DIR/sweep-budget-VALUE/, and\n"
          "                      DIR/sweep.csv and chart-sweep-budget.png (not with --budget)\n"
          "--size WxH            image size, each side 16..8192 (default 320x180)\n"
          "--workers N           threads generating tiles, 1..64 (default: cores - 1)\n"
          "--policy wait|skip    a visible tile not ready: the frame waits for it (wait,\n"
          "                      default) or draws without it, a hole (skip)\n"
          "--method M            the culling method (default tilequery+chc)\n"
          "--view-distance M     metres, 1..100000 (default 600)\n"
          "--upload-budget BYTES per frame, bytes of finished tiles uploaded ahead of need\n"
          "                      (default 32M)\n"
          "--start-cell I,J      moves the whole path by that many cells (default 0,0)\n"
          "--repeat P            the cells' selection repeats every P cells (default: none)\n"
          "--seed N              seed of the generators, the selection and wander (default 1)\n"
          "--out DIR             output folder (default out-memtest)\n"
          "--quiet               no progress line and no summary lines\n",
          f);
    fputs(tw_gl_usage, f);
    fputs("Options take their value as --opt VALUE or --opt=VALUE; unique prefixes work;\n"
          "numbers are plain decimal digits.\n"
          "Limits: at most 10000000 frames (the distance over what the path moves a frame)\n"
          "and 1000000 rows of memory.csv, refused before the walk starts (exit status 2).\n"
          "Progress (stderr): on a terminal one line rewritten in place; otherwise a line\n"
          "every 10 s, or every TW_PROGRESS_INTERVAL_S seconds (environment; 0: every frame).\n",
          f);
}

enum {
    OPT_DISTANCE = TW_CLI_OPT_PROGRAM,
    OPT_EVERY,
    OPT_OUT,
    OPT_SWEEP,
};

static const struct option options_table[] = {
    TW_CLI_COMMON_OPTIONS,
    {"distance", required_argument, NULL, OPT_DISTANCE},
    {"every", required_argument, NULL, OPT_EVERY},
    {"out", required_argument, NULL, OPT_OUT},
    {"sweep", required_argument, NULL, OPT_SWEEP},
    TW_GL_OPTIONS,
    {NULL, 0, NULL, 0},
};

static void parse_sweep(const char *opt, const char *v, struct options *o)
{
    if (strncmp(v, "budget=", 7) != 0)
        tw_cli_fail(program, opt, "'%s' is not of the form budget=B1,B2,... (memtest sweeps the "
                    "cache budget only)", v);
    const char *s = v + 7;
    o->sweep_count = 0;
    for (;;) {
        const char *end = strchr(s, ',');
        const size_t n = end ? (size_t)(end - s) : strlen(s);
        if (n == 0)
            tw_cli_fail(program, opt, "'%s' has an empty value", v);
        if (o->sweep_count == MAX_SWEEP)
            tw_cli_fail(program, opt, "more than %d values", MAX_SWEEP);
        if (n >= sizeof(o->sweep_text[0]))
            tw_cli_fail(program, opt, "'%.*s' is not a byte count", (int)n, s);
        char *text = o->sweep_text[o->sweep_count];
        memcpy(text, s, n);
        text[n] = '\0';
        o->sweep[o->sweep_count] = tw_cli_bytes(program, opt, text, (uint64_t)1 << 50);
        for (uint32_t k = 0; k < o->sweep_count; k++)
            if (o->sweep[k] == o->sweep[o->sweep_count])
                tw_cli_fail(program, opt, "the budget '%s' is listed twice", text);
        o->sweep_count++;
        if (!end)
            break;
        s = end + 1;
    }
}

static void apply_option(void *user, int opt, const char *name, const char *v)
{
    struct options *o = user;
    if (tw_gl_option(&o->gl, opt, name, v))
        return;
    switch (opt) {
    case OPT_DISTANCE:
        /* Checked as a float, taken in double: 0.2 km is 200 m, not 200.000003. */
        tw_cli_float(program, name, v, 0.001f, 10000.0f);
        o->distance_m = 1000.0 * strtod(v, NULL);
        break;
    case OPT_EVERY:
        tw_cli_float(program, name, v, 1.0f, 1000000.0f);
        o->every_m = strtod(v, NULL);
        break;
    case OPT_OUT:
        if (*v == '\0')
            tw_cli_fail(program, name, "the output folder name is empty");
        o->out = v;
        break;
    case OPT_SWEEP: parse_sweep(name, v, o); break;
    default: tw_cli_fail(program, name, "unknown option '%s' (see tileworld memtest --help)", name);
    }
}

/* ---- the camera: a long path, a CSV repeated end to end ------------------------- */

struct walk {
    struct tw_path path;
    float footprint[2];
    uint32_t next;              /* key of the current repetition */
    int64_t shift_i, shift_j;   /* cells a repetition moves on: last key's - first key's */
    int64_t rep;                /* repetitions done */
    bool have_last;
    struct tw_camera last;
};

/* Metres from a to b (cells as integers first: exact far from the origin). */
static double step_m(const struct tw_camera *a, const struct tw_camera *b, const float fp[2])
{
    const double dx = (double)(b->pos.cell.i - a->pos.cell.i) * fp[0] +
                      ((double)b->pos.local[0] - a->pos.local[0]);
    const double dy = (double)b->pos.local[1] - a->pos.local[1];
    const double dz = (double)(b->pos.cell.j - a->pos.cell.j) * fp[1] +
                      ((double)b->pos.local[2] - a->pos.local[2]);
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* The next camera and the metres it moved (0 at the first, and at the jump
 * from a repetition's end to the next one's start). */
static int walk_next(struct walk *w, struct tw_camera *cam, double *moved)
{
    bool jump = false;
    if (w->next == w->path.count) {
        w->next = 0;
        w->rep++;
        jump = true;
    }
    *cam = w->path.keys[w->next++];
    const int64_t limit = (int64_t)1 << 62;
    const double di = (double)w->shift_i * (double)w->rep, dj = (double)w->shift_j * (double)w->rep;
    if (fabs(di) > (double)limit || fabs(dj) > (double)limit)
        return TW_ERR_LIMIT;
    cam->pos.cell.i += w->shift_i * w->rep;
    cam->pos.cell.j += w->shift_j * w->rep;
    *moved = w->have_last && !jump ? step_m(&w->last, cam, w->footprint) : 0.0;
    w->last = *cam;
    w->have_last = true;
    return TW_OK;
}

/* A built-in long path of enough frames for distance_m, or a CSV. */
static void walk_init(const struct options *o, const struct tw_cli_world *shown, struct walk *w)
{
    memset(w, 0, sizeof(*w));
    w->footprint[0] = shown->footprint[0];
    w->footprint[1] = shown->footprint[1];
    const char *name = o->cli.path;
    if (strcmp(name, "straight") == 0 || strcmp(name, "wander") == 0) {
        /* 2 m a frame (tw_path_builtin_speed); turns cost a little. */
        const double frames = ceil(o->distance_m / 2.0 * 1.05) + 16.0;
        if (frames > MAX_FRAMES)
            tw_cli_fail(program, "--distance", "%g km would take about %.0f frames, more than "
                        "memtest's limit of %.0f: give a shorter --distance",
                        o->distance_m / 1000.0, frames, MAX_FRAMES);
        const int err = tw_path_builtin(name, o->cli.world.selection.seed, (uint32_t)frames,
                                              0.0f, w->footprint[0], w->footprint[1], &w->path);
        if (err) {
            tw_cli_message(program, "--path %s: %s", name, tw_error_to_str(err));
            exit(1);
        }
        if (tw_path_translate(&w->path, o->cli.start_cell.i, o->cli.start_cell.j))
            tw_cli_fail(program, "--start-cell", "the translated path overflows the grid");
    } else {
        if (strcmp(name, "street") == 0 || strcmp(name, "flyover") == 0 ||
            strcmp(name, "forest") == 0 || strcmp(name, "teleport") == 0 ||
            strcmp(name, "spin") == 0)
            tw_cli_fail(program, "--path", "memtest walks straight, wander or a CSV file, not '%s'",
                        name);
        tw_cli_load_path(&o->cli, name, 0, w->footprint, &w->path);
    }
    if (w->path.count == 0)
        tw_cli_fail(program, "--path", "'%s' has no camera keys", name);
    const struct tw_camera *first = &w->path.keys[0], *last = &w->path.keys[w->path.count - 1];
    w->shift_i = last->pos.cell.i - first->pos.cell.i;
    w->shift_j = last->pos.cell.j - first->pos.cell.j;
    double length = 0.0;
    for (uint32_t k = 1; k < w->path.count; k++)
        length += step_m(&w->path.keys[k - 1], &w->path.keys[k], w->footprint);
    if (!(length > 0.0))
        tw_cli_fail(program, "--path", "'%s' does not move the camera: no distance to cover", name);
    /* Each repetition moves length metres in count frames (its first frame
     * moves none): the frames are known before one is rendered. */
    const double frames = ceil(o->distance_m / length) * (double)w->path.count;
    if (frames > MAX_FRAMES)
        tw_cli_fail(program, "--path", "'%s' moves %g m over its %u rows: %g km would take about "
                    "%.0f frames, more than memtest's limit of %.0f; give a path that moves "
                    "farther a row, or a shorter --distance", name, length, w->path.count,
                    o->distance_m / 1000.0, frames, MAX_FRAMES);
    const double rows = fmin(frames, floor(o->distance_m / o->every_m)) + 2.0;
    if (rows > MAX_ROWS)
        tw_cli_fail(program, "--every", "a row every %g m over %g km makes about %.0f rows of "
                    "memory.csv, more than memtest's limit of %.0f; give a larger --every or a "
                    "shorter --distance", o->every_m, o->distance_m / 1000.0, rows, MAX_ROWS);
}

/* ---- measuring ------------------------------------------------------------------ */

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

enum verdict { HELD, FAILED, NOT_APPLICABLE };

struct check {
    char name[40];      /* a few words, for the last line */
    char what[200];
    char figure[400];
    char why[160];      /* NOT_APPLICABLE: why, in a few words */
    enum verdict verdict;
};

static const char *verdict_name(enum verdict v)
{
    return v == HELD ? "yes" : v == FAILED ? "no" : "not applicable";
}

/* What one run measured. */
struct result {
    uint64_t budget;
    char budget_text[32];
    uint32_t frames;
    double distance_m;
    double wall_s;
    uint64_t loads_requested, loads_done, evictions, tile_evictions, reloads, reloads_library,
        refused, holes;
    uint64_t peak_total, final_total, peak_needed, peak_rss, final_rss, rss_start;
    uint64_t rss_first, rss_last;   /* peaks of the rows at 40-50 % and in the last 10 % */
    uint32_t rss_first_rows, rss_last_rows;
    uint64_t *rss_km;               /* RSS when each whole km was reached ([0]: the first frame) */
    uint32_t rss_km_count;
    uint64_t heap_used, heap_free, heap_free_peak; /* at the last record; the peak of the free */
    uint32_t frames_over, frames_over_needed, frames_over_other;
    uint64_t worst_over;            /* the most bytes over budget on a frame that was not excused */
    uint32_t worst_over_frame;
    double lat_median, lat_p99, lat_max;
    uint32_t lat_count;
    double mean_ms, median_ms, p99_ms, mean_cpu_ms;
    uint32_t accounting_mismatch_frames;
    uint32_t live_tiles, event_tiles;
    uint64_t live_bytes, event_bytes;
    uint64_t totals_loads_done, totals_evictions, totals_reloads;
    struct check checks[4];
    uint32_t check_count;
    bool all_held;
};

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

/* why: for NOT_APPLICABLE, why not (else NULL). */
static void add_check(struct result *r, enum verdict v, const char *name, const char *what,
                      const char *figure, const char *why)
{
    struct check *c = &r->checks[r->check_count++];
    snprintf(c->name, sizeof(c->name), "%s", name);
    snprintf(c->what, sizeof(c->what), "%s", what);
    snprintf(c->figure, sizeof(c->figure), "%s", figure);
    snprintf(c->why, sizeof(c->why), "%s", why ? why : "");
    c->verdict = v;
}

static void judge(struct result *r)
{
    char what[200], figure[400];
    r->check_count = 0;
    /* 1. the budget */
    if (r->budget == 0) {
        snprintf(figure, sizeof(figure), "no --budget: peak %.1f MiB of cache", r->peak_total / MIB);
        add_check(r, NOT_APPLICABLE, "within the budget", "cache bytes <= the budget on every "
                  "frame", figure, "no --budget given");
    } else {
        snprintf(what, sizeof(what), "cache bytes <= the budget (%.1f MiB) on every frame, except "
                 "frames whose visible set alone needs more", r->budget / MIB);
        int n = snprintf(figure, sizeof(figure), "peak %.1f MiB; %u of %u frames over the budget: "
                         "%u where the view needed more (peak need %.1f MiB), %u otherwise",
                         r->peak_total / MIB, r->frames_over, r->frames, r->frames_over_needed,
                         r->peak_needed / MIB, r->frames_over_other);
        if (r->frames_over_other && n > 0 && (size_t)n < sizeof(figure))
            snprintf(figure + n, sizeof(figure) - (size_t)n, " (worst %.2f MiB over at frame %u)",
                     r->worst_over / MIB, r->worst_over_frame);
        add_check(r, r->frames_over_other == 0 ? HELD : FAILED, "within the budget", what, figure,
                  NULL);
    }
    /* 2. RSS flat in distance */
    snprintf(what, sizeof(what), "RSS flat: peak over the last 10 %% of the distance <= %.2f x the "
             "peak over 40-50 %% of it (memory.csv's rows; the first part lets the cache fill "
             "and the allocator's heap settle)", RSS_GROWTH_BOUND);
    const double growth = r->rss_first ? (double)r->rss_last / (double)r->rss_first : 0.0;
    snprintf(figure, sizeof(figure), "40-50 %%: %.1f MiB, last 10 %%: %.1f MiB (%+.1f %%); "
             "the allocator's heap at the end: %.1f MiB in use, %.1f MiB held free",
             r->rss_first / MIB, r->rss_last / MIB, 100.0 * (growth - 1.0), r->heap_used / MIB,
             r->heap_free / MIB);
    if (r->rss_first_rows < 2 || r->rss_last_rows < 2) {
        snprintf(figure, sizeof(figure), "%u and %u rows at 40-50 %% and in the last 10 %%: --every "
                 "is too coarse for --distance to see a trend", r->rss_first_rows, r->rss_last_rows);
        add_check(r, NOT_APPLICABLE, "RSS flat", what, figure, "too few rows of memory.csv "
                  "for a trend: give a smaller --every or a longer --distance");
    } else {
        add_check(r, r->rss_first && growth <= RSS_GROWTH_BOUND ? HELD : FAILED, "RSS flat", what,
                  figure, NULL);
    }
    /* 3. no leak */
    const bool leak_free = r->accounting_mismatch_frames == 0 && r->live_tiles == r->event_tiles &&
                           r->live_bytes == r->event_bytes &&
                           r->totals_loads_done == r->loads_done &&
                           r->totals_evictions == r->tile_evictions &&
                           r->live_tiles + r->totals_evictions == r->totals_loads_done;
    snprintf(figure, sizeof(figure), "at the end %u tiles, %llu bytes live in the cache; loaded "
             "less evicted: %u tiles, %llu bytes (%llu loaded - %llu evicted); %u frames where "
             "they differed",
             r->live_tiles, (unsigned long long)r->live_bytes, r->event_tiles,
             (unsigned long long)r->event_bytes, (unsigned long long)r->loads_done,
             (unsigned long long)r->tile_evictions, r->accounting_mismatch_frames);
    add_check(r, leak_free ? HELD : FAILED, "no leak",
              "no leak: the live tiles and bytes the cache reports are what was loaded less what "
              "was evicted, on every frame", figure, NULL);
    /* 4. load latency */
    snprintf(what, sizeof(what), "load latency p99 <= %.0f frames (request to ready, at 2 m a "
             "frame)", LATENCY_P99_BOUND);
    if (r->lat_count == 0) {
        snprintf(figure, sizeof(figure), "no tile was loaded: nothing to time");
        add_check(r, NOT_APPLICABLE, "load latency", what, figure, "no tile was loaded in the "
                  "walk: only providers such as city-gen load tiles");
    } else {
        snprintf(figure, sizeof(figure), "median %.0f, p99 %.0f, max %.0f frames over %u loads",
                 r->lat_median, r->lat_p99, r->lat_max, r->lat_count);
        add_check(r, r->lat_p99 <= LATENCY_P99_BOUND ? HELD : FAILED, "load latency", what,
                  figure, NULL);
    }
    r->all_held = true;
    for (uint32_t k = 0; k < r->check_count; k++)
        r->all_held &= r->checks[k].verdict != FAILED;
}

/* What the progress line of the runs shows of this one. */
struct run_progress {
    struct tw_progress *line;
    double done_before;         /* metres walked by the runs before this one */
    char what[64];              /* "budget 16M, run 2 of 3; " in a sweep, else "" */
};

/* Walks the whole distance once with budget, writing dir/memory.csv. */
static int walk_once(const struct options *o, const struct tw_cli_world *shown, struct walk *walk,
                     struct tw_context *ctx, const char *dir, struct result *r,
                     const struct run_progress *progress, int *world_error, char *err,
                     size_t err_size)
{
    struct tw_world *world = NULL;
    struct tw_cell_map *evicted = NULL;
    struct tw_outfile csv = {0};
    struct values frame_ms = {0}, latency = {0};
    struct interval iv = {0};
    int rc = TW_OK;
    const double t0 = now_s();

    struct tw_world_settings ws = o->cli.world;
    tw_cli_world_apply(shown, &ws);
    ws.cache_budget_bytes = r->budget;
    ws.get_proc = tw_context_get_proc(ctx);
    ws.log = (struct tw_log){tw_cli_log, (void *)&o->cli};
    rc = tw_world_create_tuned(&ws, &o->cli.tuning, &world);
    if (rc) {
        *world_error = rc;
        snprintf(err, err_size, "cannot create the world: %s", tw_error_to_str(rc));
        goto out;
    }
    rc = tw_cell_map_create(&evicted);
    if (rc) {
        snprintf(err, err_size, "out of memory");
        goto out;
    }
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/memory.csv", dir);
    rc = tw_outfile_open(&csv, file, err, err_size);
    if (rc)
        goto out;
    tw_outfile_printf(&csv, "%s", memory_header);

    const uint32_t km_cap = (uint32_t)(o->distance_m / 1000.0) + 2;
    r->rss_km = calloc(km_cap, sizeof(*r->rss_km));
    if (!r->rss_km) {
        rc = TW_ERR_NOMEM;
        snprintf(err, err_size, "out of memory");
        goto out;
    }
    walk->next = 0;
    walk->rep = 0;
    walk->have_last = false;
    double distance = 0.0, next_record = 0.0, total_ms = 0.0, cpu_total = 0.0;
    uint64_t ready_bytes = 0, evicted_bytes = 0;
    uint32_t ready_tiles = 0, evicted_tiles = 0;
    for (uint32_t f = 0;; f++) {
        struct tw_camera cam;
        double moved = 0.0;
        rc = walk_next(walk, &cam, &moved);
        if (rc) {
            snprintf(err, err_size, "--path: the repeated path leaves the grid");
            goto out;
        }
        distance += moved;
        struct tw_frame_stats st;
        rc = tw_world_frame(world, &cam, &st);
        if (!rc)
            rc = tw_world_finish(world, &st);
        if (rc) {
            snprintf(err, err_size, "frame %u failed: %s", f + 1, tw_error_to_str(rc));
            goto out;
        }
        size_t event_count = 0;
        const struct tw_tile_event *events = tw_world_tile_events(world, &event_count);
        for (size_t k = 0; k < event_count && !rc; k++) {
            const struct tw_tile_event *e = &events[k];
            if (e->kind == TW_TILE_READY) {
                ready_tiles++;
                ready_bytes += e->bytes;
                r->loads_done++;
                r->reloads_library += e->reload;
                if (tw_cell_map_find(evicted, e->cell)) {
                    r->reloads++;
                    iv.reloads++;
                }
                rc = values_push(&latency, e->latency);
                if (!rc)
                    rc = values_push(&iv.latency, e->latency);
            } else if (e->kind == TW_TILE_EVICTED) {
                evicted_tiles++;
                evicted_bytes += e->bytes;
                r->tile_evictions++;
                rc = tw_cell_map_set(evicted, e->cell, f);
            } else {
                r->refused++;
            }
        }
        if (!rc)
            rc = values_push(&frame_ms, st.ms_frame);
        if (rc) {
            snprintf(err, err_size, "out of memory");
            goto out;
        }
        struct tw_cache_totals totals;
        tw_world_cache_totals(world, &totals);
        if (totals.tiles_ready != ready_tiles - evicted_tiles ||
            totals.tile_bytes != ready_bytes - evicted_bytes)
            r->accounting_mismatch_frames++;

        const uint64_t total = st.bytes_cpu + st.bytes_gpu;
        r->frames++;
        if (total > r->peak_total)
            r->peak_total = total;
        if (st.bytes_needed > r->peak_needed)
            r->peak_needed = st.bytes_needed;
        if (r->budget && total > r->budget) {
            r->frames_over++;
            if (st.bytes_needed > r->budget) {
                r->frames_over_needed++;
            } else {
                r->frames_over_other++;
                if (total - r->budget > r->worst_over) {
                    r->worst_over = total - r->budget;
                    r->worst_over_frame = f + 1;
                }
            }
        }
        r->loads_requested += st.loads_requested;
        r->evictions += st.evictions;
        r->holes += st.tiles_pending;
        const uint64_t rss = rss_bytes();
        if (f == 0)
            r->rss_start = rss;
        if (rss > r->peak_rss)
            r->peak_rss = rss;
        r->final_rss = rss;
        while (r->rss_km_count < km_cap && distance >= 1000.0 * r->rss_km_count)
            r->rss_km[r->rss_km_count++] = rss;

        iv.frames++;
        iv.loads_requested += st.loads_requested;
        iv.loads_done += st.loads_done;
        iv.evictions += st.evictions;
        iv.holes += st.tiles_pending;
        iv.ms += st.ms_frame;
        iv.cpu_ms += st.cpu_ms;
        if (st.ms_frame > iv.ms_max)
            iv.ms_max = st.ms_frame;
        total_ms += st.ms_frame;
        cpu_total += st.cpu_ms;

        const bool done = distance >= o->distance_m - 1e-3;
        if (done || distance >= next_record - 1e-3) {
            const double lat_median = tw_report_percentile(iv.latency.v, iv.latency.n, 50.0);
            const double lat_p99 = tw_report_percentile(iv.latency.v, iv.latency.n, 99.0);
            const struct heap_figures heap = heap_figures();
            /* Check 2 reads the recorded rows, the series memory.csv and the chart
             * show: a frame's RSS also holds the tiles being made at that moment
             * (the arrays a worker builds a tile in, until it is packed), and the
             * peak of single frames is in the figures, not in the trend. */
            if (distance >= 0.4 * o->distance_m - 1e-3 && distance <= 0.5 * o->distance_m + 1e-3) {
                r->rss_first_rows++;
                if (rss > r->rss_first)
                    r->rss_first = rss;
            }
            if (distance >= 0.9 * o->distance_m - 1e-3) {
                r->rss_last_rows++;
                if (rss > r->rss_last)
                    r->rss_last = rss;
            }
            r->heap_used = heap.used;
            r->heap_free = heap.held_free;
            if (heap.held_free > r->heap_free_peak)
                r->heap_free_peak = heap.held_free;
            tw_outfile_printf(&csv, "%.1f,%u,%llu,%llu,%llu,%llu,%llu,%llu,%u,%u,%llu,%llu,%llu,"
                              "%llu,%.0f,%.0f,%llu,%llu,%.3f,%.3f,%.3f,%llu,%llu,%llu,%u\n",
                              distance, f + 1, (unsigned long long)st.bytes_state,
                              (unsigned long long)(st.bytes_cpu - st.bytes_state),
                              (unsigned long long)st.bytes_gpu, (unsigned long long)total,
                              (unsigned long long)st.bytes_needed, (unsigned long long)r->budget,
                              st.tiles_cached, totals.tiles_ready,
                              (unsigned long long)iv.loads_requested,
                              (unsigned long long)iv.loads_done, (unsigned long long)iv.evictions,
                              (unsigned long long)iv.reloads, lat_median, lat_p99,
                              (unsigned long long)iv.holes, (unsigned long long)rss,
                              iv.ms / iv.frames, iv.cpu_ms / iv.frames, iv.ms_max,
                              (unsigned long long)heap.used, (unsigned long long)heap.held_free,
                              (unsigned long long)st.bytes_loading, st.tiles_loading);
            const struct values keep = iv.latency;
            memset(&iv, 0, sizeof(iv));
            iv.latency = keep;
            iv.latency.n = 0;
            while (next_record <= distance + 1e-3)
                next_record += o->every_m;
        }
        char note[128];
        snprintf(note, sizeof(note), "%s%.1f ms/frame", progress->what, total_ms / (f + 1));
        tw_progress_update(progress->line, progress->done_before + fmin(distance, o->distance_m),
                           note);
        if (done) {
            r->final_total = total;
            r->live_tiles = totals.tiles_ready;
            r->live_bytes = totals.tile_bytes;
            r->event_tiles = ready_tiles - evicted_tiles;
            r->event_bytes = ready_bytes - evicted_bytes;
            r->totals_loads_done = totals.loads_done;
            r->totals_evictions = totals.evictions;
            r->totals_reloads = totals.reloads;
            break;
        }
    }
    rc = tw_outfile_commit(&csv, err, err_size);
    if (rc)
        goto out;
    r->distance_m = distance;
    r->lat_count = latency.n;
    r->lat_median = tw_report_percentile(latency.v, latency.n, 50.0);
    r->lat_p99 = tw_report_percentile(latency.v, latency.n, 99.0);
    r->lat_max = tw_report_percentile(latency.v, latency.n, 100.0);
    double sum = 0.0;
    for (uint32_t k = 0; k < frame_ms.n; k++)
        sum += frame_ms.v[k];
    r->mean_cpu_ms = r->frames ? cpu_total / r->frames : 0.0;
    r->mean_ms = frame_ms.n ? sum / frame_ms.n : 0.0;
    r->median_ms = tw_report_percentile(frame_ms.v, frame_ms.n, 50.0);
    r->p99_ms = tw_report_percentile(frame_ms.v, frame_ms.n, 99.0);
    r->wall_s = now_s() - t0;
out:
    tw_outfile_discard(&csv);
    tw_world_destroy(world);
    tw_cell_map_destroy(evicted);
    free(frame_ms.v);
    free(latency.v);
    free(iv.latency.v);
    return rc;
}

/* ---- reports ---------------------------------------------------------------------- */

static json_object *number(double v, int decimals)
{
    char text[64];
    snprintf(text, sizeof(text), "%.*f", decimals, v);
    return json_object_new_double_s(v, text);
}

static json_object *u64(uint64_t v)
{
    return json_object_new_int64(v > (uint64_t)INT64_MAX ? INT64_MAX : (int64_t)v);
}

static const char *policy_name(enum tw_stream_policy p)
{
    return p == TW_STREAM_SKIP ? "skip" : "wait";
}

static json_object *result_json(const struct options *o, const struct tw_cli_world *shown,
                                const struct result *r)
{
    json_object *root = json_object_new_object();
    json_object_object_add(root, "tileset", json_object_new_string(shown->name));
    json_object_object_add(root, "path", json_object_new_string(o->cli.path));
    char size[64];
    snprintf(size, sizeof(size), "%ux%u", o->cli.world.width, o->cli.world.height);
    json_object_object_add(root, "size", json_object_new_string(size));
    json_object_object_add(root, "seed", u64(o->cli.world.selection.seed));
    json_object_object_add(root, "heap_used_bytes", u64(r->heap_used));
    json_object_object_add(root, "heap_free_bytes", u64(r->heap_free));
    json_object_object_add(root, "peak_heap_free_bytes", u64(r->heap_free_peak));
    json_object_object_add(root, "budget_bytes", u64(r->budget));
    json_object_object_add(root, "workers", json_object_new_int64(o->cli.world.workers));
    json_object_object_add(root, "policy", json_object_new_string(policy_name(o->cli.world.policy)));
    json_object_object_add(root, "view_distance", number(o->cli.world.view_distance, 1));
    json_object_object_add(root, "distance_m", number(r->distance_m, 1));
    json_object_object_add(root, "every_m", number(o->every_m, 1));
    json_object_object_add(root, "frames", json_object_new_int64(r->frames));
    json_object_object_add(root, "wall_s", number(r->wall_s, 1));
    json_object_object_add(root, "peak_cache_bytes", u64(r->peak_total));
    json_object_object_add(root, "final_cache_bytes", u64(r->final_total));
    json_object_object_add(root, "peak_needed_bytes", u64(r->peak_needed));
    json_object_object_add(root, "frames_over_budget", json_object_new_int64(r->frames_over));
    json_object_object_add(root, "frames_over_budget_view_needed",
                           json_object_new_int64(r->frames_over_needed));
    json_object_object_add(root, "frames_over_budget_otherwise",
                           json_object_new_int64(r->frames_over_other));
    json_object_object_add(root, "rss_start_bytes", u64(r->rss_start));
    json_object_object_add(root, "peak_rss_bytes", u64(r->peak_rss));
    json_object_object_add(root, "final_rss_bytes", u64(r->final_rss));
    json_object *km = json_object_new_array();
    for (uint32_t k = 0; k < r->rss_km_count; k++)
        json_object_array_add(km, u64(r->rss_km[k]));
    json_object_object_add(root, "rss_bytes_by_km", km);
    json_object_object_add(root, "loads_requested", u64(r->loads_requested));
    json_object_object_add(root, "loads_done", u64(r->loads_done));
    json_object_object_add(root, "evictions", u64(r->evictions));
    json_object_object_add(root, "tile_evictions", u64(r->tile_evictions));
    json_object_object_add(root, "reloads", u64(r->reloads));
    json_object_object_add(root, "reloads_library", u64(r->totals_reloads));
    json_object_object_add(root, "refused", u64(r->refused));
    json_object_object_add(root, "holes", u64(r->holes));
    json_object_object_add(root, "latency_median_frames", number(r->lat_median, 0));
    json_object_object_add(root, "latency_p99_frames", number(r->lat_p99, 0));
    json_object_object_add(root, "latency_max_frames", number(r->lat_max, 0));
    json_object_object_add(root, "mean_ms", number(r->mean_ms, 3));
    json_object_object_add(root, "median_ms", number(r->median_ms, 3));
    json_object_object_add(root, "p99_ms", number(r->p99_ms, 3));
    json_object_object_add(root, "mean_cpu_ms", number(r->mean_cpu_ms, 3));
    json_object *checks = json_object_new_array();
    for (uint32_t k = 0; k < r->check_count; k++) {
        json_object *c = json_object_new_object();
        json_object_object_add(c, "must_hold", json_object_new_string(r->checks[k].what));
        json_object_object_add(c, "figure", json_object_new_string(r->checks[k].figure));
        json_object_object_add(c, "held", json_object_new_string(verdict_name(r->checks[k].verdict)));
        json_object_array_add(checks, c);
    }
    json_object_object_add(root, "checks", checks);
    json_object_object_add(root, "all_held", json_object_new_boolean(r->all_held));
    return root;
}

static void md_checks(struct tw_outfile *f, const struct result *r)
{
    tw_outfile_printf(f, "| what must hold | figure | held |\n|---|---|---|\n");
    for (uint32_t k = 0; k < r->check_count; k++) {
        const struct check *c = &r->checks[k];
        tw_outfile_printf(f, "| %s | %s | %s |\n", c->what, c->figure,
                          c->verdict == FAILED ? "**no**" : verdict_name(c->verdict));
    }
}

static void md_rss_km(struct tw_outfile *f, const struct result *r)
{
    tw_outfile_printf(f, "RSS when each kilometre was reached (MiB):");
    for (uint32_t k = 0; k < r->rss_km_count; k++)
        tw_outfile_printf(f, "%s %u km %.1f", k ? "," : "", k, r->rss_km[k] / MIB);
    tw_outfile_printf(f, ".\n");
}

static int write_run_summary(const struct options *o, const struct tw_cli_world *shown,
                             const char *dir, const struct result *r, char *err, size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/summary.json", dir);
    json_object *root = result_json(o, shown, r);
    int rc = tw_report_write_json(file, root, JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED,
                                  err, err_size);
    json_object_put(root);
    if (rc)
        return rc;
    snprintf(file, sizeof(file), "%s/summary.md", dir);
    struct tw_outfile f;
    rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char name[512];
    tw_outfile_printf(&f, "# tileworld memtest: %s, path %s, %.2f km, budget %s, %ux%u, seed %llu\n\n",
                      tw_cli_escape(shown->name, name, sizeof(name)), o->cli.path,
                      r->distance_m / 1000.0, r->budget ? r->budget_text : "none",
                      o->cli.world.width, o->cli.world.height,
                      (unsigned long long)o->cli.world.selection.seed);
    char workers[32];
    if (o->cli.world.workers)
        snprintf(workers, sizeof(workers), "%u", o->cli.world.workers);
    else
        snprintf(workers, sizeof(workers), "the default number of");
    tw_outfile_printf(&f, "%u frames in %.1f s (policy %s, %s workers, view distance %g m); one "
                          "row of memory.csv every %g m.\n\n", r->frames, r->wall_s,
                      policy_name(o->cli.world.policy), workers, o->cli.world.view_distance,
                      o->every_m);
    md_checks(&f, r);
    tw_outfile_printf(&f, "\n| figure | value |\n|---|---|\n");
    tw_outfile_printf(&f, "| cache bytes, peak / final | %.1f / %.1f MiB |\n", r->peak_total / MIB,
                      r->final_total / MIB);
    tw_outfile_printf(&f, "| the view's need, peak | %.1f MiB |\n", r->peak_needed / MIB);
    tw_outfile_printf(&f, "| RSS, start / peak / final | %.1f / %.1f / %.1f MiB |\n",
                      r->rss_start / MIB, r->peak_rss / MIB, r->final_rss / MIB);
    tw_outfile_printf(&f, "| heap in use / held free by the allocator, final (peak free) | %.1f / "
                      "%.1f (%.1f) MiB |\n", r->heap_used / MIB, r->heap_free / MIB,
                      r->heap_free_peak / MIB);
    tw_outfile_printf(&f, "| loads requested / done | %llu / %llu |\n",
                      (unsigned long long)r->loads_requested, (unsigned long long)r->loads_done);
    tw_outfile_printf(&f, "| evictions: generated tiles / with culling state | %llu / %llu |\n",
                      (unsigned long long)r->tile_evictions, (unsigned long long)r->evictions);
    tw_outfile_printf(&f, "| reloads (a cell loaded again after its eviction) | %llu |\n",
                      (unsigned long long)r->reloads);
    tw_outfile_printf(&f, "| load latency median / p99 / max | %.0f / %.0f / %.0f frames |\n",
                      r->lat_median, r->lat_p99, r->lat_max);
    tw_outfile_printf(&f, "| holes (policy skip) | %llu |\n", (unsigned long long)r->holes);
    tw_outfile_printf(&f, "| frame time mean / median / p99 | %.2f / %.2f / %.2f ms |\n\n",
                      r->mean_ms, r->median_ms, r->p99_ms);
    md_rss_km(&f, r);
    tw_outfile_printf(&f, "\nCharts: chart-memory.png (bytes and RSS against distance), "
                          "chart-loads.png (loads, evictions, reloads).\n");
    return tw_outfile_commit(&f, err, err_size);
}

static int write_sweep(const struct options *o, const struct tw_cli_world *shown,
                       const struct result *results, uint32_t count, char *err, size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/sweep.csv", o->out);
    struct tw_outfile csv;
    int rc = tw_outfile_open(&csv, file, err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&csv, "budget_bytes,frames,distance_m,loads_done,tile_evictions,reloads,"
                            "peak_cache_bytes,final_cache_bytes,peak_rss_bytes,latency_p99,holes,"
                            "mean_ms,p99_ms,all_held,mean_cpu_ms\n");
    for (uint32_t k = 0; k < count; k++) {
        const struct result *r = &results[k];
        tw_outfile_printf(&csv, "%llu,%u,%.1f,%llu,%llu,%llu,%llu,%llu,%llu,%.0f,%llu,%.3f,%.3f,%d,%.3f\n",
                          (unsigned long long)r->budget, r->frames, r->distance_m,
                          (unsigned long long)r->loads_done, (unsigned long long)r->tile_evictions,
                          (unsigned long long)r->reloads, (unsigned long long)r->peak_total,
                          (unsigned long long)r->final_total, (unsigned long long)r->peak_rss,
                          r->lat_p99, (unsigned long long)r->holes, r->mean_ms, r->p99_ms,
                          r->all_held, r->mean_cpu_ms);
    }
    rc = tw_outfile_commit(&csv, err, err_size);
    if (rc)
        return rc;
    json_object *root = json_object_new_object();
    json_object *runs = json_object_new_array();
    bool all = true;
    for (uint32_t k = 0; k < count; k++) {
        json_object_array_add(runs, result_json(o, shown, &results[k]));
        all &= results[k].all_held;
    }
    json_object_object_add(root, "sweep", json_object_new_string("budget"));
    json_object_object_add(root, "runs", runs);
    json_object_object_add(root, "all_held", json_object_new_boolean(all));
    snprintf(file, sizeof(file), "%s/summary.json", o->out);
    rc = tw_report_write_json(file, root, JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED, err,
                              err_size);
    json_object_put(root);
    if (rc)
        return rc;
    snprintf(file, sizeof(file), "%s/summary.md", o->out);
    struct tw_outfile f;
    rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char name[512];
    tw_outfile_printf(&f, "# tileworld memtest sweep of the cache budget: %s, path %s, %.2f km, "
                          "%ux%u, seed %llu\n\n", tw_cli_escape(shown->name, name, sizeof(name)),
                      o->cli.path, o->distance_m / 1000.0, o->cli.world.width, o->cli.world.height,
                      (unsigned long long)o->cli.world.selection.seed);
    tw_outfile_printf(&f, "One run per budget, each in sweep-budget-VALUE/ (memory.csv, summaries, "
                          "charts); chart-sweep-budget.png: reloads and frame time against the "
                          "budget.\n\n| budget | peak cache MiB | final MiB | peak RSS MiB | loads | "
                          "evictions | reloads | latency p99 | holes | mean ms | p99 ms | checks |\n"
                          "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (uint32_t k = 0; k < count; k++) {
        const struct result *r = &results[k];
        tw_outfile_printf(&f, "| %s | %.1f | %.1f | %.1f | %llu | %llu | %llu | %.0f | %llu | %.2f | "
                              "%.2f | %s |\n", r->budget_text, r->peak_total / MIB,
                          r->final_total / MIB, r->peak_rss / MIB,
                          (unsigned long long)r->loads_done, (unsigned long long)r->tile_evictions,
                          (unsigned long long)r->reloads, r->lat_p99,
                          (unsigned long long)r->holes, r->mean_ms, r->p99_ms,
                          r->all_held ? "held" : "**some did not hold**");
    }
    for (uint32_t k = 0; k < count; k++) {
        tw_outfile_printf(&f, "\n## budget %s\n\n", results[k].budget_text);
        md_checks(&f, &results[k]);
    }
    return tw_outfile_commit(&f, err, err_size);
}

/* chart-data/run.gp and charts.gp (memtest.gp), then gnuplot: missing or
 * failing is a warning. */
static int draw_charts(const struct options *o, const struct tw_cli_world *shown, const char *dir,
                       uint64_t budget, bool sweep, char *err, size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA, dir);
    const int e = tw_report_make_dirs(file);
    if (e) {
        snprintf(err, err_size, "%s: cannot create: %s", file, strerror(e));
        return TW_ERR_IO;
    }
    snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA "/run.gp", dir);
    struct tw_outfile f;
    int rc = tw_outfile_open(&f, file, err, err_size);
    if (rc)
        return rc;
    char title[600];
    snprintf(title, sizeof(title), "%s, path %s, %.2f km, %ux%u, policy %s", shown->name,
             o->cli.path, o->distance_m / 1000.0, o->cli.world.width, o->cli.world.height,
             policy_name(o->cli.world.policy));
    tw_outfile_printf(&f, "# What the run was, for charts.gp (written by tileworld memtest)\n"
                          "run_title = '");
    for (const char *c = title; *c; c++) {
        const char ch = (unsigned char)*c < 0x20 || *c == 0x7f ? '?' : *c;
        tw_outfile_printf(&f, ch == '\'' ? "''" : "%c", ch);
    }
    tw_outfile_printf(&f, "'\nbudget = %llu.0\nsweep = %d\n", (unsigned long long)budget, sweep);
    rc = tw_outfile_commit(&f, err, err_size);
    if (rc)
        return rc;
    snprintf(file, sizeof(file), "%s/charts.gp", dir);
    rc = tw_outfile_write_all(file, TW_MEMTEST_GP, strlen(TW_MEMTEST_GP), err, err_size);
    if (rc)
        return rc;
    rc = tw_charts_run_gnuplot(dir, err, err_size);
    if (rc == TW_CHARTS_NOT_DRAWN) {
        tw_cli_message(program, "warning: %s", err);
        rc = TW_OK;
    }
    return rc;
}

/* Appends printf text to out (size bytes, *len used), cut to fit. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static void append(char *out, size_t size, size_t *len, const char *fmt, ...)
{
    if (*len + 1 >= size)
        return;
    va_list ap;
    va_start(ap, fmt);
    const int n = vsnprintf(out + *len, size - *len, fmt, ap);
    va_end(ap);
    if (n > 0)
        *len = *len + (size_t)n < size ? *len + (size_t)n : size - 1;
}

/* The verdict over the runs, for the last line: how many checks held, which
 * did not, which were not applicable and why. Every run has the same checks
 * in the same order. */
static void verdict_text(const struct result *results, uint32_t runs, char *out, size_t size)
{
    uint32_t held = 0, failed = 0, not_applicable = 0, total = 0;
    for (uint32_t k = 0; k < runs; k++)
        for (uint32_t c = 0; c < results[k].check_count; c++) {
            const enum verdict v = results[k].checks[c].verdict;
            held += v == HELD;
            failed += v == FAILED;
            not_applicable += v == NOT_APPLICABLE;
            total++;
        }
    size_t len = 0;
    out[0] = '\0';
    if (failed)
        append(out, size, &len, "SOME CHECKS DID NOT HOLD: ");
    if (held == total)
        append(out, size, &len, "all %u checks held", total);
    else
        append(out, size, &len, "%u of %u checks held", held, total);
    if (runs > 1)
        append(out, size, &len, " over %u runs", runs);
    for (int pass = 0; pass < 2; pass++) {
        const enum verdict want = pass == 0 ? FAILED : NOT_APPLICABLE;
        const uint32_t count = pass == 0 ? failed : not_applicable;
        if (count == 0)
            continue;
        append(out, size, &len, pass == 0 ? "; %u did not: " : "; %u not applicable: ", count);
        bool first = true;
        for (uint32_t c = 0; c < results[0].check_count; c++) {
            uint32_t in = 0;
            const struct check *example = NULL;
            for (uint32_t k = 0; k < runs; k++)
                if (c < results[k].check_count && results[k].checks[c].verdict == want) {
                    in++;
                    if (!example)
                        example = &results[k].checks[c];
                }
            if (!in)
                continue;
            append(out, size, &len, "%s%s", first ? "" : ", ", example->name);
            if (runs > 1)
                append(out, size, &len, " in %u of %u runs", in, runs);
            if (want == NOT_APPLICABLE)
                append(out, size, &len, " (%s)", example->why);
            first = false;
        }
    }
}

static void print_checks(const char *dir, const struct result *r)
{
    printf("%s (budget %s):\n", dir, r->budget ? r->budget_text : "none");
    for (uint32_t k = 0; k < r->check_count; k++)
        printf("  %-14s %s: %s\n", verdict_name(r->checks[k].verdict), r->checks[k].what,
               r->checks[k].figure);
}

/* One run into dir: stale outputs removed, the walk, summaries, charts. The
 * progress line is finished after the last run's walk, cleared after the
 * others' (what a run prints goes on lines of its own). */
static int memtest_run(const struct options *o, const struct tw_cli_world *shown,
                       struct walk *walk, struct tw_context *ctx, const char *dir,
                       struct result *r, const struct run_progress *progress, bool last,
                       int *world_error, char *err, size_t err_size)
{
    int rc = tw_outputs_remove_stale(dir, err, err_size);
    if (rc)
        return rc;
    const int e = tw_report_make_dirs(dir);
    if (e) {
        snprintf(err, err_size, "%s: cannot create the output folder: %s", dir, strerror(e));
        return TW_ERR_INVALID;
    }
    rc = walk_once(o, shown, walk, ctx, dir, r, progress, world_error, err, err_size);
    if (rc)
        return rc;
    if (last)
        tw_progress_finish(progress->line);
    else
        tw_progress_clear(progress->line);
    judge(r);
    rc = write_run_summary(o, shown, dir, r, err, err_size);
    if (!rc)
        rc = draw_charts(o, shown, dir, r->budget, false, err, err_size);
    if (!rc && !o->cli.quiet)
        print_checks(dir, r);
    return rc;
}

int tw_memtest_main(int argc, char **argv)
{
    struct options o;
    memset(&o, 0, sizeof(o));
    tw_cli_init(&o.cli, program);
    o.cli.tileset = "city-gen";
    o.cli.world.width = 320;
    o.cli.world.height = 180;
    o.distance_m = 5000.0;
    o.every_m = 100.0;
    o.out = "out-memtest";
    tw_cli_parse(&o.cli, argc, argv, options_table, apply_option, &o, usage);
    if (!o.cli.path)
        o.cli.path = "straight";
    if (tw_cli_given(&o.cli, TW_CLI_OPT_FRAMES))
        tw_cli_fail(program, "--frames", "memtest walks a distance: give --distance KM");
    if (o.sweep_count && tw_cli_given(&o.cli, TW_CLI_OPT_BUDGET))
        tw_cli_fail(program, "--sweep", "--sweep budget=... and --budget are two kinds of run; "
                    "give one");

    const struct tw_log log = {tw_cli_log, &o.cli};
    struct tw_cli_world shown;
    tw_cli_world_load(&o.cli, 0, &log, &shown);
    struct walk walk;
    walk_init(&o, &shown, &walk);

    const uint32_t runs = o.sweep_count ? o.sweep_count : 1;
    struct tw_progress line;
    memset(&line, 0, sizeof(line));
    struct result *results = calloc(runs, sizeof(*results));
    struct tw_context *ctx = NULL;
    char msg[1400];
    int status = 1, world_error = 0;
    int err = results ? tw_gl_context_create(&o.gl, o.cli.world.width, o.cli.world.height, &log,
                                             &ctx)
                      : TW_ERR_NOMEM;
    if (err) {
        if (err == TW_ERR_NOMEM)
            tw_cli_message(program, "out of memory");
        goto out;
    }
    if (o.sweep_count) {
        err = tw_outputs_remove_stale(o.out, msg, sizeof(msg));
        const int e = err ? 0 : tw_report_make_dirs(o.out);
        if (e) {
            snprintf(msg, sizeof(msg), "%s: cannot create the output folder: %s", o.out, strerror(e));
            err = TW_ERR_INVALID;
        }
    }
    tw_progress_init(&line, o.out, o.distance_m * runs, "m", 0, o.cli.quiet);
    for (uint32_t k = 0; k < runs && !err; k++) {
        struct result *r = &results[k];
        struct run_progress progress = {&line, o.distance_m * k, ""};
        char dir[1000];
        if (o.sweep_count) {
            r->budget = o.sweep[k];
            snprintf(r->budget_text, sizeof(r->budget_text), "%s", o.sweep_text[k]);
            snprintf(dir, sizeof(dir), "%s/sweep-budget-%s", o.out, o.sweep_text[k]);
            snprintf(progress.what, sizeof(progress.what), "budget %s, run %u of %u; ",
                     o.sweep_text[k], k + 1, runs);
        } else {
            r->budget = o.cli.world.cache_budget_bytes;
            if (r->budget && r->budget % (1u << 20) == 0)
                snprintf(r->budget_text, sizeof(r->budget_text), "%lluM",
                         (unsigned long long)(r->budget >> 20));
            else
                snprintf(r->budget_text, sizeof(r->budget_text), "%llu",
                         (unsigned long long)r->budget);
            snprintf(dir, sizeof(dir), "%s", o.out);
        }
        err = memtest_run(&o, &shown, &walk, ctx, dir, r, &progress, k + 1 == runs, &world_error,
                          msg, sizeof(msg));
    }
    if (!err && o.sweep_count) {
        err = write_sweep(&o, &shown, results, runs, msg, sizeof(msg));
        if (!err)
            err = draw_charts(&o, &shown, o.out, 0, true, msg, sizeof(msg));
    }
    if (err) {
        tw_progress_finish(&line);
        /* A world refused for the user's settings has said why in one line. */
        if (world_error) {
            if (o.cli.errors_logged == 0)
                tw_cli_message(program, "%s", msg);
            status = tw_cli_world_exit_status(world_error);
        } else {
            tw_cli_message(program, "%s", msg);
            status = err == TW_ERR_INVALID ? TW_CLI_EXIT_USAGE : 1;
        }
        goto out;
    }
    bool all = true;
    for (uint32_t k = 0; k < runs; k++)
        all &= results[k].all_held;
    if (!o.cli.quiet) {
        char verdict[1000];
        verdict_text(results, runs, verdict, sizeof(verdict));
        tw_cli_message(program, "wrote %s/summary.md: %s", o.out, verdict);
    }
    status = all ? 0 : 3;
out:
    tw_context_destroy(ctx);
    for (uint32_t k = 0; results && k < runs; k++)
        free(results[k].rss_km);
    free(results);
    tw_path_finish(&walk.path);
    tw_cli_world_finish(&shown);
    return status;
}
