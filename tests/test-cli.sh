#!/usr/bin/env bash
# The tileworld command's contract (DESIGN.md §9): bad input exits non-zero
# with exactly one line on stderr and never crashes; a walk writes its
# reports; a walk far from the origin writes the same PNGs, byte for byte.
set -u
tw=${1:?usage: test-cli.sh PATH/TO/tileworld}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0

ok() { passed=$((passed + 1)); }
bad() { failed=$((failed + 1)); echo "FAIL: $*" >&2; }

# expect_usage_error ARGS...: exit status 2 and exactly one stderr line.
expect_usage_error() {
    "$tw" "$@" >"$tmp/out" 2>"$tmp/err"
    local rc=$?
    local lines
    lines=$(wc -l <"$tmp/err")
    if [ "$rc" -ne 2 ]; then
        bad "tileworld $* exited $rc (expected 2): $(head -c 300 "$tmp/err")"
    elif [ "$lines" -ne 1 ]; then
        bad "tileworld $* wrote $lines lines on stderr (expected 1): $(head -c 300 "$tmp/err")"
    elif ! grep -q '^tileworld: ' "$tmp/err"; then
        bad "tileworld $*: stderr does not start with 'tileworld: ': $(cat "$tmp/err")"
    else
        ok
    fi
}

small=(--size 96x54 --frames 2 --png-every 0 --quiet --out "$tmp/x")
expect_usage_error
expect_usage_error frobnicate
expect_usage_error walk --tileset nope "${small[@]}"
expect_usage_error walk --tileset "$tmp" "${small[@]}"
expect_usage_error walk --size 12x "${small[@]:2}"
expect_usage_error walk --size abc
expect_usage_error walk --size 0x100
expect_usage_error walk --size 100000x100
expect_usage_error walk --size 100x-5
expect_usage_error walk --frames nan
expect_usage_error walk --frames -1
expect_usage_error walk --frames 0
expect_usage_error walk --frames 99999999999999999999999
expect_usage_error walk --frames 1.5
expect_usage_error walk --seed 1e5
expect_usage_error walk --seed -3
expect_usage_error walk --start-cell 1,
expect_usage_error walk --start-cell ,1
expect_usage_error walk --start-cell 9223372036854775808,0
expect_usage_error walk --start-cell 4611686018427387905,0
expect_usage_error walk --start-cell nan,0
expect_usage_error walk --repeat 0
expect_usage_error walk --view-distance nan
expect_usage_error walk --view-distance inf
expect_usage_error walk --view-distance -5
expect_usage_error walk --method nope
expect_usage_error walk --path nope
expect_usage_error walk --path "$tmp/missing.csv"
expect_usage_error walk --out
expect_usage_error walk --bogus 1
expect_usage_error walk stray
expect_usage_error bench --methods vfc,vfc
expect_usage_error bench --methods ,
expect_usage_error walk --methods vfc "${small[@]}"

# Malformed path files: the message names the file and the line.
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n0,0,1,1.7,1,0,nan\n' >"$tmp/nan.csv"
printf '0,0,1,1.7,1,0,0\n' >"$tmp/noheader.csv"
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n0,0,1,1.7\n' >"$tmp/short.csv"
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n99999999999999999999,0,1,1.7,1,0,0\n' >"$tmp/big.csv"
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n0,0,1,1.7,1,0,95\n' >"$tmp/pitch.csv"
: >"$tmp/empty.csv"
for f in nan noheader short big pitch empty; do
    expect_usage_error walk --path "$tmp/$f.csv" "${small[@]}"
done
if grep -q "nan.csv:2:" <("$tw" walk --path "$tmp/nan.csv" "${small[@]}" 2>&1); then ok; else bad "path error does not name file:line"; fi

# A path file works wherever a path name goes, and --frames defaults to its rows.
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n0,0,0,1.7,3,0,0\n0,0,0,1.7,4,10,0\n-1,0,79.5,1.7,5,20,1\n' >"$tmp/good.csv"
if "$tw" walk --path "$tmp/good.csv" --size 96x54 --png-every 0 --quiet --out "$tmp/csv" 2>"$tmp/err" &&
   [ "$(wc -l <"$tmp/csv/frames.csv")" -eq 4 ]; then ok; else bad "walk over a CSV path: $(cat "$tmp/err")"; fi

# A walk writes frames.csv (header + one row per frame), summary.json, PNGs.
if "$tw" walk --tileset city --path street --frames 5 --method vfc --size 160x90 --png-every 2 \
      --quiet --out "$tmp/walk" 2>"$tmp/err"; then
    [ "$(wc -l <"$tmp/walk/frames.csv")" -eq 6 ] && ok || bad "frames.csv row count"
    head -1 "$tmp/walk/frames.csv" | grep -q '^frame,method,ms_frame,ms_cull,ms_wait,triangles,clusters,draws,queries,tiles_queried,tiles_visible,tiles_new,tiles_cached,cache_bytes,predict_fail,missed_pixels,missed_clusters,overdraw_triangles$' \
        && ok || bad "frames.csv header"
    for key in '"methods"' '"vfc"' '"mean_ms"' '"median_ms"' '"p95_ms"' '"p99_ms"' '"mean_triangles"' \
               '"mean_queries"' '"missed_pixels_total"' '"frames_with_missed_pixels"' \
               '"tiles_new_total"' '"peak_cache_bytes"' '"predict_fail_rate"' '"tileset"' '"path"' \
               '"size"' '"seed"'; do
        grep -q "$key" "$tmp/walk/summary.json" && ok || bad "summary.json lacks $key"
    done
    [ -s "$tmp/walk/frame-00000.png" ] && [ -s "$tmp/walk/frame-00004.png" ] && ok || bad "PNG snapshots"
    [ ! -e "$tmp/walk/frame-00001.png" ] && ok || bad "--png-every 2 wrote frame 1"
    awk -F, 'NR > 1 && ($6 <= 0 || $11 <= 0) { exit 1 }' "$tmp/walk/frames.csv" && ok || bad "frames draw nothing"
else
    bad "walk failed: $(cat "$tmp/err")"
fi

# Far from the origin: the same PNG files, byte for byte (DESIGN §3).
common=(walk --tileset city --path street --frames 12 --method vfc --size 160x90 --png-every 4 --repeat 4 --quiet)
if "$tw" "${common[@]}" --start-cell 0,0 --out "$tmp/near" 2>"$tmp/err" &&
   "$tw" "${common[@]}" --start-cell 1099511627776,1099511627776 --out "$tmp/far" 2>>"$tmp/err"; then
    n=0
    for f in "$tmp"/near/*.png; do
        n=$((n + 1))
        cmp -s "$f" "$tmp/far/$(basename "$f")" && ok || bad "$(basename "$f") differs far from the origin"
    done
    [ "$n" -eq 3 ] && ok || bad "expected 3 PNGs, found $n"
else
    bad "far-origin walks failed: $(cat "$tmp/err")"
fi

# info prints a row per prototype and the common box.
if "$tw" info --tileset city >"$tmp/info" 2>"$tmp/err"; then
    grep -q '^tile ' "$tmp/info" && grep -q '^common box:' "$tmp/info" && ok || bad "info output"
    rows=$(awk '/^tile /{on=1; next} /^total:/{on=0} on' "$tmp/info" | wc -l)
    [ "$rows" -ge 8 ] && ok || bad "info lists $rows prototypes"
else
    bad "info failed: $(cat "$tmp/err")"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
