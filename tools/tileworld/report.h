/*
 * Reports of a walk or a bench run (DESIGN.md §9): frames.csv written as
 * frames come, summary.json and summary.md at the end, PNG snapshots.
 * Private to runtime/ (used by the tileworld command).
 */
#ifndef TW_RUNTIME_REPORT_H
#define TW_RUNTIME_REPORT_H

#include <stdio.h>

#include "tileworld/runtime.h"

/* Per-method accumulation of frame statistics. */
struct tw_method_summary {
    bool used;
    double *ms;               /* every frame's ms_frame */
    uint32_t frames, cap;
    double triangles, queries;
    uint64_t missed_pixels_total;
    uint32_t frames_with_missed_pixels;
    uint64_t tiles_new_total;
    uint64_t peak_cache_bytes;
    uint64_t predict_fail, tiles_queried;
    uint64_t tiles_visible;
    uint32_t max_tiles_visible;
    double ms_wait;
    double overdraw_triangles;
    double ms_max;
};

/* One method's figures over a run. */
struct tw_method_figures {
    bool used;
    uint32_t frames;
    double mean_ms, median_ms, p95_ms, p99_ms, max_ms;
    double mean_triangles, mean_queries, mean_overdraw_triangles;
    double mean_tiles_visible;
    uint32_t max_tiles_visible;
    uint64_t missed_pixels_total;
    uint32_t frames_with_missed_pixels;
    double predict_fail_rate;
    uint64_t peak_cache_bytes;
};

struct tw_report {
    char dir[1024];
    FILE *frames_csv;
    struct tw_method_summary methods[TW_METHOD_COUNT];
    /* What the run was, for summary.json. */
    char tileset[256];
    char path[256];
    uint32_t width, height;
    uint64_t seed;
};

/* Creates dir (and its parents) if needed and opens dir/frames.csv. On
 * failure writes "DIR: reason" into err. */
int tw_report_open(struct tw_report *r, const char *dir, char *err, size_t err_size);
/* Appends one frames.csv row and accumulates it. */
int tw_report_add(struct tw_report *r, const struct tw_frame_stats *st);
/* Writes summary.json (and summary.md when markdown is true), closes
 * frames.csv and frees everything. figures (may be NULL) receives each
 * method's figures, indexed by method. */
int tw_report_close(struct tw_report *r, bool markdown,
                    struct tw_method_figures figures[TW_METHOD_COUNT], char *err, size_t err_size);
/* Frees without writing summaries (after a failure). */
void tw_report_abort(struct tw_report *r);

/* Creates dir and its parents; returns 0 or an errno value. */
int tw_report_make_dirs(const char *dir);

/* Writes an RGB8 image (top row first) as PNG. */
int tw_report_write_png(const char *file, const uint8_t *rgb, uint32_t width, uint32_t height,
                        char *err, size_t err_size);

/* Percentile p in [0, 100] of n values (sorted in place), nearest rank. */
double tw_report_percentile(double *values, uint32_t n, double p);

#endif
