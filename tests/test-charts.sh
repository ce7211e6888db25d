#!/usr/bin/env bash
# Charts of a bench run (runtime/charts.h): a small bench draws valid PNGs;
# a sweep.csv adds the sweep chart; malformed input and a missing gnuplot
# give a non-zero exit with one line naming the file and the place.
#   test-charts.sh PATH/TO/tileworld [PATH/TO/charts-driver]
# Without the driver only the bench's own charts are checked (bench must
# then draw them itself).
set -u
tw=${1:?usage: test-charts.sh PATH/TO/tileworld [PATH/TO/charts-driver]}
driver=${2:-}
if ! command -v gnuplot >/dev/null 2>&1; then
    echo "SKIP: gnuplot is not installed" >&2
    exit 77
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0

ok() { passed=$((passed + 1)); }
bad() { failed=$((failed + 1)); echo "FAIL: $*" >&2; }

# expect_png FILE: the 8-byte PNG signature and more than a blank image's
# few hundred bytes (a chart with axes, text and lines is tens of kB).
expect_png() {
    local f=$1
    if [ ! -f "$f" ]; then
        bad "$f was not written"
        return
    fi
    local sig size
    sig=$(head -c 8 "$f" | od -An -tx1 | tr -d ' \n')
    size=$(wc -c <"$f")
    if [ "$sig" != "89504e470d0a1a0a" ]; then
        bad "$f is not a PNG (signature $sig)"
    elif [ "$size" -lt 10000 ]; then
        bad "$f is only $size bytes"
    else
        ok
    fi
}

# expect_failure NAME PATTERN CMD...: non-zero exit, exactly one stderr line
# that matches PATTERN (an extended regex).
expect_failure() {
    local name=$1 pattern=$2
    shift 2
    "$@" >"$tmp/out" 2>"$tmp/err"
    local rc=$?
    local lines
    lines=$(wc -l <"$tmp/err")
    if [ "$rc" -eq 0 ]; then
        bad "$name: exited 0"
    elif [ "$lines" -ne 1 ]; then
        bad "$name: $lines lines on stderr (expected 1): $(head -c 400 "$tmp/err")"
    elif ! grep -Eq -- "$pattern" "$tmp/err"; then
        bad "$name: stderr does not match '$pattern': $(cat "$tmp/err")"
    else
        ok
    fi
}

run="$tmp/run"
if ! "$tw" bench --frames 6 --size 160x90 --methods vfc,chc,oracle --verify --png-every 0 \
        --quiet --out "$run" 2>"$tmp/bench-err"; then
    bad "bench failed: $(head -c 400 "$tmp/bench-err")"
    echo "charts: $passed passed, $failed failed"
    exit 1
fi
if [ -n "$driver" ]; then
    "$driver" "$run" 2>"$tmp/err" && ok || bad "charts-driver $run: $(cat "$tmp/err")"
fi
for chart in chart-frame-time chart-triangles chart-speed-accuracy; do
    expect_png "$run/$chart.png"
done
[ -f "$run/charts.gp" ] && ok || bad "$run/charts.gp was not written"
[ ! -e "$run/chart-sweep.png" ] && ok || bad "chart-sweep.png drawn without a sweep.csv"

if [ -z "$driver" ]; then
    echo "charts: $passed passed, $failed failed (no charts-driver: input errors not checked)"
    [ "$failed" -eq 0 ]
    exit
fi

# charts.gp re-runs as it is, in its folder.
rm -f "$run/chart-triangles.png"
(cd "$run" && gnuplot charts.gp) 2>"$tmp/err" && ok || bad "gnuplot charts.gp: $(cat "$tmp/err")"
expect_png "$run/chart-triangles.png"

# A sweep adds its chart; a non-numeric parameter is plotted by rank.
sweep="$tmp/sweep"
mkdir -p "$sweep"
cp "$run/frames.csv" "$sweep/"
cat >"$sweep/sweep.csv" <<'EOF'
method,param,value,mean_ms,median_ms,p95_ms,mean_triangles,mean_queries,missed_pixels_total,mean_overdraw_triangles
chc,T,0,20.5,20.1,24.0,119000,160,0,20000
chc,T,10,18.2,18.0,21.0,110000,150,35,15000
chc,T,100,15.9,15.5,19.0,100000,140,900,9000
vfc,cluster_triangles,64,80.0,79.0,90.0,1100000,0,0,990000
vfc,cluster_triangles,256,70.0,69.0,80.0,1080000,0,0,980000
chc,cluster_triangles,64,25.0,24.0,30.0,120000,300,0,21000
chc,cluster_triangles,256,21.0,20.0,26.0,119000,160,0,20000
oracle,order,front,9.0,9.0,10.0,87000,0,0,0
oracle,order,back,9.5,9.4,10.1,87000,0,0,0
EOF
"$driver" "$sweep" 2>"$tmp/err" && ok || bad "charts-driver with sweep.csv: $(cat "$tmp/err")"
for chart in chart-speed-accuracy chart-sweep; do
    expect_png "$sweep/$chart.png"
done

# Malformed input: one line naming the file and the line.
bad_dir="$tmp/bad"
mkdir -p "$bad_dir"
expect_failure "missing frames.csv" "$bad_dir/frames.csv: cannot read" "$driver" "$bad_dir"
: >"$bad_dir/frames.csv"
expect_failure "empty frames.csv" "frames.csv: empty file" "$driver" "$bad_dir"
head -n 3 "$run/frames.csv" >"$bad_dir/frames.csv"
echo "4,vfc,12.5,oops" >>"$bad_dir/frames.csv"
expect_failure "short row" "frames.csv:4: 4 fields where the header has [0-9]+" "$driver" "$bad_dir"
head -n 2 "$run/frames.csv" >"$bad_dir/frames.csv"
tail -n 1 "$run/frames.csv" | sed 's/^\([^,]*\),\([^,]*\),[^,]*,/\1,\2,fast,/' >>"$bad_dir/frames.csv"
expect_failure "bad number" "frames.csv:3: column 'ms_frame': 'fast' is not a non-negative number" \
    "$driver" "$bad_dir"
sed 's/ms_frame/ms_total/' "$run/frames.csv" >"$bad_dir/frames.csv"
expect_failure "missing column" "frames.csv:1: the header has no 'ms_frame' column" "$driver" "$bad_dir"
head -n 1 "$run/frames.csv" >"$bad_dir/frames.csv"
expect_failure "header only" "frames.csv: no frames" "$driver" "$bad_dir"
cp "$run/frames.csv" "$bad_dir/frames.csv"
printf 'method,param,value,mean_ms,missed_pixels_total,mean_overdraw_triangles\nchc,T,1,-3,0,0\n' \
    >"$bad_dir/sweep.csv"
expect_failure "bad sweep.csv" "sweep.csv:2: column 'mean_ms'" "$driver" "$bad_dir"
rm "$bad_dir/sweep.csv"

# No gnuplot in PATH: an error that says so (the caller warns and goes on).
expect_failure "no gnuplot" "gnuplot is not installed" env PATH="$tmp/empty-path" "$driver" "$run"

# gnuplot fails: its last stderr line, on the one line.
mkdir -p "$tmp/fake-bin"
cat >"$tmp/fake-bin/gnuplot" <<'EOF'
#!/bin/sh
echo "" >&2
echo "plot 'chart-data/x.dat'" >&2
echo "     ^" >&2
echo '"charts.gp" line 3: something broke' >&2
exit 1
EOF
chmod +x "$tmp/fake-bin/gnuplot"
expect_failure "gnuplot fails" \
    'charts.gp: gnuplot failed \(exit status 1\): "charts.gp" line 3: something broke$' \
    env PATH="$tmp/fake-bin" "$driver" "$run"

echo "charts: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
