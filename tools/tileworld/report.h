/*
 * Reports of a walk or a bench run (DESIGN.md §9): frames.csv (and, for the
 * charts of a bench, chart-data/frames-METHOD.dat: the same rows, one file
 * per method) written as frames come, summary.json and summary.md at the
 * end. Every file is written whole or not at all (outfile.h).
 */
#ifndef TW_TOOLS_REPORT_H
#define TW_TOOLS_REPORT_H

#include <stdio.h>

#include "tileworld/runtime.h"
#include "tools/outfile.h"

/* The folder of the chart data, inside a run's folder. */
#define TW_REPORT_CHART_DATA "chart-data"

/* bench --split: a frame's set of clusters drawn again from its camera
 * with no culling (tw_world_frame_fixed, then finished), timed like the
 * frame: what drawing the set cost, apart from what finding it cost. */
struct tw_report_set {
    double cpu_ms, ms;
    uint64_t triangles;
    uint32_t draws;
};

/* Per-method accumulation of frame statistics. */
struct tw_method_summary {
    bool used;
    double *ms;               /* every frame's ms_frame */
    double *cpu_ms;           /* every frame's cpu_ms */
    double *gpu_ms;           /* the gpu_ms of the frames where it is known */
    uint32_t frames, cap;
    uint32_t gpu_frames;      /* those frames */
    double triangles, queries;
    uint64_t missed_pixels_total;
    uint32_t frames_with_missed_pixels;
    uint64_t missed_clusters_total;
    uint64_t depth_errors_total;
    uint32_t frames_with_depth_errors;
    uint64_t tiles_new_total;
    uint64_t peak_cache_bytes;
    uint64_t predict_fail, tiles_queried;
    uint64_t tiles_visible;
    uint32_t max_tiles_visible;
    double ms_wait;
    double overdraw_triangles;
    double overdraw_box_triangles;
    double ms_max;
    uint32_t set_frames;      /* frames with a set drawn again (--split: every frame) */
    double set_cpu_ms, set_ms, set_triangles, set_draws;   /* their sums */
};

/* One method's figures over a run. */
struct tw_method_figures {
    bool used;
    uint32_t frames;
    double mean_ms, median_ms, p95_ms, p99_ms, max_ms;
    double mean_cpu_ms, median_cpu_ms, p99_cpu_ms, max_cpu_ms;  /* process CPU time */
    double mean_triangles, mean_queries, mean_overdraw_triangles;
    double mean_tiles_visible;
    uint32_t max_tiles_visible;
    uint64_t missed_pixels_total;
    uint32_t frames_with_missed_pixels;
    uint64_t missed_clusters_total;
    uint64_t depth_errors_total;
    uint32_t frames_with_depth_errors;
    double predict_fail_rate;
    uint64_t peak_cache_bytes;
};

/* What a run was, for the summaries. */
struct tw_report_about {
    char tileset[256];
    char path[256];
    uint32_t width, height;
    uint64_t seed;
    /* How accuracy was measured: verify_tolerance is the run's resolved
     * one (with verified); the testing-only mutation is said in the
     * summaries, so that a mutated run never passes for a real one. */
    bool verified;
    float verify_tolerance;
    bool deterministic;
    float mutate_query_shrink;
    /* What ran (DESIGN §15): the context's kind ("osmesa", "egl-device", ...),
     * GL_VENDOR, GL_RENDERER, GL_VERSION, whether the renderer is a CPU
     * rasteriser (GPU time is then CPU work), and the program's build. Empty
     * strings are reported as "unknown". */
    char context[32];
    char gl_vendor[128], gl_renderer[256], gl_version[128];
    bool software;
    char build_type[32];
    char commit[64];
};

struct tw_report {
    char dir[1024];
    bool open;
    struct tw_outfile frames_csv;
    bool chart_data;
    struct tw_outfile chart_frames[TW_METHOD_COUNT];
    struct tw_method_summary methods[TW_METHOD_COUNT];
    struct tw_report_about about;  /* set before tw_report_open(), kept by it */
};

/* Creates dir (and its parents) if needed and starts dir/frames.csv (and
 * with chart_data, dir/chart-data/). On failure writes "DIR: reason" into
 * err: TW_ERR_INVALID when the folder cannot be made, else TW_ERR_IO. */
int tw_report_open(struct tw_report *r, const char *dir, bool chart_data, char *err,
                   size_t err_size);
/* Appends one row and accumulates it, with its set drawn again (--split,
 * given for every frame of a run or none; NULL: not measured, its columns
 * 0); on a failed write returns TW_ERR_IO
 * with "FILE: cannot write: reason" in err. */
int tw_report_add(struct tw_report *r, const struct tw_frame_stats *st,
                  const struct tw_report_set *set, char *err, size_t err_size);
/* Completes frames.csv (and the chart data), then writes summary.json (and
 * summary.md when markdown is true) and frees everything. figures (may be
 * NULL) receives each method's figures, indexed by method. */
int tw_report_close(struct tw_report *r, bool markdown,
                    struct tw_method_figures figures[TW_METHOD_COUNT], char *err, size_t err_size);
/* Frees and removes the unfinished files, writing no summary (after a
 * failure). */
void tw_report_abort(struct tw_report *r);

/* Writes a JSON document (json-c's flags) as file, whole or not at all. */
struct json_object;
int tw_report_write_json(const char *file, struct json_object *root, int flags, char *err,
                         size_t err_size);

/* Creates dir and its parents; returns 0 or an errno value. */
int tw_report_make_dirs(const char *dir);

/* Percentile p in [0, 100] of n values (sorted in place), nearest rank. */
double tw_report_percentile(double *values, uint32_t n, double p);

#endif
