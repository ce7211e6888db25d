/*
 * tileworld memtest (DESIGN.md §13): the tile cache's memory
 * against distance travelled. Walks a long path (straight, wander, or a path
 * CSV repeated) for --distance kilometres through a tileset or a provider,
 * under --budget, and every --every metres records the cache's bytes (CPU
 * culling state, CPU geometry and BVHs, GPU buffers), tiles cached, loads,
 * evictions, reloads, load latency, holes, the process's RSS and the frame
 * time into DIR/memory.csv; then writes DIR/summary.json, DIR/summary.md and
 * the charts (charts.h's gnuplot machinery, with the built-in memtest.gp as
 * DIR/charts.gp):
 *   chart-memory.png   bytes (stacked: CPU state, CPU geometry, GPU) and RSS
 *                      against distance, the budget as a line
 *   chart-loads.png    loads, evictions and reloads per record interval
 *                      against distance
 *   chart-sweep-budget.png (--sweep budget=...) reloads and frame time
 *                      against the budget, in DIR (one sweep-budget-VALUE/
 *                      folder per value)
 * and checks what must hold (printed, in summary.md and summary.json as in
 * bench --scenario): exit status 3 when one does not hold.
 */
#ifndef TW_TOOLS_MEMTEST_H
#define TW_TOOLS_MEMTEST_H

/* Runs `tileworld memtest ARGS`: argv[0] is "memtest". Returns the exit
 * status: 0, 1 (a runtime failure), 2 (bad input, one line on stderr) or 3
 * (a check did not hold). */
int tw_memtest_main(int argc, char **argv);

#endif
