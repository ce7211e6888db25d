/*
 * Reports of a walk or a bench run (DESIGN.md §9): frames.csv (and, for the
 * charts of a bench, chart-data/frames-METHOD.dat: the same rows, one file
 * per method) written as frames come, summary.json and summary.md at the
 * end. Every file is written whole or not at all (outfile.h).
 */
#ifndef TW_TOOLS_REPORT_H
#define TW_TOOLS_REPORT_H

#include <stdio.h>

#include "runtime/runtime-internal.h"
#include "tiles/tiles-internal.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"
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

/* --split, a method's frames and their sets compared: over the frames after
 * the method's first (which compiles shader variants and builds every tile
 * the redraw then finds ready), the frame's mean CPU time is its set's
 * (drawing) plus the rest (finding). The rest is told apart from nothing
 * only when it exceeds twice its standard error; otherwise it is bounded
 * (drawing then costs at least the frame less that bound), unless the bound
 * exceeds the frame (too noisy to part), or the set drawn again cost more
 * than the frame beyond that margin (not measurable for the method). */
enum tw_split_verdict {
    TW_SPLIT_NONE,            /* no --split, or fewer than TW_SPLIT_MIN_FRAMES compared */
    TW_SPLIT_MEASURED,        /* finding = frame - set, above its margin */
    TW_SPLIT_BOUNDED,         /* finding at most the margin above its mean */
    TW_SPLIT_NOT_MEASURABLE,  /* the set drawn again cost more than the frame */
    TW_SPLIT_TOO_NOISY,       /* the margin exceeds the frame: neither part told apart */
};
#define TW_SPLIT_MIN_FRAMES 3

struct tw_split_figures {
    enum tw_split_verdict verdict;
    uint32_t frames;          /* frames compared */
    double frame_cpu_ms;      /* their mean CPU time */
    double set_cpu_ms;        /* their sets' mean CPU time, drawn again */
    double finding_cpu_ms;    /* frame_cpu_ms - set_cpu_ms (may be negative: see verdict) */
    double margin_cpu_ms;     /* twice the standard error of finding_cpu_ms */
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
    uint64_t lod_pixels_total;
    double lod_depth_sum;     /* of the frames' lod_depth_m */
    double ms_objects;        /* of the frames' ms_objects */
    uint64_t object_rebuilds; /* of the frames' object_rebuilds */
    uint64_t tiles_new_total;
    uint64_t peak_instance_bytes;  /* this method's tile instances (frames.csv cache_bytes) */
    uint64_t predict_fail, tiles_queried;
    uint64_t tiles_visible;
    uint32_t max_tiles_visible;
    double ms_wait;
    uint64_t waits, flushes;  /* the frames' round trips to the GPU, summed */
    double bytes_read_back;
    double overdraw_triangles;
    double overdraw_box_triangles;
    double ms_max;
    uint32_t set_frames;      /* frames with a set drawn again (--split: every frame) */
    double set_cpu_ms, set_ms, set_triangles, set_draws;   /* their sums */
    /* The frames compared for the split (all but the method's first): sums
     * of their CPU time, their sets', and of the difference and its square. */
    uint32_t split_frames;
    double split_frame_cpu_ms, split_set_cpu_ms, split_set_ms, split_diff, split_diff_sq;
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
    uint64_t lod_pixels_total;   /* pixels differing from full detail (verify, LOD on) */
    double lod_pixel_fraction;   /* their mean share of the image a frame */
    double predict_fail_rate;
    uint64_t peak_instance_bytes;
    double mean_gpu_ms;       /* over the frames whose GPU time came back; -1: none did */
    uint32_t gpu_frames;      /* those frames */
    struct tw_split_figures split;  /* --split */
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
    bool bench;                 /* a bench run (else a walk): the summaries' title */
    bool verified;
    float verify_tolerance;
    float max_screen_error;     /* resolved; <= 0: full detail */
    bool deterministic;
    uint32_t views;             /* cameras on the world (--views) */
    uint32_t cars;              /* moving cars in the world (--cars) */
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
    uint32_t frames;          /* of the path: each method's */
    /* Which methods must never miss a visible pixel under the run's settings
     * (tw_method_conservative()). */
    bool conservative[TW_METHOD_ALL];
    /* --allow-missed: a conservative method's missed pixels are reported,
     * not a failure. */
    bool allow_missed;
    /* Set before tw_report_close(): what the world's tile cache did over the
     * run (generated tiles: loads, evictions, refusals), and what a 3D
     * Tiles provider fetched (has_tiles3d). */
    bool has_totals;
    struct tw_cache_totals totals;
    bool has_tiles3d;
    struct tw_tiles3d_stats tiles3d;
};

struct tw_report {
    char dir[1024];
    bool open;
    struct tw_outfile frames_csv;
    bool chart_data;
    struct tw_outfile chart_frames[TW_METHOD_ALL];
    struct tw_method_summary methods[TW_METHOD_ALL];
    /* Every byte the world's tile cache held after a frame, CPU and GPU
     * (frames.csv bytes_cpu + bytes_gpu): its peak over the run. */
    uint64_t peak_tile_cache_bytes;
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
                    struct tw_method_figures figures[TW_METHOD_ALL], char *err, size_t err_size);
/* Frees and removes the unfinished files, writing no summary (after a
 * failure). */
void tw_report_abort(struct tw_report *r);

/* The verdict of a run: a few lines (at most TW_VERDICT_LINES) that say what
 * ran, how fast each method was (for a bench: the fastest conservative
 * method, and every method against vfc and the box oracle where they ran),
 * what --verify found (or that accuracy was not measured) and on what
 * renderer. failed tells whether a conservative method missed a pixel. */
#define TW_VERDICT_LINES 6
enum tw_verdict_form {
    TW_VERDICT_TEXT,          /* a terminal's: input text escaped (tw_log_escape) */
    TW_VERDICT_MARKDOWN,      /* summary.md's: escaped for Markdown as well */
};
struct tw_verdict {
    char lines[TW_VERDICT_LINES][1024];
    int count;
    bool failed;
};
void tw_report_verdict(const struct tw_report_about *about,
                       const struct tw_method_figures figures[TW_METHOD_ALL], bool bench,
                       enum tw_verdict_form form, struct tw_verdict *out);
/* Whether a conservative method missed a pixel under --verify. */
bool tw_report_missed(const struct tw_report_about *about,
                      const struct tw_method_figures figures[TW_METHOD_ALL]);

/* Text from input (a tileset's or a path file's name: any bytes) made safe
 * for a terminal, a report and JSON: valid UTF-8, no control character or
 * bidirectional override (tw_log_escape()); with markdown, also no
 * character that Markdown reads as syntax (| ` * _ [ ] # < > & \ ~).
 * Writes at most size bytes into out (cut with "...") and returns out. */
const char *tw_report_escape(const char *text, bool markdown, char *out, size_t size);

/* Writes a JSON document (json-c's flags) as file, whole or not at all. */
struct json_object;
int tw_report_write_json(const char *file, struct json_object *root, int flags, char *err,
                         size_t err_size);

/* Creates dir and its parents; returns 0 or an errno value. */
int tw_report_make_dirs(const char *dir);

/* Percentile p in [0, 100] of n values (sorted in place), nearest rank. */
double tw_report_percentile(double *values, uint32_t n, double p);

#endif
