/*
 * Charts of a bench run (DESIGN.md §9), drawn by gnuplot as PNG with the
 * checked-in script tools/tileworld/charts.gp (built into the program):
 *   chart-frame-time.png      frame time per frame, one line per method
 *   chart-triangles.png       triangles drawn per frame, one line per method
 *   chart-speed-accuracy.png  mean frame time against missed pixels and
 *                             against overdraw, one point per method (and
 *                             per sweep value)
 *   chart-sweep.png           mean frame time against the swept parameter
 *                             (with --sweep)
 *   chart-pareto.png          with --sweep under --verify: mean CPU time per
 *                             frame against missed pixels and against depth
 *                             errors per frame, one point per method and
 *                             value, the Pareto fronts drawn (pareto.h)
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
 * failed or was stopped. */
#define TW_CHARTS_NOT_DRAWN 1

/* How long gnuplot may take before it is killed. */
#define TW_CHARTS_TIMEOUT_S 120

/* A sweep: every method's figures at every value of one parameter. */
struct tw_chart_sweep {
    const char *param;
    uint32_t count;
    const double *values;                                       /* count, any order */
    const struct tw_method_figures (*figures)[TW_METHOD_COUNT]; /* count, by method */
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
    const struct tw_method_figures *figures;    /* TW_METHOD_COUNT, by method */
    const struct tw_chart_sweep *sweep;         /* NULL: no sweep */
};

/* Writes chart-data/methods.dat, chart-data/sweep-METHOD.dat (with a
 * sweep), chart-data/run.gp and charts.gp into run->dir, then runs
 * `gnuplot charts.gp` there (posix_spawnp, output to gnuplot.log, killed
 * after TW_CHARTS_TIMEOUT_S) and gives the charts it drew their names.
 * Returns TW_OK; TW_CHARTS_NOT_DRAWN with a one-line reason in err when
 * gnuplot is missing or fails (the caller warns and goes on); or a negative
 * tw_error with "FILE: reason" in err when a file cannot be written. */
int tw_charts_write(const struct tw_chart_run *run, char *err, size_t err_size);

/* Runs `gnuplot charts.gp` in dir (a script already written there, which
 * draws each chart as .chart-NAME.png.tmp when tw_temporaries is defined),
 * as tw_charts_write() does: output in dir/gnuplot.log, killed after
 * TW_CHARTS_TIMEOUT_S, the charts renamed once it succeeded. Returns
 * TW_OK, TW_CHARTS_NOT_DRAWN with a reason in err, or a negative tw_error. */
int tw_charts_run_gnuplot(const char *dir, char *err, size_t err_size);

#endif
