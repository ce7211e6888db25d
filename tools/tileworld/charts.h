/*
 * Charts of a bench run (DESIGN.md §9), drawn by gnuplot as PNG with the
 * checked-in script tools/tileworld/charts.gp (built into the program).
 * Every time a chart plots is the run's primary time per frame (struct
 * tw_chart_run.time): CPU time, or GPU time on a real GPU; wall time, which
 * swings with the load of a shared machine, has charts of its own.
 *   chart-frame-time.png      primary time per frame, one line per method
 *   chart-frame-time-wall.png wall time per frame, one line per method
 *   chart-triangles.png       triangles drawn per frame, one line per method
 *   chart-speed-accuracy.png  mean primary time against missed pixels and
 *                             against overdraw, one point per method (and
 *                             per sweep value), labels placed apart
 *                             (tw_charts_place_labels)
 *   chart-sweep.png           mean primary time against the swept
 *                             parameter (with --sweep)
 *   chart-sweep-wall.png      mean wall time against it (with --sweep)
 *   chart-pareto.png          with --sweep under --verify: mean primary time
 *                             against missed pixels and against depth errors
 *                             per frame, one point per method and value, the
 *                             Pareto fronts drawn (pareto.h) and named
 *   chart-lod.png             with --sweep max_screen_error=... under
 *                             --verify: mean primary time against the
 *                             pixels differing from full detail (% of the
 *                             image, mean per frame), one point per method
 *                             and value, each method's joined by value and
 *                             labelled with it, the Pareto front drawn
 *   chart-split.png           with --split: each method's CPU time, parted
 * Also written into the run's folder: charts.gp (to re-run or edit there:
 * `cd DIR && gnuplot charts.gp`), chart-data/ (what it plots, from the
 * run's figures in memory: chart-data/frames-METHOD.dat comes from the
 * report as frames are drawn, report.h) and gnuplot.log (what gnuplot said).
 */
#ifndef TW_TOOLS_CHARTS_H
#define TW_TOOLS_CHARTS_H

#include <stdbool.h>
#include <stddef.h>

#include "tools/tileworld/pareto.h"
#include "tools/tileworld/report.h"

/* tw_charts_write() drew nothing, but the run goes on: gnuplot is missing,
 * failed or was stopped (with room left on the disk). */
#define TW_CHARTS_NOT_DRAWN 1

/* How long gnuplot may take before it is killed. */
#define TW_CHARTS_TIMEOUT_S 120

/* The time per frame that the charts plot first. */
enum tw_chart_time {
    /* The process's CPU time, all threads (frames.csv's cpu_ms): the
     * default, and the figure that holds on a shared machine and on a
     * software renderer (whose "GPU" time is CPU work that cpu_ms counts). */
    TW_CHART_TIME_CPU = 0,
    /* GPU time (gpu_ms), for a real GPU: frames whose GPU time is not known
     * are left out, never read as 0; where no frame's is known the charts
     * plot CPU time and say so. */
    TW_CHART_TIME_GPU,
};

/* A sweep: every method's figures at every value of one parameter. */
struct tw_chart_sweep {
    const char *param;
    uint32_t count;
    const double *values;                                       /* count, any order */
    const struct tw_method_figures (*figures)[TW_METHOD_ALL]; /* count, by method */
    const struct tw_pareto_point *points;                       /* speed against accuracy */
    uint32_t point_count;
};

/* What a run was and what it measured (all borrowed). */
struct tw_chart_run {
    const char *dir;                            /* the run's folder, with chart-data/frames-*.dat */
    const char *tileset, *path;
    uint32_t width, height;
    bool verified;                              /* --verify: accuracy was measured */
    bool split;                                 /* --split: frames-*.dat's set_* columns */
    const enum tw_method *methods;              /* in the order of the run */
    uint32_t method_count;
    const struct tw_method_figures *figures;    /* TW_METHOD_ALL, by method */
    const struct tw_chart_sweep *sweep;         /* NULL: no sweep */
    /* The primary time: TW_CHART_TIME_GPU where the context is a real GPU
     * (struct tw_context_info.software false), else CPU (zero). With GPU,
     * the means are the figures' mean_gpu_ms (over their gpu_frames) and
     * the frame charts read frames-*.dat's gpu_ms. */
    enum tw_chart_time time;
    const char *context;                        /* the context's kind, for the labels; may be NULL */
};

/* Writes chart-data/methods.dat, chart-data/sweep-METHOD.dat (with a
 * sweep), chart-data/pareto*.dat and the label files (labels-*.dat),
 * chart-data/run.gp and charts.gp into run->dir, then runs `gnuplot
 * charts.gp` there (posix_spawnp, output to gnuplot.log, killed after
 * TW_CHARTS_TIMEOUT_S), checks every chart it drew (tw_charts_check_png)
 * and gives those that are whole their names. Returns TW_OK;
 * TW_CHARTS_NOT_DRAWN with a one-line reason in err when gnuplot is missing
 * or fails with room left on the disk (the caller warns and goes on); or a
 * negative tw_error with "FILE: reason" in err when a file cannot be
 * written, a chart is not a whole PNG or the disk is full (the run fails). */
int tw_charts_write(const struct tw_chart_run *run, char *err, size_t err_size);

/* Runs `gnuplot charts.gp` in dir (a script already written there, which
 * draws each chart as .chart-NAME.png.tmp when tw_temporaries is defined),
 * as tw_charts_write() does: output in dir/gnuplot.log, killed after
 * TW_CHARTS_TIMEOUT_S, each chart checked and renamed once gnuplot
 * succeeded. Returns TW_OK, TW_CHARTS_NOT_DRAWN with a reason in err, or
 * TW_ERR_IO with "DIR/chart-NAME.png: reason" in err when a chart is not
 * a whole PNG (that chart is removed; "no space left on device" when a
 * write in dir says so) or when gnuplot failed on a full disk. */
int tw_charts_run_gnuplot(const char *dir, char *err, size_t err_size);

/* Checks that file is one whole PNG: the signature, IHDR first, every
 * chunk within the file with its CRC right, IEND last and nothing after
 * it. Returns TW_OK; TW_ERR_FORMAT with "FILE: reason" in err (empty,
 * truncated and where, a bad CRC, ...); TW_ERR_IO when it cannot be read. */
int tw_charts_check_png(const char *file, char *err, size_t err_size);

/* ---- labels that do not overlap --------------------------------------------------- */

/* A box on the image, in pixels (y grows downwards): x0 < x1, y0 < y1. */
struct tw_chart_box {
    double x0, y0, x1, y1;
};

/* A point's label, in pixels of the image. */
struct tw_chart_label {
    double x, y;                /* in: the point */
    double width, height;       /* in: the label's box */
    double centre_x, centre_y;  /* out: the box's centre */
    bool moved;                 /* out: placed away from its point, to be joined to it by a
                                   leader line (from x, y to tw_charts_label_anchor()) */
    bool overlaps;              /* out: no place was free; it is where it overlaps least */
};

/* Places count labels, in order (the first get the nearest places): each
 * next to its point (gap pixels from it, in one of 8 directions) where its
 * box overlaps no label placed before, no obstacle (the markers of every
 * point, drawn or labelled, and fixed texts: the caller's) and stays inside
 * area; else farther out on rings of 16 directions, moved, preferring
 * places whose leader line crosses no other label (where many labels share
 * one point, some must). Deterministic; no allocation. Returns how many
 * labels overlap something (0 unless the area is full). */
uint32_t tw_charts_place_labels(struct tw_chart_label *labels, uint32_t count,
                                const struct tw_chart_box *obstacles, uint32_t obstacle_count,
                                double gap, struct tw_chart_box area);

/* Where a leader line from a label's point meets its box (the box's
 * border on the way to its centre). */
void tw_charts_label_anchor(const struct tw_chart_label *label, double *x, double *y);

#endif
