/*
 * The files a run of tileworld writes into its folder, by name, so that a
 * new run can first remove what an earlier one left there: a folder then
 * never mixes the files of two runs (a new frames.csv beside an old
 * summary.json). Only these names are ever removed, never anything else:
 *   frames.csv summary.json summary.md sweep.csv sweep.md scenarios.md scenarios.json
 *   memory.csv (tileworld memtest)
 *   charts.gp gnuplot.log chart-*.png frame-NNNNN.png frame-NNNNN-METHOD.png
 *   chart-data/ (its .dat and run.gp files), sweep-PARAM-VALUE/ (sweep-budget-VALUE/ of memtest) and
 *   scenario-NAME/ (and scenario-NAME/far/) with the same files inside, and
 *   the temporaries .NAME.tmp of all of these (a killed run's).
 * A folder is removed only when nothing else is left in it.
 */
#ifndef TW_TOOLS_OUTPUTS_H
#define TW_TOOLS_OUTPUTS_H

#include <stddef.h>

/* Removes what an earlier run left in dir (a missing dir is fine). On
 * failure returns TW_ERR_IO with "FILE: cannot remove: reason" in err. */
int tw_outputs_remove_stale(const char *dir, char *err, size_t err_size);

#endif
