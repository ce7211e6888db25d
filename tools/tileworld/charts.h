/*
 * Charts of a bench run (DESIGN.md §9), drawn by gnuplot as PNG:
 *   chart-frame-time.png      frame time per frame, one line per method
 *   chart-triangles.png       triangles drawn per frame, one line per method
 *   chart-speed-accuracy.png  mean frame time against missed pixels and
 *                             against overdraw, one point per method
 *   chart-sweep.png           mean frame time against a parameter (only
 *                             when dir/sweep.csv exists)
 * Also written into dir: charts.gp (the gnuplot script, to re-run or edit:
 * `cd DIR && gnuplot charts.gp`) and chart-data/ (the data it plots).
 * Private to runtime/ (used by the tileworld command).
 */
#ifndef TW_RUNTIME_CHARTS_H
#define TW_RUNTIME_CHARTS_H

#include <stddef.h>

/* Writes the charts of a bench run in dir from dir/frames.csv and, if
 * present, dir/sweep.csv (columns method, param, value, mean_ms,
 * missed_pixels_total, mean_overdraw_triangles and, optionally,
 * mean_triangles, found by name; one row per method and value), by running
 * gnuplot with dir as its working directory. Reads dir/summary.json, if
 * present, for the chart subtitles. Returns TW_OK, or a negative tw_error
 * with a one-line "file:line: reason" in err (err_size bytes, may be 0):
 * TW_ERR_FORMAT for malformed input, TW_ERR_IO when a file cannot be read or
 * written, when gnuplot is not installed (the message says so; the caller
 * warns and goes on) or when gnuplot fails or runs for more than 120 s.
 * Forks a child; the caller's threads and signal handlers are untouched. */
int tw_charts_write(const char *dir, char *err, size_t err_size);

#endif
