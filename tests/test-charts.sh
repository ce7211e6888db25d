#!/usr/bin/env bash
# Charts of a bench run (tools/tileworld/charts.h): a small bench draws PNGs
# that decode, plotting CPU time (llvmpipe is a software renderer) with wall
# time in charts of its own; its charts.gp re-runs in the folder; a sweep
# adds the sweep charts, a sweep of max_screen_error chart-lod.png; gnuplot missing or failing is one warning line and
# the run still succeeds, with no chart under its final name; a full disk
# (a small tmpfs, where mounting is permitted) fails the run with one line
# and leaves no chart that is not whole.
#   test-charts.sh PATH/TO/tileworld PATH/TO/png-check
set -u
tw=${1:?usage: test-charts.sh PATH/TO/tileworld PATH/TO/png-check}
check=${2:?usage: test-charts.sh PATH/TO/tileworld PATH/TO/png-check}
if ! command -v gnuplot >/dev/null 2>&1; then
    echo "SKIP: gnuplot is not installed" >&2
    exit 77
fi
. "$(dirname "$0")/test-lib.sh"

# expect_chart FILE SIZE: decodes at SIZE with the many colours of
# antialiased lines and text (a blank or one-colour image has a few).
expect_chart() {
    local f=$1 size=$2 out
    if [ ! -f "$f" ]; then
        bad "$f was not written"
        return
    fi
    if ! out=$("$check" "$f"); then
        bad "$f does not decode as PNG"
        return
    fi
    local got colours
    got=$(awk '{ print $2 }' <<<"$out")
    colours=$(awk '{ print $4 }' <<<"$out")
    if [ "$got" != "$size" ]; then
        bad "$f is $got, not $size"
    elif [ "$colours" -lt 50 ]; then
        bad "$f has only $colours colours: $out"
    else
        ok
    fi
}

# expect_one_line NAME PATTERN FILE: FILE holds exactly one line, matching
# the extended regex PATTERN.
expect_one_line() {
    local lines
    lines=$(wc -l <"$3")
    if [ "$lines" -ne 1 ]; then
        bad "$1: $lines lines on stderr (expected 1): $(head -c 400 "$3")"
    elif ! grep -Eq -- "$2" "$3"; then
        bad "$1: stderr does not match '$2': $(cat "$3")"
    else
        ok
    fi
}

# no_charts NAME DIR: no chart PNG under a final or a temporary name.
no_charts() {
    local left
    left=$(cd "$2" && ls -A | grep -E '^\.?chart-.*\.png(\.tmp)?$')
    [ -z "$left" ] && ok || bad "$1: charts left in $2: $left"
}

small=(--size 160x90 --methods vfc,chc,oracle --verify --png-every 0 --quiet)

# ---- a small bench -------------------------------------------------------------
run="$tmp/run"
if ! "$tw" bench --frames 6 "${small[@]}" --out "$run" 2>"$tmp/bench-err"; then
    bad "bench failed: $(head -c 400 "$tmp/bench-err")"
    finish charts
fi
[ ! -s "$tmp/bench-err" ] && ok || bad "bench printed: $(head -c 400 "$tmp/bench-err")"
expect_chart "$run/chart-frame-time.png" 1000x600
expect_chart "$run/chart-frame-time-wall.png" 1000x600
expect_chart "$run/chart-triangles.png" 1000x600
expect_chart "$run/chart-speed-accuracy.png" 1200x600
[ ! -e "$run/chart-sweep.png" ] && ok || bad "chart-sweep.png drawn without a sweep"
[ ! -e "$run/chart-split.png" ] && ok || bad "chart-split.png drawn without --split"
[ -f "$run/charts.gp" ] && ok || bad "$run/charts.gp was not written"
[ -f "$run/gnuplot.log" ] && ok || bad "$run/gnuplot.log was not written"
[ -z "$(cd "$run" && ls -A | grep '\.tmp$')" ] && ok || bad "temporaries left in $run"

# The data: a line of column names, one row per frame of each method, the
# frames.csv columns but method, with the same numbers.
for m in vfc chc oracle; do
    f="$run/chart-data/frames-$m.dat"
    if [ ! -f "$f" ]; then
        bad "$f was not written"
        continue
    fi
    head -2 "$f" | tail -1 | grep -q '^frame ms_frame ms_cull ms_wait triangles clusters draws queries' \
        && ok || bad "$f: no header of column names"
    [ "$(grep -vc '^#' "$f")" -eq 7 ] && ok || bad "$f: expected a header and 6 rows"
    want=$(awk -F, -v m="$m" '$2 == m { $2 = ""; print }' OFS=' ' "$run/frames.csv" | sed 's/  / /')
    got=$(grep -v '^#' "$f" | tail -n +2)
    [ "$want" = "$got" ] && ok || bad "$f differs from the $m rows of frames.csv"
done
grep -q '^method frames mean_ms ' "$run/chart-data/methods.dat" && ok || bad "methods.dat header"
[ "$(awk '$1 == "chc" || $1 == "vfc" || $1 == "oracle"' "$run/chart-data/methods.dat" | wc -l)" -eq 3 ] \
    && ok || bad "methods.dat rows"
grep -q "^methods = 'vfc chc oracle'" "$run/chart-data/run.gp" && ok || bad "run.gp methods"
grep -q "^run_title = 'tileset city, path street, 160x90'" "$run/chart-data/run.gp" && ok || bad "run.gp title"
grep -q '^verified = 1' "$run/chart-data/run.gp" && ok || bad "run.gp verified"
# The time the charts plot: CPU time on a software renderer (OSMesa's
# llvmpipe), each method's mean the summary's.
grep -q "^time = 'cpu'$" "$run/chart-data/run.gp" && grep -q "^frame_time_column = 'cpu_ms'$" \
    "$run/chart-data/run.gp" && grep -q "^mean_time_column = 'mean_cpu_ms'$" "$run/chart-data/run.gp" &&
    ok || bad "run.gp: not CPU time: $(grep -E '^(time|frame_time_column|mean_time_column) ' "$run/chart-data/run.gp")"
grep -q ' mean_cpu_ms .* mean_gpu_ms gpu_frames$' "$run/chart-data/methods.dat" && ok || bad "methods.dat: time columns"
# The speed-accuracy labels: one per method in each panel, none of kind 0.
for p in 1 2; do
    f="$run/chart-data/labels-speed-accuracy-$p.dat"
    [ "$(awk 'NR > 2 && $2 == 1' "$f" 2>/dev/null | wc -l)" -eq 3 ] && ok || bad "$f: expected 3 method labels"
done

# The same script is built into the program and written into the folder.
src=$(dirname "$0")/../tools/tileworld/charts.gp
cmp -s "$src" "$run/charts.gp" && ok || bad "$run/charts.gp differs from $src"

# charts.gp re-runs as it is, in its folder, and writes final names.
rm -f "$run/chart-triangles.png"
(cd "$run" && gnuplot charts.gp) 2>"$tmp/err" && [ ! -s "$tmp/err" ] && ok ||
    bad "gnuplot charts.gp: $(cat "$tmp/err")"
expect_chart "$run/chart-triangles.png" 1000x600

# ---- --split adds its chart -----------------------------------------------------
split="$tmp/split"
if "$tw" bench --frames 3 "${small[@]}" --split --out "$split" 2>"$tmp/err"; then
    expect_chart "$split/chart-split.png" 1000x600
    grep -q '^split = 1' "$split/chart-data/run.gp" && ok || bad "run.gp: split"
    head -2 "$split/chart-data/frames-chc.dat" | tail -1 | grep -q ' set_cpu_ms set_ms set_triangles set_draws overdraw_box_triangles gpu_ms gpu_ms_id waits flushes bytes_read_back tiles_late hzb_lag lod_pixels lod_pixels_exact lod_depth_m objects object_cells object_rebuilds ms_objects$' &&
        ok || bad "frames-chc.dat: no set_* columns"
else
    bad "bench --split: $(head -c 400 "$tmp/err")"
fi
grep -q '^split = 0' "$run/chart-data/run.gp" && ok || bad "run.gp: split without --split"

# ---- a sweep adds its chart ------------------------------------------------------
sweep="$tmp/sweep"
if "$tw" bench --frames 3 "${small[@]}" --sweep T=0,10 --out "$sweep" 2>"$tmp/err"; then
    ok
    expect_chart "$sweep/chart-sweep.png" 1000x600
    expect_chart "$sweep/chart-sweep-wall.png" 1000x600
    expect_chart "$sweep/chart-speed-accuracy.png" 1200x600
    # A label for each method and each value of chc (vfc and the oracle are
    # unaffected: their points are not repeated).
    f="$sweep/chart-data/labels-speed-accuracy-1.dat"
    [ "$(awk 'NR > 2 && $2 == 2 && $1 == "chc"' "$f" | wc -l)" -eq 2 ] &&
        [ "$(awk 'NR > 2 && $2 == 2 && $1 != "chc"' "$f" | wc -l)" -eq 0 ] && ok || bad "$f: sweep labels"
    for m in vfc chc oracle; do
        f="$sweep/chart-data/sweep-$m.dat"
        [ "$(awk '$1 == "0" || $1 == "10"' "$f" 2>/dev/null | wc -l)" -eq 2 ] && ok ||
            bad "$f: expected one row per value"
    done
    grep -q "^sweep_param = 'T'" "$sweep/chart-data/run.gp" && grep -q "^sweep_values = '0 10'" \
        "$sweep/chart-data/run.gp" && ok || bad "run.gp sweep"
    # vfc and the oracle draw the same at every T.
    grep -q "^sweep_unaffected = 'vfc oracle'" "$sweep/chart-data/run.gp" && ok ||
        bad "run.gp: $(grep unaffected "$sweep/chart-data/run.gp")"
    # Speed against accuracy: a point per method and value, the fronts, sweep.md.
    expect_chart "$sweep/chart-pareto.png" 1200x600
    grep -q '^pareto = 1' "$sweep/chart-data/run.gp" && ok || bad "run.gp: pareto"
    f="$sweep/chart-data/pareto.dat"
    head -2 "$f" | tail -1 | grep -q '^method value mean_cpu_ms missed_per_frame depth_errors_per_frame conservative front front_depth speedup time_ms mean_gpu_ms lod_fraction front_lod$' &&
        ok || bad "$f: header"
    [ "$(grep -vc '^#' "$f")" -eq 7 ] && ok || bad "$f: expected a header and 6 points"
    # T=0 is conservative, T=10 not, for chc; vfc and the oracle always.
    awk '$1 == "chc" && $2 == "0" && $6 == 1 { a++ } $1 == "chc" && $2 == "10" && $6 == 0 { b++ }
         $1 == "vfc" && $6 == 1 { c++ } END { exit !(a == 1 && b == 1 && c == 2) }' "$f" && ok ||
        bad "$f: conservative column: $(cat "$f")"
    # The oracle is never on a front, and every front point is in pareto.dat.
    awk '$1 == "oracle" && ($7 == 1 || $8 == 1) { exit 1 }' "$f" && ok || bad "$f: the oracle on a front"
    # CPU time: time_ms is mean_cpu_ms.
    awk 'NR > 2 && $10 != $3 { exit 1 }' "$f" && ok || bad "$f: time_ms is not mean_cpu_ms"
    front=$(awk 'NR > 2 && $7 == 1' "$f")
    [ -n "$front" ] && [ "$front" = "$(tail -n +3 "$sweep/chart-data/pareto-front.dat")" ] && ok ||
        bad "pareto-front.dat does not hold the front of pareto.dat"
    grep -q '^| method | T | mean CPU ms | speed-up vs T=0 |' "$sweep/sweep.md" && ok || bad "sweep.md table"
    grep -q '^\*\*The front of CPU time against missed pixels\*\*' "$sweep/sweep.md" && ok || bad "sweep.md front"
    grep -q '^mean_cpu_ms\|,mean_cpu_ms,' "$sweep/sweep.csv" && ok || bad "sweep.csv: mean_cpu_ms"
    # chart-lod.png is a sweep of max_screen_error's only.
    [ ! -e "$sweep/chart-lod.png" ] && [ ! -e "$sweep/chart-data/pareto-lod.dat" ] &&
        [ ! -e "$sweep/chart-data/labels-lod.dat" ] && grep -q '^lod = 0$' "$sweep/chart-data/run.gp" &&
        ok || bad "chart-lod.png or its data drawn for a sweep of T"
else
    bad "bench --sweep failed: $(head -c 400 "$tmp/err")"
fi

# ---- a sweep of max_screen_error adds chart-lod.png ------------------------------------
# Speed against image error: a point per method and value, each method's
# joined by value, the front of time against the pixels differing from full
# detail.
lod="$tmp/lod"
if "$tw" bench --frames 2 "${small[@]}" --sweep max_screen_error=0,4 --out "$lod" 2>"$tmp/err"; then
    ok
    expect_chart "$lod/chart-lod.png" 1200x600
    expect_chart "$lod/chart-pareto.png" 1200x600
    grep -q '^lod = 1$' "$lod/chart-data/run.gp" && ok || bad "run.gp: lod"
    f="$lod/chart-data/pareto.dat"
    # Full detail differs from itself nowhere; 4 px of error somewhere.
    awk '$1 == "chc" && $2 == "0" && $12 == 0 { a++ } $1 == "chc" && $2 == "4" && $12 > 0 { b++ }
         END { exit !(a == 1 && b == 1) }' "$f" && ok || bad "$f: lod_fraction: $(cat "$f")"
    awk '$1 == "oracle" && $13 == 1 { exit 1 }' "$f" && ok || bad "$f: the oracle on the image-error front"
    # pareto-lod.dat: every point, by method in the run's order and value.
    got=$(awk 'NR > 2 { printf "%s %s,", $1, $2 }' "$lod/chart-data/pareto-lod.dat")
    [ "$got" = "vfc 0,vfc 4,chc 0,chc 4,oracle 0,oracle 4," ] && ok || bad "pareto-lod.dat order: $got"
    # pareto-front-lod.dat: the front_lod rows of pareto.dat, by image error.
    g="$lod/chart-data/pareto-front-lod.dat"
    [ -n "$(awk 'NR > 2 && $13 == 1' "$f")" ] &&
        [ "$(awk 'NR > 2 && $13 == 1' "$f" | sort)" = "$(tail -n +3 "$g" | sort)" ] &&
        awk 'NR > 2 { if (NR > 3 && $12 < last) exit 1; last = $12 }' "$g" && ok ||
        bad "$g does not hold the image-error front of pareto.dat by lod_fraction: $(cat "$g")"
    [ "$(awk 'NR > 2 && $2 == 2' "$lod/chart-data/labels-lod.dat" | wc -l)" -eq 6 ] && ok ||
        bad "labels-lod.dat: expected a label per point"
    grep -q '^| method | max_screen_error | mean CPU ms | speed-up vs max_screen_error=0 | missed pixels / frame | depth errors / frame | pixels differing from full detail (%) |' \
        "$lod/sweep.md" && ok || bad "sweep.md: no image error column"
    grep -q '^\*\*The front of CPU time against image error (pixels differing from full detail)\*\*' \
        "$lod/sweep.md" && ok || bad "sweep.md: the image-error front not named"
    head -1 "$lod/sweep.csv" | grep -q ',conservative,lod_pixels_total,lod_pixel_fraction$' &&
        awk -F, 'NR > 1 && NF != 19 { exit 1 }' "$lod/sweep.csv" && ok || bad "sweep.csv: lod columns"
    awk -F, '$1 == "chc" && $3 == "0" && $18 == 0 && $19 == 0 { a++ } $1 == "chc" && $3 == "4" && $18 > 0 && $19 > 0 { b++ }
             END { exit !(a == 1 && b == 1) }' "$lod/sweep.csv" && ok || bad "sweep.csv: lod figures: $(cat "$lod/sweep.csv")"
else
    bad "bench --sweep max_screen_error failed: $(head -c 400 "$tmp/err")"
fi

# A later run without a sweep in the same folder leaves no sweep chart or
# sweep data of the earlier one.
if "$tw" bench --frames 2 "${small[@]}" --out "$sweep" 2>"$tmp/err"; then
    [ ! -e "$sweep/chart-sweep.png" ] && [ ! -e "$sweep/sweep.csv" ] && [ ! -e "$sweep/sweep-T-10" ] &&
        [ -z "$(ls "$sweep/chart-data" | grep '^sweep-\|^pareto')" ] && [ ! -e "$sweep/sweep.md" ] &&
        [ ! -e "$sweep/chart-pareto.png" ] && ok ||
        bad "a bench without a sweep left the earlier sweep's files: $(ls -A "$sweep" "$sweep/chart-data")"
    expect_chart "$sweep/chart-frame-time.png" 1000x600
else
    bad "bench over an earlier sweep failed: $(head -c 400 "$tmp/err")"
fi

# ---- no gnuplot in PATH: one warning line, exit 0, the data and script written ----
nogp="$tmp/nogp"
mkdir -p "$tmp/empty-path"
if env PATH="$tmp/empty-path" "$tw" bench --frames 2 "${small[@]}" --out "$nogp" 2>"$tmp/err"; then
    ok
    expect_one_line "no gnuplot" "^tileworld: warning: .*gnuplot is not installed" "$tmp/err"
    no_charts "no gnuplot" "$nogp"
    [ -f "$nogp/charts.gp" ] && [ -f "$nogp/chart-data/frames-vfc.dat" ] && [ -f "$nogp/summary.md" ] &&
        ok || bad "no gnuplot: charts.gp, chart data or summaries missing"
else
    bad "no gnuplot: bench exited non-zero: $(cat "$tmp/err")"
fi

# ---- gnuplot fails: its last line on the one warning line, no chart kept ----------
mkdir -p "$tmp/fake-bin"
cat >"$tmp/fake-bin/gnuplot" <<'EOF'
#!/bin/sh
# Draws one chart under its temporary name in the run's folder (tileworld
# passes -e "cd 'DIR'; ..."), then fails as gnuplot does.
dir=$(printf '%s\n' "$2" | sed "s/^cd '\\([^']*\\)'.*/\\1/")
echo drawn >"$dir/.chart-frame-time.png.tmp"
echo "" >&2
echo "plot 'chart-data/x.dat'" >&2
echo "     ^" >&2
echo '"charts.gp" line 3: something broke' >&2
exit 1
EOF
chmod +x "$tmp/fake-bin/gnuplot"
fails="$tmp/fails"
if env PATH="$tmp/fake-bin:$PATH" "$tw" bench --frames 2 "${small[@]}" --out "$fails" 2>"$tmp/err"; then
    ok
    expect_one_line "gnuplot fails" \
        'charts.gp: gnuplot failed \(exit status 1\), no charts: "charts.gp" line 3: something broke$' \
        "$tmp/err"
    no_charts "gnuplot fails" "$fails"
    grep -q 'something broke' "$fails/gnuplot.log" && ok || bad "gnuplot.log lacks gnuplot's output"
else
    bad "gnuplot fails: bench exited non-zero: $(cat "$tmp/err")"
fi

# ---- a full disk: one error line, exit 1, no chart that is not whole ---------------
# A tmpfs the run's data fits in (the size of the no-gnuplot run's folder,
# and 96 KiB more) and its charts do not. gnuplot exits 0 there having
# written charts short; they are refused. Needs mount: skipped without it.
full="$tmp/full"
mkdir -p "$full"
data_kb=$(du -sk "$nogp" 2>/dev/null | awk '{ print $1 }')
if [ -n "$data_kb" ] && mount -t tmpfs -o size=$((data_kb + 96))k tmpfs "$full" 2>/dev/null; then
    "$tw" bench --frames 2 "${small[@]}" --out "$full/run" 2>"$tmp/err"
    status=$?
    [ "$status" -eq 1 ] && ok || bad "full disk: exit status $status, not 1: $(cat "$tmp/err")"
    expect_one_line "full disk" \
        "^tileworld: $full/run(/chart-[a-z-]+\.png: cannot write|: cannot write the charts): No space left on device" \
        "$tmp/err"
    for f in "$full"/run/chart-*.png; do
        [ -e "$f" ] || continue
        "$check" "$f" >/dev/null 2>&1 && ok || bad "full disk: $f is not a whole PNG"
    done
    [ -z "$(cd "$full/run" && ls -A | grep '\.tmp$')" ] && ok || bad "full disk: temporaries left"
    umount "$full" || bad "cannot unmount $full"
else
    echo "full disk: skipped (cannot mount a tmpfs here)"
fi

finish charts
