# The charts of a tileworld bench run (DESIGN.md §9), drawn with gnuplot.
#
# tileworld writes this script into the run's folder, beside chart-data/, and
# runs it there. To change a chart and draw it again:
#     cd DIR && gnuplot charts.gp
#
# The data (chart-data/), written by tileworld from the figures of the run;
# every .dat file has a line of column names, so that columns are read by
# name ('ms_frame', column('triangles')):
#   run.gp             what the run was: run_title, methods, frames_per_method,
#                      verified, sweep_param, sweep_values, sweep_unaffected,
#                      pareto, split
#   frames-METHOD.dat  one row per frame of METHOD: the columns of frames.csv
#                      but method (frame, ms_frame, ms_cull, ms_wait, triangles,
#                      clusters, draws, queries, tiles_*, cache_bytes,
#                      predict_fail, missed_pixels, missed_clusters,
#                      overdraw_triangles, cpu_ms, depth_errors, and what
#                      frames.csv gains: set_cpu_ms and the other set_*
#                      columns of bench --split, 0 without it)
#   methods.dat        one row per method, in the order of `methods`: method,
#                      frames, mean_ms, median_ms, p95_ms, p99_ms, max_ms,
#                      mean_triangles, mean_queries, mean_overdraw_triangles,
#                      missed_pixels_total, frames_with_missed_pixels, mean_cpu_ms,
#                      median_cpu_ms, p99_cpu_ms, depth_errors_total,
#                      frames_with_depth_errors, missed_clusters_total
#   sweep-METHOD.dat   with --sweep: one row per value of sweep_param, by value:
#                      value, then the columns of methods.dat but method
#   pareto.dat         with --sweep under --verify (pareto = 1): one row per
#                      method and value, by mean CPU time: method, value,
#                      mean_cpu_ms, missed_per_frame, depth_errors_per_frame,
#                      conservative, front, front_depth (0 or 1), speedup
#   pareto-front.dat, pareto-front-depth.dat: the rows of pareto.dat on the
#                      front of CPU time against missed pixels, depth errors
#
# A new chart is a block at the end: set the output to out('chart-NAME.png')
# and plot columns by name; `for [i=1:n]` goes over the methods, line(i) is
# method i's colour. tileworld renames every chart-*.png it finds drawn.

load 'chart-data/run.gp'

# tileworld draws every chart under a temporary name (.chart-NAME.png.tmp)
# and gives it its name once gnuplot has finished without an error.
out(name) = exists('tw_temporaries') ? '.'.name.'.tmp' : name

# pngcairo draws antialiased text; the gd png terminal is the fallback.
# noenhanced: method names such as tilequery+chc are printed as they are.
if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {
    png_term = "pngcairo noenhanced font 'DejaVu Sans,11' linewidth 1.3"
} else {
    png_term = "png noenhanced"
}

n = words(methods)
method(i) = word(methods, i)
frames_file(i) = 'chart-data/frames-'.method(i).'.dat'
sweep_file(i) = 'chart-data/sweep-'.method(i).'.dat'
listed(list, name) = strstrt(' '.list.' ', ' '.name.' ') > 0

# One colour per method, the same in every chart of every run: vfc the grey
# baseline, the oracle a black dashed lower bound, the box oracle (the bound
# of box queries) an orange dashed one. Linetypes, unlike line styles,
# survive the reset before each chart.
known = 'vfc tilequery chc tilequery+chc oracle hzb tilequery+hzb box-oracle'
palette = '#7f7f7f #56b4e9 #009e73 #d55e00 #000000 #0072b2 #cc79a7 #e69f00 #882255 #44aa99 #999933 #aa4499'
position(list, name) = listed(list, name) ? words(substr(' '.list.' ', 1, strstrt(' '.list.' ', ' '.name.' '))) + 1 : 0
line_of(m) = position(known, m) > 0 ? position(known, m) : 9 + (position(methods, m) + 4) % 4
line(i) = line_of(method(i))
colour(i) = word(palette, line(i))
do for [i = 1:n] {
    dash = method(i) eq 'oracle' || method(i) eq 'box-oracle' ? 2 : 1
    set linetype line(i) lc rgb colour(i) lw 2 dt dash pt 7
}

# Counts read best as plain numbers of a named unit.
unit_scale(max) = max >= 1e7 ? 1e6 : max >= 1e4 ? 1e3 : 1
unit_name(max) = max >= 1e7 ? 'millions' : max >= 1e4 ? 'thousands' : ''
human(v) = v >= 1e6 ? sprintf('%.2fM', v / 1e6) : v >= 1e4 ? sprintf('%.0fk', v / 1e3) : sprintf('%.0f', v)
tic_label(v) = v >= 1e6 ? sprintf('%.0fM', v / 1e6) : v >= 1e4 ? sprintf('%.0fk', v / 1e3) : sprintf('%.0f', v)
min(a, b) = a < b ? a : b
max(a, b) = a > b ? a : b

# Tics at 1, 2, 5 x 10^k inside [tic_lo, tic_hi] of a log axis (decades only
# over more than four): gnuplot's decades alone read badly over one or two.
# Set tic_axis, tic_lo and tic_hi, then: eval log_tics
log_tics = "tic_list = ''; \
    do for [d = floor(log10(tic_lo)):ceil(log10(tic_hi))] { \
        do for [s in '1 2 5'] { \
            v = s * 10.0**d; \
            if (v >= tic_lo && v <= tic_hi && (tic_hi / tic_lo <= 1e4 || s eq '1')) { \
                tic_list = tic_list.(tic_list eq '' ? '' : ', ').sprintf('%.10g', v) \
            } \
        } \
    }; \
    eval sprintf('set %stics (%s)', tic_axis, tic_list)"

# A log axis of 1 + value, so that 0 has a place: '0' at 1, 10^k at 1 + 10^k.
# Set tic_axis and tic_hi, then: eval symlog_tics
symlog_tics = "tic_list = \"'0' 1\"; \
    do for [d = (tic_hi > 1e4 ? 1 : 0):floor(log10(tic_hi))] { \
        v = 10.0**d; \
        if (v + 1 <= tic_hi) { tic_list = tic_list.sprintf(\", '%s' %.10g\", tic_label(v), v + 1) } \
    }; \
    eval sprintf('set %stics (%s)', tic_axis, tic_list)"

# What every method did over the run, for keys, ranges and labels.
array mean_ms[n]
array mean_triangles[n]
array missed[n]
array overdraw[n]
array ms_lo[n]
array ms_hi[n]
array triangles_lo[n]
array triangles_hi[n]
do for [i = 1:n] {
    stats frames_file(i) using 'ms_frame' nooutput
    mean_ms[i] = STATS_mean; ms_lo[i] = STATS_min; ms_hi[i] = STATS_max
    stats frames_file(i) using 'triangles' nooutput
    mean_triangles[i] = STATS_mean; triangles_lo[i] = STATS_min; triangles_hi[i] = STATS_max
    stats frames_file(i) using 'missed_pixels' nooutput
    missed[i] = STATS_sum
    stats frames_file(i) using 'overdraw_triangles' nooutput
    overdraw[i] = STATS_mean
}

heading(title) = title."\n".run_title.(frames_per_method > 0 ? sprintf(', %d frames per method', frames_per_method) : '')

# ---- chart-frame-time.png, chart-triangles.png: one line per method --------------
do for [chart = 1:2] {
    reset
    triangles = chart == 2
    name = triangles ? 'chart-triangles.png' : 'chart-frame-time.png'
    lo = 1e300; hi = 0; frame_lo = 1e300; frame_hi = 0
    do for [i = 1:n] {
        m = triangles ? mean_triangles[i] : mean_ms[i]
        lo = min(lo, m); hi = max(hi, m)
        frame_lo = min(frame_lo, triangles ? triangles_lo[i] : ms_lo[i])
        frame_hi = max(frame_hi, triangles ? triangles_hi[i] : ms_hi[i])
    }
    # Only a spread of more than 10x hides the faster methods on a linear
    # axis; below that a linear axis compares better.
    log_y = lo > 0 && hi / lo > 10
    scale = triangles ? unit_scale(hi) : 1
    unit = triangles ? unit_name(hi) : 'ms'
    set terminal @png_term size 1000,600
    set output out(name)
    set label 100 heading(triangles ? 'Triangles drawn per frame (lower is better)' \
                                    : 'Frame time per frame (lower is better)') \
        at screen 0.5, screen 0.955 center font ',13'
    # The key in rows of three between the heading and the plot, where it
    # hides no line.
    set key at graph 0.5, graph 1.01 bottom center horizontal maxcols 3 Left reverse samplen 3 width 1
    set tmargin 4.5 + (n + 2) / 3
    set xlabel 'frame'
    set ylabel (triangles ? 'triangles drawn per frame' : 'frame time'). \
        (unit ne '' || log_y ? ' ('.unit.(unit ne '' && log_y ? ', ' : '').(log_y ? 'log scale' : '').')' : '')
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set autoscale xfixmin
    set autoscale xfixmax
    set format y '%g'
    if (log_y) {
        # A frame of 0 (nothing drawn) has no place on a log axis.
        frame_lo = frame_lo > 0 ? frame_lo : lo
        tic_axis = 'y'; tic_lo = frame_lo / scale / 1.25; tic_hi = frame_hi / scale * 1.25
        set logscale y
        set yrange [tic_lo:tic_hi]
        eval log_tics
    } else {
        set yrange [0:*]
    }
    plot for [i = 1:n] frames_file(i) using 'frame':(column(triangles ? 'triangles' : 'ms_frame') / scale) \
        with lines lt line(i) \
        title method(i).(triangles ? ' (mean '.human(mean_triangles[i]).')' : sprintf(' (mean %.1f ms)', mean_ms[i]))
}

# ---- chart-speed-accuracy.png: one point per method (and per sweep value) --------
reset
sweep_shown(i) = sweep_param ne '' && !listed(sweep_unaffected, method(i))
x_max = 0; missed_max = 0; overdraw_max = 0; overdraw_min = 1e300
do for [i = 1:n] {
    x_max = max(x_max, mean_ms[i]); missed_max = max(missed_max, missed[i])
    overdraw_max = max(overdraw_max, overdraw[i])
    if (overdraw[i] > 0) { overdraw_min = min(overdraw_min, overdraw[i]) }
    if (sweep_shown(i)) {
        stats sweep_file(i) using 'mean_ms' nooutput
        x_max = max(x_max, STATS_max)
        stats sweep_file(i) using 'missed_pixels_total' nooutput
        missed_max = max(missed_max, STATS_max)
        stats sweep_file(i) using 'mean_overdraw_triangles' nooutput
        overdraw_max = max(overdraw_max, STATS_max)
        if (STATS_min > 0) { overdraw_min = min(overdraw_min, STATS_min) }
    }
}
# Labels are staggered above and below the points in the order of their x,
# on two heights, so that four neighbours do not write over each other.
array label_dy[n]
do for [i = 1:n] {
    rank = 0
    do for [j = 1:n] { if (mean_ms[j] < mean_ms[i] || (mean_ms[j] == mean_ms[i] && j < i)) { rank = rank + 1 } }
    label_dy[i] = word('1.2 -1.2 2.3 -2.3', rank % 4 + 1) + 0
}
# The sweep's points of each method it changes, joined, with labels (every
# other one above, the others below, as neighbours often coincide), as
# plot elements for the macro @sweep_plots (an iteration that turns out
# empty would still open its file).
sweep_plots = ''
do for [i = 1:n] {
    if (sweep_shown(i)) {
        sweep_plots = sweep_plots.sprintf(", sweep_file(%d) using 'mean_ms':(y(column(y_column))) \
            with linespoints lt line(%d) pt 6 ps 1.3 lw 1 dt 3 notitle, \
            sweep_file(%d) every 2 using 'mean_ms':(y(column(y_column))):(sweep_label(%d)) \
            with labels left offset char 0.9,0.6 font ',8' tc rgb colour(%d) notitle, \
            sweep_file(%d) every 2::1 using 'mean_ms':(y(column(y_column))):(sweep_label(%d)) \
            with labels left offset char 0.9,-0.7 font ',8' tc rgb colour(%d) notitle", \
            i, i, i, i, i, i, i, i)
    }
}
any_sweep = sweep_plots ne ''
# The first point of a method's sweep says whose it is; the line carries the
# name to the others.
sweep_label(i) = (strcol('value') eq word(sweep_values, 1) ? method(i).' ' : '').sweep_param.'='.strcol('value')

set terminal @png_term size 1200,600
set output out('chart-speed-accuracy.png')
set multiplot layout 1,2 title "Speed against accuracy: one point per method, lower left is better\n".run_title font ',13'
set grid xtics ytics lc rgb '#d8d8d8'
set border 3
set tics nomirror
set key top right Left reverse samplen 1 spacing 1.1 box lc rgb '#bbbbbb' opaque
set xlabel 'mean frame time (ms)'
set xrange [0:(x_max > 0 ? x_max * 1.25 : 1)]

do for [panel = 1:2] {
    missed_panel = panel == 1
    unset label
    unset arrow
    if (missed_panel) {
        # Missed pixels: 0 expected of a conservative method.
        set title 'Missed pixels (visible errors)' font ',12'
        set ylabel 'missed pixels, total over the run (log scale of 1 + value)'
        log_y = 1
        tic_hi = max(20, (missed_max + 1) * 8)
    } else {
        # Overdraw, on a log axis too when vfc's dwarfs the rest.
        unset key
        set title 'Overdraw (wasted work)' font ',12'
        log_y = overdraw_min < 1e300 && overdraw_max / overdraw_min > 10
        tic_hi = max(20, (overdraw_max + 1) * 4)
    }
    scale = 1
    if (log_y) {
        tic_axis = 'y'
        set logscale y
        set yrange [tic_hi**(-1.0 / 9):tic_hi]
        eval symlog_tics
        if (!missed_panel) { set ylabel 'overdraw triangles per frame, mean (log scale of 1 + value)' }
    } else {
        scale = unit_scale(overdraw_max)
        unset logscale y
        set ytics autofreq
        set format y '%g'
        set yrange [0:(overdraw_max > 0 ? overdraw_max / scale * 1.15 : 1)]
        set ylabel 'overdraw triangles per frame, mean'.(unit_name(overdraw_max) ne '' ? ' ('.unit_name(overdraw_max).')' : '')
    }
    y(v) = log_y ? v + 1 : v / scale
    y_column = missed_panel ? 'missed_pixels_total' : 'mean_overdraw_triangles'
    if (missed_panel) {
        set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lc rgb '#9a9a9a' dt 2 back
        set label 1 'no pixel missed (conservative)' at graph 0.99, first 1 right offset 0,-1 tc rgb '#6a6a6a' font ',9'
    } else {
        set label 1 'triangles drawn in clusters with no visible pixel' at graph 0.99, graph 0.03 right tc rgb '#6a6a6a' font ',9'
    }
    if (!verified) {
        set label 2 "accuracy not measured:\nrun bench with --verify" at graph 0.5, graph 0.6 center tc rgb '#b00000' font ',12'
    }
    do for [i = 1:n] {
        eval sprintf("set label %d '%s' at first %.10g, first %.10g center offset char 0,%.1f font ',10' tc rgb '%s' front", \
                     9 + i, method(i), mean_ms[i], y(missed_panel ? missed[i] : overdraw[i]), \
                     label_dy[i], colour(i))
    }
    plot for [i = 1:n] 'chart-data/methods.dat' every ::(i - 1)::(i - 1) \
             using 'mean_ms':(y(column(y_column))) with points lt line(i) pt 7 ps 2 \
             title (missed_panel ? method(i) : '') @sweep_plots, \
         NaN with points lc rgb '#555555' pt 6 ps 1.3 title (missed_panel && any_sweep ? 'sweep settings' : '')
}
unset multiplot

# ---- chart-sweep.png: mean frame time against the swept parameter -----------------
if (sweep_param ne '') {
    reset
    values = words(sweep_values)
    v_lo = 1e300; v_hi = -1e300; v_pos = 1e300; zero = 0
    do for [k = 1:values] {
        v = word(sweep_values, k) + 0
        v_lo = min(v_lo, v); v_hi = max(v_hi, v)
        if (v > 0) { v_pos = min(v_pos, v) } else { zero = 1 }
    }
    # 0, 1, 4, 16, 64 would bunch up on a linear axis and 0 has no place on
    # a log one: such values are spaced evenly, labelled with their values.
    # Sizes swept by doubling space evenly on a log axis.
    by_rank = zero && v_pos < 1e300 && v_hi / v_pos >= 50
    log_x = !by_rank && v_lo > 0 && v_hi / v_lo >= 50
    ms_lo = 1e300; ms_hi = 0; any_unaffected = 0
    do for [i = 1:n] {
        stats sweep_file(i) using 'mean_ms' nooutput
        ms_lo = min(ms_lo, STATS_min); ms_hi = max(ms_hi, STATS_max)
        if (listed(sweep_unaffected, method(i))) { any_unaffected = 1 }
    }
    log_y = ms_lo > 0 && ms_hi / ms_lo > 10
    set terminal @png_term size 1000,600
    set output out('chart-sweep.png')
    set title "Mean frame time against ".sweep_param." (lower is better)\n".run_title font ',13'
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set key outside right top vertical Left reverse samplen 2
    set xlabel sweep_param.(by_rank ? ' (evenly spaced)' : '')
    if (by_rank) {
        set xrange [-0.5:values - 0.5]
    } else {
        if (log_x) {
            set logscale x 2
            set xrange [v_lo / 1.25:v_hi * 1.25]
        } else {
            margin = v_hi > v_lo ? (v_hi - v_lo) * 0.08 : 1
            set xrange [v_lo - margin:v_hi + margin]
        }
    }
    if (log_y) {
        tic_axis = 'y'; tic_lo = ms_lo / 1.25; tic_hi = ms_hi * 1.25
        set logscale y
        set yrange [tic_lo:tic_hi]
        eval log_tics
        set ylabel 'mean frame time (ms, log scale)'
    } else {
        set yrange [0:*]
        set ylabel 'mean frame time (ms)'
    }
    if (any_unaffected) {
        set label 1 'unaffected: '.sweep_param.' changes nothing the method draws' at graph 0.01, graph 1.02 left font ',9' tc rgb '#6a6a6a'
    }
    unaffected(i) = listed(sweep_unaffected, method(i))
    if (by_rank) {
        plot for [i = 1:n] sweep_file(i) using 0:'mean_ms':xtic(strcol('value')) \
            with linespoints lt line(i) pt 7 ps 1.3 lw (unaffected(i) ? 1 : 2) \
            title method(i).(unaffected(i) ? ' (unaffected)' : '')
    } else {
        plot for [i = 1:n] sweep_file(i) using 'value':'mean_ms' \
            with linespoints lt line(i) pt 7 ps 1.3 lw (unaffected(i) ? 1 : 2) \
            title method(i).(unaffected(i) ? ' (unaffected)' : '')
    }
}

# ---- chart-pareto.png: speed against accuracy over a sweep (--verify) -------------
# One point per method and value: mean CPU time per frame against missed
# pixels per frame (left) and depth errors per frame (right); conservative
# points (T = 0) filled squares, the others open circles; the points of the
# Pareto front (no other point as fast with as few errors, and better in
# one) ringed, named and joined by a black staircase. The oracles are drawn but never on a
# front: they need the ID pass (the front itself comes from pareto.c).
if (pareto) {
    reset
    stats 'chart-data/pareto.dat' using 'mean_cpu_ms' nooutput
    cpu_lo = STATS_min; cpu_hi = STATS_max
    stats 'chart-data/pareto.dat' using 'missed_per_frame' nooutput
    missed_hi = STATS_max
    stats 'chart-data/pareto.dat' using 'depth_errors_per_frame' nooutput
    depth_hi = STATS_max
    span = cpu_hi > cpu_lo ? cpu_hi - cpu_lo : max(cpu_hi, 1) * 0.1
    set terminal @png_term size 1200,600
    set output out('chart-pareto.png')
    set multiplot layout 1,2 title "Speed against accuracy over the sweep of ".sweep_param. \
        ": one point per method and value, lower left is better\n".run_title font ',13'
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set xlabel 'mean CPU time per frame (ms, all threads)'
    set xrange [max(0, cpu_lo - 0.15 * span):cpu_hi + 0.15 * span]
    set logscale y
    tic_axis = 'y'
    mine(i) = strcol('method') eq method(i)
    do for [panel = 1:2] {
        depth_panel = panel == 2
        column_name = depth_panel ? 'depth_errors_per_frame' : 'missed_per_frame'
        front_file = depth_panel ? 'chart-data/pareto-front-depth.dat' : 'chart-data/pareto-front.dat'
        tic_hi = max(20, ((depth_panel ? depth_hi : missed_hi) + 1) * 8)
        set yrange [tic_hi**(-1.0 / 9):tic_hi]
        eval symlog_tics
        set title (depth_panel ? 'Depth errors (anything drawn wrong)' : 'Missed pixels (visible errors)') font ',12'
        set ylabel (depth_panel ? 'depth errors' : 'missed pixels').' per frame, mean (log scale of 1 + value)'
        set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lc rgb '#9a9a9a' dt 2 back
        set label 1 (depth_panel ? 'no depth error' : 'no pixel missed') at graph 0.99, first 1 right offset 0,-1 tc rgb '#6a6a6a' font ',9'
        # Keys under the panels, where they hide no point: the methods
        # under the left one, the marks under the right one.
        set bmargin 6
        set key at graph 0.5, screen 0.01 center bottom horizontal maxcols 3 Left reverse samplen 1 width 1
        plot for [i = 1:n] 'chart-data/pareto.dat' \
                 using 'mean_cpu_ms':(mine(i) && column('conservative') > 0 ? column(column_name) + 1 : NaN) \
                 with points lt line(i) pt 5 ps 1.4 title (depth_panel ? '' : method(i)), \
             for [i = 1:n] 'chart-data/pareto.dat' \
                 using 'mean_cpu_ms':(mine(i) && column('conservative') == 0 ? column(column_name) + 1 : NaN) \
                 with points lt line(i) pt 6 ps 1.4 lw 1.5 notitle, \
             front_file using 'mean_cpu_ms':(column(column_name) + 1) with steps lc rgb '#000000' lw 1.5 \
                 notitle, \
             front_file using 'mean_cpu_ms':(column(column_name) + 1) with points lc rgb '#000000' \
                 pt 6 ps 2.6 lw 1.2 title (depth_panel ? 'Pareto front' : ''), \
             front_file every 2 using 'mean_cpu_ms':(column(column_name) + 1):(strcol('method').' '.sweep_param.'='.strcol('value')) \
                 with labels left offset char 0.8,0.7 font ',8' notitle, \
             front_file every 2::1 using 'mean_cpu_ms':(column(column_name) + 1):(strcol('method').' '.sweep_param.'='.strcol('value')) \
                 with labels left offset char 0.8,-0.7 font ',8' notitle, \
             NaN with points lc rgb '#555555' pt 5 ps 1.4 title (depth_panel ? 'conservative (T = 0)' : ''), \
             NaN with points lc rgb '#555555' pt 6 ps 1.4 title (depth_panel ? 'T > 0' : '')
        unset arrow
        unset label
    }
    unset multiplot
}

# ---- chart-split.png: with --split, each method's CPU time parted -------------------
# The frame's CPU time is the outlined bar; inside it, the part its set costs
# when drawn again with no culling, and above that what finding the set
# cost. A set that cost more than its frame (noise, or a frame that drew in
# a cheaper order) stands out above the outline.
if (split) {
    reset
    array cpu_all[n]
    array cpu_set[n]
    oracle_cpu = -1
    do for [i = 1:n] {
        stats frames_file(i) using 'cpu_ms' nooutput
        cpu_all[i] = STATS_mean
        stats frames_file(i) using 'set_cpu_ms' nooutput
        cpu_set[i] = STATS_mean
        if (method(i) eq 'oracle') { oracle_cpu = cpu_all[i] }
    }
    set terminal @png_term size 1000,600
    set output out('chart-split.png')
    set title heading('CPU time per frame: drawing what each method drew, and finding it') font ',13'
    set boxwidth 0.6
    set xrange [0.4:n + 0.6]
    set yrange [0:*]
    set xtics nomirror ()
    do for [i = 1:n] { set xtics add (method(i) i) }
    set ylabel 'mean CPU time per frame (ms)'
    set grid ytics lc rgb '#d8d8d8'
    set border 3
    set ytics nomirror
    set key top right Left reverse samplen 2 box lc rgb '#bbbbbb' opaque
    if (oracle_cpu > 0) {
        set arrow 1 from graph 0, first oracle_cpu to graph 1, first oracle_cpu nohead dt 2 lc rgb '#000000' front
        set label 1 "the oracle's frame" at graph 0.005, first oracle_cpu left offset 0,-0.8 font ',9' front
    }
    plot cpu_all using 1:2 with boxes fill solid 0.9 noborder lc rgb '#f2b56b' \
             title 'finding it: queries, waits, traversal', \
         cpu_set using 1:2 with boxes fill solid 0.9 noborder lc rgb '#4f81b3' \
             title 'drawing its set (drawn again with no culling)', \
         cpu_all using 1:2 with boxes lc rgb '#333333' lw 1.5 fill empty \
             title 'the frame', \
         cpu_all using 1:(max(cpu_all[column(1)], cpu_set[column(1)])):(sprintf('%.1f of which %.1f drawing', \
             cpu_all[column(1)], cpu_set[column(1)])) with labels offset 0,0.8 font ',9' notitle
}
