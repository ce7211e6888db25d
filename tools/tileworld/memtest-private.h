/*
 * tileworld memtest's insides, shared by the files that make it: memtest.c
 * (the options, the usage text, the runs), memtest-path.c (the camera's
 * walk along the path), memtest-walk.c (the memory figures, one walk
 * through the world into memory.csv), memtest-checks.c (what must hold, the
 * verdict) and memtest-report.c (summary.json, summary.md, the sweep's
 * table, the charts). Private to the tileworld program.
 */
#ifndef TW_TOOLS_MEMTEST_PRIVATE_H
#define TW_TOOLS_MEMTEST_PRIVATE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tools/cli.h"
#include "tools/progress.h"

/* The name in front of every message. */
#define TW_MEMTEST_PROGRAM "tileworld"
/* Most values of --sweep budget=... */
#define TW_MEMTEST_MAX_SWEEP 16
/* Bytes in a MiB, for the figures. */
#define TW_MEMTEST_MIB (1024.0 * 1024.0)

/* The command line. */
struct tw_memtest_options {
    struct tw_cli cli;
    double distance_m;
    double every_m;
    const char *out;
    uint64_t sweep[TW_MEMTEST_MAX_SWEEP];
    char sweep_text[TW_MEMTEST_MAX_SWEEP][32];
    uint32_t sweep_count;
    struct tw_context_settings gl; /* --gl, --gpu */
};

/* ---- the camera: a long path, a CSV repeated end to end ------------------------- */

struct tw_memtest_walk {
    struct tw_path path;
    float footprint[2];
    uint32_t next;              /* key of the current repetition */
    int64_t shift_i, shift_j;   /* cells a repetition moves on: last key's - first key's */
    int64_t rep;                /* repetitions done */
    bool have_last;
    struct tw_camera last;
};

/* The walk for o over the world shown: a built-in long path of enough frames
 * for o->distance_m, or a CSV. A run too long for memtest's limits, or a path
 * that does not move, is refused (exit status 2); w->path is the caller's, to
 * free with tw_path_finish. */
void tw_memtest_walk_init(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                          struct tw_memtest_walk *w);

/* The walk back at its first key, for the next run. */
void tw_memtest_walk_restart(struct tw_memtest_walk *w);

/* The next camera and the metres it moved (0 at the first, and at the jump
 * from a repetition's end to the next one's start). TW_ERR_LIMIT when the
 * repeated path leaves the grid. */
int tw_memtest_walk_next(struct tw_memtest_walk *w, struct tw_camera *cam, double *moved);

/* ---- one run -------------------------------------------------------------------- */

enum tw_memtest_verdict { TW_MEMTEST_HELD, TW_MEMTEST_FAILED, TW_MEMTEST_NOT_APPLICABLE };

struct tw_memtest_check {
    char name[40];      /* a few words, for the last line */
    char what[200];
    char figure[400];
    char why[160];      /* TW_MEMTEST_NOT_APPLICABLE: why, in a few words */
    enum tw_memtest_verdict verdict;
};

/* What one run measured. */
struct tw_memtest_result {
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
    struct tw_memtest_check checks[4];
    uint32_t check_count;
    bool all_held;
};

/* What the progress line of the runs shows of this one. */
struct tw_memtest_progress {
    struct tw_progress *line;
    double done_before;         /* metres walked by the runs before this one */
    char what[64];              /* "budget 16M, run 2 of 3; " in a sweep, else "" */
};

/* Walks the whole distance once with r->budget, writing dir/memory.csv and
 * filling r's figures (r->budget and r->budget_text are the caller's; r->rss_km
 * is allocated here, the caller frees it, also on failure). Returns 0 or an
 * error with a line in err; *world_error is the world's error when the world
 * could not be made for the settings. */
int tw_memtest_walk_once(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                         struct tw_memtest_walk *walk, struct tw_context *ctx, const char *dir,
                         struct tw_memtest_result *r, const struct tw_memtest_progress *progress,
                         int *world_error, char *err, size_t err_size);

/* ---- what must hold ------------------------------------------------------------ */

/* Judges r's checks: fills r->checks, r->check_count and r->all_held. */
void tw_memtest_judge(struct tw_memtest_result *r);

/* The verdict over the runs results, for the last line, into out (size
 * bytes, cut to fit): how many checks held, which did not, which were not
 * applicable and why. */
void tw_memtest_verdict_text(const struct tw_memtest_result *results, uint32_t runs, char *out,
                             size_t size);

/* ---- reports -------------------------------------------------------------------- */

/* dir/summary.json and dir/summary.md of one run. Returns 0 or an error with
 * a line in err. */
int tw_memtest_write_run_summary(const struct tw_memtest_options *o,
                                 const struct tw_cli_world *shown, const char *dir,
                                 const struct tw_memtest_result *r, char *err, size_t err_size);

/* The sweep's o->out/sweep.csv, summary.json and summary.md over count runs.
 * Returns 0 or an error with a line in err. */
int tw_memtest_write_sweep(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                           const struct tw_memtest_result *results, uint32_t count, char *err,
                           size_t err_size);

/* dir's charts: chart-data/run.gp (budget: the line drawn; sweep: the sweep's
 * chart), charts.gp, then gnuplot, whose absence or failure is a warning.
 * Returns 0 or an error with a line in err. */
int tw_memtest_draw_charts(const struct tw_memtest_options *o, const struct tw_cli_world *shown,
                           const char *dir, uint64_t budget, bool sweep, char *err,
                           size_t err_size);

/* One run's checks on stdout, headed by dir. */
void tw_memtest_print_checks(const char *dir, const struct tw_memtest_result *r);

#endif
