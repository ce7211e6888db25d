# The charts of a tileworld memtest run (DESIGN.md §13), drawn with gnuplot.
#
# tileworld writes this script into the run's folder as charts.gp and runs it
# there. To change a chart and draw it again:
#     cd DIR && gnuplot charts.gp
#
# The data, written by tileworld:
#   chart-data/run.gp  what the run was: run_title, budget (bytes, 0: none),
#                      sweep (1: a --sweep budget=... folder, with sweep.csv;
#                      0: one run, with memory.csv)
#   memory.csv         one row per record interval: distance_m, frame, bytes_*,
#                      tiles, loads, evictions, reloads, latency, holes,
#                      rss_bytes, frame times (README, tileworld memtest)
#   sweep.csv          one row per budget of the sweep (its time per frame:
#                      mean_cpu_ms where it has one, else the wall mean_ms)
# tileworld renames every chart-*.png it finds drawn.

load 'chart-data/run.gp'

# Drawn under a temporary name (.chart-NAME.png.tmp), renamed once gnuplot
# has finished without an error.
out(name) = exists('tw_temporaries') ? '.'.name.'.tmp' : name

if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {
    png_term = "pngcairo noenhanced font 'DejaVu Sans,11' linewidth 1.3"
} else {
    png_term = "png noenhanced"
}

MiB = 1048576.0
km(x) = x / 1000.0

if (!sweep) {
    # ---- chart-memory.png: the cache's bytes, stacked, and RSS; the budget --------
    reset
    set datafile separator comma
    set terminal @png_term size 1000,600
    set output out('chart-memory.png')
    set title "Memory against distance travelled\n".run_title
    set xlabel 'distance travelled (km)'
    set ylabel 'MiB'
    set key below horizontal maxcols 3 Left reverse
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set yrange [0:*]
    set autoscale xfixmin
    set autoscale xfixmax
    state(x) = column('bytes_state') / MiB
    cpu(x) = (column('bytes_state') + column('bytes_geometry')) / MiB
    if (budget > 0) {
        plot 'memory.csv' using (km(column('distance_m'))):(state(0)) with filledcurves x1 \
                 lc rgb '#56b4e9' title 'CPU: culling state', \
             '' using (km(column('distance_m'))):(state(0)):(cpu(0)) with filledcurves \
                 lc rgb '#009e73' title 'CPU: geometry, BVHs, tables', \
             '' using (km(column('distance_m'))):(cpu(0)):(column('bytes_total') / MiB) \
                 with filledcurves lc rgb '#e69f00' title 'GPU: vertex and index buffers', \
             '' using (km(column('distance_m'))):(column('rss_bytes') / MiB) with lines lw 2 \
                 lc rgb '#000000' title 'process RSS', \
             '' using (km(column('distance_m'))):(column('heap_used_bytes') / MiB) with lines \
                 lw 1 lc rgb '#777777' title 'malloc heap in use', \
             budget / MiB with lines dt 2 lw 2 lc rgb '#d55e00' \
                 title sprintf('cache budget (%.0f MiB)', budget / MiB)
    } else {
        plot 'memory.csv' using (km(column('distance_m'))):(state(0)) with filledcurves x1 \
                 lc rgb '#56b4e9' title 'CPU: culling state', \
             '' using (km(column('distance_m'))):(state(0)):(cpu(0)) with filledcurves \
                 lc rgb '#009e73' title 'CPU: geometry, BVHs, tables', \
             '' using (km(column('distance_m'))):(cpu(0)):(column('bytes_total') / MiB) \
                 with filledcurves lc rgb '#e69f00' title 'GPU: vertex and index buffers', \
             '' using (km(column('distance_m'))):(column('rss_bytes') / MiB) with lines lw 2 \
                 lc rgb '#000000' title 'process RSS (no cache budget)', \
             '' using (km(column('distance_m'))):(column('heap_used_bytes') / MiB) with lines \
                 lw 1 lc rgb '#777777' title 'malloc heap in use'
    }

    # ---- chart-loads.png: loads, evictions, reloads per interval ------------------
    reset
    set datafile separator comma
    set terminal @png_term size 1000,600
    set output out('chart-loads.png')
    set title "Tile loads and evictions against distance travelled (per record interval)\n".run_title
    set xlabel 'distance travelled (km)'
    set ylabel 'tiles per interval'
    set key below horizontal maxcols 3 Left reverse
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set yrange [0:*]
    set autoscale xfixmin
    set autoscale xfixmax
    plot 'memory.csv' using (km(column('distance_m'))):(column('loads_done')) with steps lw 2 \
             lc rgb '#0072b2' title 'loads done', \
         '' using (km(column('distance_m'))):(column('evictions')) with steps lw 2 \
             lc rgb '#d55e00' title 'evictions (tiles and culling state)', \
         '' using (km(column('distance_m'))):(column('reloads')) with steps lw 2 \
             lc rgb '#000000' title 'reloads (a tile loaded again after its eviction)', \
         '' using (km(column('distance_m'))):(column('holes')) with steps lw 1 dt 2 \
             lc rgb '#7f7f7f' title 'holes (tiles drawn without their content, policy skip)'
} else {
    # ---- chart-sweep-budget.png: reloads and time per frame against budget -------
    # The time is CPU time (mean_cpu_ms), the figure that holds on a shared
    # machine, where sweep.csv has it; else wall time (mean_ms), said so.
    reset
    set datafile separator comma
    header = ''
    do for [k = 1:40] {
        stats 'sweep.csv' every ::0::0 using (header = header.' '.columnhead(k), 0) nooutput
    }
    cpu = strstrt(header.' ', ' mean_cpu_ms ') > 0
    time_column = cpu ? 'mean_cpu_ms' : 'mean_ms'
    time_label = cpu ? 'mean CPU time per frame (ms)' : 'mean wall time per frame (ms; sweep.csv has no CPU time)'
    set terminal @png_term size 1000,600
    set output out('chart-sweep-budget.png')
    set title "Reloads and ".(cpu ? 'CPU' : 'wall')." time per frame against the cache budget\n".run_title
    set xlabel 'cache budget (MiB)'
    set ylabel 'reloads over the run'
    set y2label time_label
    set ytics nomirror
    set y2tics
    set key top right
    set grid xtics ytics lc rgb '#d8d8d8'
    set yrange [0:*]
    set y2range [0:*]
    set offsets graph 0.05, graph 0.05, 0, 0
    plot 'sweep.csv' using (column('budget_bytes') / MiB):(column('reloads')) with linespoints \
             lw 2 pt 7 lc rgb '#d55e00' title 'reloads', \
         '' using (column('budget_bytes') / MiB):(column(time_column)) axes x1y2 with linespoints \
             lw 2 pt 5 lc rgb '#0072b2' title (cpu ? 'mean CPU time per frame' : 'mean wall time per frame')
}
