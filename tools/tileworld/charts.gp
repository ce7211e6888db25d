# The charts of a tileworld bench run (DESIGN.md §9), drawn with gnuplot.
#
# tileworld writes this script into the run's folder, beside chart-data/, and
# runs it there. To change a chart and draw it again:
#     cd DIR && gnuplot charts.gp
#
# Time: every chart plots the run's primary time per frame, `time` in
# run.gp: the process's CPU time (cpu_ms, all threads), the figure that holds
# on a shared machine and on a software renderer, or on a real GPU the GPU
# time (gpu_ms; frames whose GPU time is not known are left out, never read
# as 0). Wall time swings with the machine's load: it has charts of its own,
# chart-frame-time-wall.png and chart-sweep-wall.png.
#
# The data (chart-data/), written by tileworld from the figures of the run;
# every .dat file has a line of column names, so that columns are read by
# name ('ms_frame', column('triangles')):
#   run.gp             what the run was: run_title, methods, frames_per_method,
#                      verified, sweep_param, sweep_values, sweep_unaffected,
#                      pareto, lod, split; the time (time, frame_time_column,
#                      mean_time_column, time_name, time_note) and each
#                      method's mean_time, mean_wall and time_frames; the
#                      panels and axis ranges of the speed-accuracy, Pareto
#                      and LOD charts, for which tileworld placed their labels
#   frames-METHOD.dat  one row per frame of METHOD: the columns of frames.csv
#                      but method (frame, ms_frame, ms_cull, ms_wait, triangles,
#                      clusters, draws, queries, tiles_*, cache_bytes,
#                      predict_fail, missed_pixels, missed_clusters,
#                      overdraw_triangles, cpu_ms, depth_errors, ..., the set_*
#                      columns of bench --split (0 without it), gpu_ms (-1: not
#                      known), gpu_ms_id, waits, flushes, bytes_read_back,
#                      tiles_late, hzb_lag)
#   methods.dat        one row per method, in the order of `methods`: method,
#                      frames, mean_ms, median_ms, p95_ms, p99_ms, max_ms (wall),
#                      mean_triangles, mean_queries, mean_overdraw_triangles,
#                      missed_pixels_total, frames_with_missed_pixels, mean_cpu_ms,
#                      median_cpu_ms, p99_cpu_ms, depth_errors_total,
#                      frames_with_depth_errors, missed_clusters_total,
#                      mean_gpu_ms (NaN: none known), gpu_frames
#   sweep-METHOD.dat   with --sweep: one row per value of sweep_param, by value:
#                      value, then the columns of methods.dat but method
#   pareto.dat         with --sweep under --verify (pareto = 1): one row per
#                      method and value, by time_ms: method, value,
#                      mean_cpu_ms, missed_per_frame, depth_errors_per_frame,
#                      conservative, front, front_depth (0 or 1), speedup,
#                      time_ms (the primary time), mean_gpu_ms, lod_fraction
#                      (the share of the pixels differing from full detail,
#                      mean per frame), front_lod (0 or 1)
#   pareto-front.dat, pareto-front-depth.dat: the rows of pareto.dat on the
#                      front of the primary time against missed pixels, depth
#                      errors
#   pareto-lod.dat     with a sweep of max_screen_error under --verify
#                      (lod = 1): the rows of pareto.dat by method (in the
#                      order of `methods`) and value
#   pareto-front-lod.dat (lod = 1): the rows of pareto.dat on the front of the
#                      primary time against lod_fraction, by lod_fraction
#   labels-speed-accuracy-1.dat, -2.dat, labels-pareto-1.dat, -2.dat,
#                      labels-lod.dat: the
#                      point labels of each panel, placed apart by tileworld:
#                      method, kind (1: a method's point, 2: a sweep value's),
#                      x, y (the point), label_x, label_y (the label's centre),
#                      anchor_x, anchor_y (where its leader line ends), moved
#                      (1: drawn with a leader line), text
#
# A new chart is a block at the end: set the output to out('chart-NAME.png')
# and plot columns by name; `for [i=1:n]` goes over the methods, line(i) is
# method i's colour. tileworld checks and renames every chart-*.png it finds
# drawn.

load 'chart-data/run.gp'

# tileworld draws every chart under a temporary name (.chart-NAME.png.tmp)
# and gives it its name once gnuplot has finished without an error and the
# file is a whole PNG.
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
known_value(v) = v == v    # false for NaN

# A frame's primary time: gpu_ms is -1 where it is not known, left out.
frame_time(t) = t >= 0 ? t : NaN

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

# Each method's range per frame of its primary time, wall time and
# triangles (its means come from run.gp).
array time_lo[n]
array time_hi[n]
array wall_lo[n]
array wall_hi[n]
array mean_triangles[n]
array triangles_lo[n]
array triangles_hi[n]
do for [i = 1:n] {
    time_lo[i] = NaN; time_hi[i] = NaN
    if (time_frames[i] > 0) {
        stats frames_file(i) using (frame_time(column(frame_time_column))) nooutput
        time_lo[i] = STATS_min; time_hi[i] = STATS_max
    }
    stats frames_file(i) using 'ms_frame' nooutput
    wall_lo[i] = STATS_min; wall_hi[i] = STATS_max
    stats frames_file(i) using 'triangles' nooutput
    mean_triangles[i] = STATS_mean; triangles_lo[i] = STATS_min; triangles_hi[i] = STATS_max
}

heading(title) = title."\n".run_title.(frames_per_method > 0 ? sprintf(', %d frames per method', frames_per_method) : '')

# ---- chart-frame-time.png, chart-triangles.png, chart-frame-time-wall.png ---------
# One line per method: its primary time per frame, its triangles, its wall
# time (the secondary view).
do for [chart = 1:3] {
    reset
    triangles = chart == 2
    wall = chart == 3
    name = triangles ? 'chart-triangles.png' : wall ? 'chart-frame-time-wall.png' : 'chart-frame-time.png'
    lo = 1e300; hi = 0; frame_lo = 1e300; frame_hi = 0
    do for [i = 1:n] {
        m = triangles ? mean_triangles[i] : wall ? mean_wall[i] : mean_time[i]
        if (known_value(m)) {
            lo = min(lo, m); hi = max(hi, m)
            frame_lo = min(frame_lo, triangles ? triangles_lo[i] : wall ? wall_lo[i] : time_lo[i])
            frame_hi = max(frame_hi, triangles ? triangles_hi[i] : wall ? wall_hi[i] : time_hi[i])
        }
    }
    # Only a spread of more than 10x hides the faster methods on a linear
    # axis; below that a linear axis compares better.
    log_y = lo > 0 && hi / lo > 10
    scale = triangles ? unit_scale(hi) : 1
    unit = triangles ? unit_name(hi) : 'ms'
    set terminal @png_term size 1000,600
    set output out(name)
    title = triangles ? 'Triangles drawn per frame (lower is better)' \
          : wall ? 'Wall time per frame (lower is better), the secondary view: it swings with the machine''s load' \
          : time_name.' per frame (lower is better): '.time_note
    set label 100 heading(title) at screen 0.5, screen 0.955 center font ',13'
    # The key in rows of three between the heading and the plot, where it
    # hides no line.
    set key at graph 0.5, graph 1.01 bottom center horizontal maxcols 3 Left reverse samplen 3 width 1
    set tmargin 4.5 + (n + 2) / 3
    set xlabel 'frame'
    set ylabel (triangles ? 'triangles drawn per frame' : wall ? 'wall time per frame' : time_name.' per frame'). \
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
    key_mean(i) = triangles ? ' (mean '.human(mean_triangles[i]).')' \
        : known_value(wall ? mean_wall[i] : mean_time[i]) ? sprintf(' (mean %.1f ms)', wall ? mean_wall[i] : mean_time[i]) \
        : ' (no '.time_name.' known)'
    if (time eq 'gpu' && !triangles && !wall) {
        # A gap where a frame's GPU time did not come back; a lone frame
        # between two gaps is a dot.
        plot for [i = 1:n] frames_file(i) using 'frame':(frame_time(column(frame_time_column))) \
            with linespoints lt line(i) pt 7 ps 0.4 title method(i).key_mean(i)
    } else {
        plot for [i = 1:n] frames_file(i) \
            using 'frame':(triangles ? column('triangles') / scale : wall ? column('ms_frame') : column(frame_time_column)) \
            with lines lt line(i) title method(i).key_mean(i)
    }
}

# The two panels of chart-speed-accuracy.png and chart-pareto.png, where
# run.gp says (tileworld placed the labels for these margins and ranges).
panel_margins = "set lmargin at screen panel_left[panel]; set rmargin at screen panel_right[panel]; \
    set tmargin at screen panel_top; set bmargin at screen panel_bottom"
# The labels of a panel, in label_file: the methods' names, the sweep
# values' (smaller), and leader lines to those moved away from their points.
# A macro (@label_elements), expanded where a block is read: label_file is
# set before each plot. (A row of the other kind gets an empty text, not a
# NaN place: gnuplot 5.4.4 crashes on labels that are all NaN.)
label_text(k) = column('kind') == k ? strcol('text') : ''
label_file = ''
label_elements = ", \
    label_file using 'label_x':'label_y':(label_text(1)):(line_of(strcol('method'))) \
        with labels center font ',10' tc variable notitle, \
    label_file using 'label_x':'label_y':(label_text(2)):(line_of(strcol('method'))) \
        with labels center font ',8' tc variable notitle, \
    label_file using (column('moved') > 0 ? column('x') : NaN):'y':(column('anchor_x') - column('x')): \
        (column('anchor_y') - column('y')):(line_of(strcol('method'))) \
        with vectors nohead lw 0.6 lc variable notitle"

# ---- chart-speed-accuracy.png: one point per method (and per sweep value) --------
reset
sweep_shown(i) = sweep_param ne '' && !listed(sweep_unaffected, method(i))
# The sweep's points of each method it changes, joined, as plot elements
# for the macro @sweep_plots (an iteration that turns out empty would still
# open its file); their labels are in the panel's labels file.
sweep_plots = ''
do for [i = 1:n] {
    if (sweep_shown(i)) {
        sweep_plots = sweep_plots.sprintf(", sweep_file(%d) using mean_time_column:(y(column(y_column))) \
            with linespoints lt line(%d) pt 6 ps 1.3 lw 1 dt 3 notitle", i, i)
    }
}
any_sweep = sweep_plots ne ''

set terminal @png_term size 1200,600
set output out('chart-speed-accuracy.png')
set multiplot title "Speed against accuracy: one point per method, lower left is better\n".run_title.'; '.time_name.': '.time_note font ',13'
set grid xtics ytics lc rgb '#d8d8d8'
set border 3
set tics nomirror
set xlabel 'mean '.time_name.' per frame (ms)'
set xrange [0:sa_x_hi]

do for [panel = 1:2] {
    missed_panel = panel == 1
    eval panel_margins
    unset label
    unset arrow
    if (missed_panel) {
        # The methods' key under the left panel, where it hides no point.
        set key at screen panel_left[1], screen 0.01 left bottom horizontal maxcols 5 Left reverse samplen 1 width 1
        # Missed pixels: 0 expected of a conservative method.
        set title 'Missed pixels (visible errors)' font ',12'
        set ylabel 'missed pixels, total over the run (log scale of 1 + value)'
    } else {
        unset key
        # Overdraw, on a log axis too when vfc's dwarfs the rest.
        set title 'Overdraw (wasted work)' font ',12'
    }
    log_y = sa_y_log[panel]
    scale = sa_y_scale[panel]
    if (log_y) {
        tic_axis = 'y'; tic_hi = sa_y_hi[panel]
        set logscale y
        eval symlog_tics
        if (!missed_panel) { set ylabel 'overdraw triangles per frame, mean (log scale of 1 + value)' }
    } else {
        unset logscale y
        set ytics autofreq
        set format y '%g'
        set ylabel 'overdraw triangles per frame, mean'.(scale == 1e6 ? ' (millions)' : scale == 1e3 ? ' (thousands)' : '')
    }
    # The range after the scale: a range from 0 set while the axis is still
    # the left panel's log one makes gnuplot warn.
    set yrange [sa_y_lo[panel]:sa_y_hi[panel]]
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
    label_file = sprintf('chart-data/labels-speed-accuracy-%d.dat', panel)
    plot for [i = 1:n] 'chart-data/methods.dat' every ::(i - 1)::(i - 1) \
             using mean_time_column:(y(column(y_column))) with points lt line(i) pt 7 ps 2 \
             title (missed_panel ? method(i) : '') @sweep_plots @label_elements, \
         NaN with points lc rgb '#555555' pt 6 ps 1.3 title (missed_panel && any_sweep ? 'sweep settings' : '')
}
unset multiplot

# ---- chart-sweep.png, chart-sweep-wall.png: mean time against the swept parameter --
if (sweep_param ne '') {
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
    unaffected(i) = listed(sweep_unaffected, method(i))
    any_unaffected = 0
    do for [i = 1:n] { if (unaffected(i)) { any_unaffected = 1 } }
    do for [wall = 0:1] {
        reset
        column_name = wall ? 'mean_ms' : mean_time_column
        what = wall ? 'wall time' : time_name
        ms_lo = 1e300; ms_hi = 0
        do for [i = 1:n] {
            stats sweep_file(i) using (column(column_name)) nooutput
            if (STATS_records > STATS_invalid) { ms_lo = min(ms_lo, STATS_min); ms_hi = max(ms_hi, STATS_max) }
        }
        log_y = ms_lo > 0 && ms_hi / ms_lo > 10
        set terminal @png_term size 1000,600
        set output out(wall ? 'chart-sweep-wall.png' : 'chart-sweep.png')
        set title (wall ? "Mean wall time per frame against ".sweep_param." (lower is better), the secondary view:\n".\
                          "it swings with the machine's load; ".time_name." is chart-sweep.png" \
                        : "Mean ".time_name." per frame against ".sweep_param." (lower is better)\n".time_name.": ".time_note). \
            "\n".run_title font ',13'
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
            set ylabel 'mean '.what.' per frame (ms, log scale)'
        } else {
            set yrange [0:*]
            set ylabel 'mean '.what.' per frame (ms)'
        }
        if (any_unaffected) {
            set label 1 'unaffected: '.sweep_param.' changes nothing the method draws (its spread is noise)' \
                at graph 0.01, graph 1.02 left font ',9' tc rgb '#6a6a6a'
        }
        if (by_rank) {
            # A column named by a variable does not tell gnuplot that the
            # first line names the columns: without this it would count that
            # line as the first point and shift every value one place right.
            set datafile columnheaders
            plot for [i = 1:n] sweep_file(i) using 0:(column(column_name)):xtic(strcol('value')) \
                with linespoints lt line(i) pt 7 ps 1.3 lw (unaffected(i) ? 1 : 2) \
                title method(i).(unaffected(i) ? ' (unaffected)' : '')
            unset datafile columnheaders
        } else {
            plot for [i = 1:n] sweep_file(i) using 'value':(column(column_name)) \
                with linespoints lt line(i) pt 7 ps 1.3 lw (unaffected(i) ? 1 : 2) \
                title method(i).(unaffected(i) ? ' (unaffected)' : '')
        }
    }
}

# ---- chart-pareto.png: speed against accuracy over a sweep (--verify) -------------
# One point per method and value: mean primary time per frame against missed
# pixels per frame (left) and depth errors per frame (right); conservative
# points (T = 0) filled squares, the others open circles; the points of the
# Pareto front (no other point as fast with as few errors, and better in
# one) ringed, named and joined by a black staircase. The oracles are drawn
# but never on a front: they need the ID pass (the front itself comes from
# pareto.c).
if (pareto) {
    reset
    set terminal @png_term size 1200,600
    set output out('chart-pareto.png')
    set multiplot title "Speed against accuracy over the sweep of ".sweep_param. \
        ": one point per method and value, lower left is better\n".run_title.'; '.time_name.': '.time_note font ',13'
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set xlabel 'mean '.time_name.' per frame (ms)'
    set xrange [pa_x_lo:pa_x_hi]
    set logscale y
    tic_axis = 'y'
    mine(i) = strcol('method') eq method(i)
    do for [panel = 1:2] {
        depth_panel = panel == 2
        eval panel_margins
        column_name = depth_panel ? 'depth_errors_per_frame' : 'missed_per_frame'
        front_file = depth_panel ? 'chart-data/pareto-front-depth.dat' : 'chart-data/pareto-front.dat'
        tic_hi = pa_y_hi[panel]
        set yrange [pa_y_lo[panel]:pa_y_hi[panel]]
        eval symlog_tics
        set title (depth_panel ? 'Depth errors (anything drawn wrong)' : 'Missed pixels (visible errors)') font ',12'
        set ylabel (depth_panel ? 'depth errors' : 'missed pixels').' per frame, mean (log scale of 1 + value)'
        set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lc rgb '#9a9a9a' dt 2 back
        set label 1 (depth_panel ? 'no depth error' : 'no pixel missed') at graph 0.99, first 1 right offset 0,-1 tc rgb '#6a6a6a' font ',9'
        # Keys under the panels, where they hide no point: the methods
        # under the left one, the marks under the right one.
        set key at graph 0.5, screen 0.01 center bottom horizontal maxcols 3 Left reverse samplen 1 width 1
        label_file = sprintf('chart-data/labels-pareto-%d.dat', panel)
        plot for [i = 1:n] 'chart-data/pareto.dat' \
                 using 'time_ms':(mine(i) && column('conservative') > 0 ? column(column_name) + 1 : NaN) \
                 with points lt line(i) pt 5 ps 1.4 title (depth_panel ? '' : method(i)), \
             for [i = 1:n] 'chart-data/pareto.dat' \
                 using 'time_ms':(mine(i) && column('conservative') == 0 ? column(column_name) + 1 : NaN) \
                 with points lt line(i) pt 6 ps 1.4 lw 1.5 notitle, \
             front_file using 'time_ms':(column(column_name) + 1) with steps lc rgb '#000000' lw 1.5 \
                 notitle, \
             front_file using 'time_ms':(column(column_name) + 1) with points lc rgb '#000000' \
                 pt 6 ps 2.6 lw 1.2 title (depth_panel ? 'Pareto front' : '') @label_elements, \
             NaN with points lc rgb '#555555' pt 5 ps 1.4 title (depth_panel ? 'conservative (T = 0)' : ''), \
             NaN with points lc rgb '#555555' pt 6 ps 1.4 title (depth_panel ? 'T > 0' : '')
        unset arrow
        unset label
    }
    unset multiplot
}

# ---- chart-lod.png: speed against image error over a sweep of max_screen_error ----
# One point per method and value (--verify): the pixels differing from full
# detail (% of the image, mean per frame) against the mean primary time per
# frame; each method's points joined in order of value, each labelled with
# its value; the points of the Pareto front of time against image error
# (pareto.c) ringed and joined by a black staircase. The oracles are drawn
# but never on the front.
if (lod) {
    reset
    set terminal @png_term size 1200,600
    set output out('chart-lod.png')
    set lmargin at screen panel_left[1]
    set rmargin at screen panel_right[2]
    set tmargin at screen panel_top
    set bmargin at screen panel_bottom
    set title "Speed against image error over the sweep of ".sweep_param.", lower left is better\n". \
        "one point per method and value, labelled with the value; ".run_title."\n". \
        time_name.': '.time_note font ',13'
    set grid xtics ytics lc rgb '#d8d8d8'
    set border 3
    set tics nomirror
    set xlabel 'pixels differing from full detail, mean per frame (% of the image)'
    set ylabel 'mean '.time_name.' per frame (ms)'
    set xrange [0:lod_x_hi]
    set yrange [pa_x_lo:pa_x_hi]
    set key at graph 0.5, screen 0.01 center bottom horizontal maxcols 5 Left reverse samplen 1 width 1
    mine(i) = strcol('method') eq method(i)
    percent(c) = 100 * column(c)
    front_file = 'chart-data/pareto-front-lod.dat'
    label_file = 'chart-data/labels-lod.dat'
    plot for [i = 1:n] 'chart-data/pareto-lod.dat' \
             using (mine(i) ? percent('lod_fraction') : NaN):'time_ms' \
             with linespoints lt line(i) pt 7 ps 1.3 lw 1 dt 3 title method(i), \
         front_file using (percent('lod_fraction')):'time_ms' with steps lc rgb '#000000' lw 1.5 \
             dt solid notitle, \
         front_file using (percent('lod_fraction')):'time_ms' with points lc rgb '#000000' \
             pt 6 ps 2.6 lw 1.2 dt solid title 'Pareto front' @label_elements
}

# ---- chart-split.png: with --split, each method's CPU time parted -------------------
# The frame's CPU time is the outlined bar; inside it, the part its set costs
# when drawn again with no culling, and above that what finding the set
# cost. A set that cost more than its frame (noise, or a frame that drew in
# a cheaper order) stands out above the outline. CPU time whatever `time`
# says: the redrawn set is timed on the CPU only.
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
