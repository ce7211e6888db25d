#!/usr/bin/env bash
# The tileworld command's contract (DESIGN.md §9): bad input exits non-zero
# with exactly one line on stderr and never crashes; options take their
# value as --opt VALUE and --opt=VALUE; numbers are plain decimal digits; a
# walk writes its reports; a walk far from the origin writes the same PNGs,
# byte for byte; output files are whole or absent (a full disk, a killed
# run, a failed run leave no half-written or stale file under a final name).
set -u
tw=${1:?usage: test-cli.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

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
# Full detail where the command's contract does not depend on the levels:
# a process that shows the city builds them first (about 3 s; ten under
# AddressSanitizer), and this test runs many. Its walks of the report
# (below) and of a full run into a folder, and info, keep the default;
# test-lod-world, test-hlod-world, test-charts and test-tiles3d-levels
# cover the levels through the program.
full=(--max-screen-error 0)
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
expect_usage_error walk --fps 0
expect_usage_error walk --fps 10001
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

# --opt=value works as --opt value does, for the same checks.
expect_usage_error walk --size=12x "${small[@]:2}"
expect_usage_error walk --frames=0
expect_usage_error walk --method=nope
expect_usage_error walk --out=
expect_usage_error walk --verify=yes
expect_usage_error walk --bogus=1
expect_usage_error walk --frames
expect_usage_error walk --chc 5          # ambiguous: --chc-batch, --chc-nav
expect_usage_error walk -x
expect_usage_error walk -- --frames 2
expect_usage_error import
expect_usage_error info --tileset city extra

# Accuracy options: a tolerance above 0 and below 1, a shrink below 1.
for v in 0 0.0 1 1.5 -0.1 1e-5 abc ''; do
    expect_usage_error walk --verify-tolerance "$v" "${small[@]}"
done
for v in 1 1.0 -0.1 2 1e-2 nan; do
    expect_usage_error walk --mutate-query-shrink "$v" "${small[@]}"
done
expect_usage_error walk --deterministic=yes "${small[@]}"
# A scenario runs its own path and selection: what it would ignore is refused.
expect_usage_error bench --scenario spin --path street "${small[@]}"
expect_usage_error bench --scenario spin --start-cell 3,4 "${small[@]}"
expect_usage_error bench --scenario spin --repeat 4 "${small[@]}"
expect_usage_error bench --scenario spin --sweep T=0,1 "${small[@]}"
"$tw" bench --scenario spin --path street 2>"$tmp/err"
grep -q -- "--path: --scenario runs its own path" "$tmp/err" && ok || bad "scenario --path: $(cat "$tmp/err")"

# Numbers mean what they say: plain decimal digits only.
for v in 0x10 inf nan 1e400 1e3 ' 5' '5 ' +5 '' 1. .5 1,5 ０; do
    expect_usage_error walk --view-distance "$v"
done
for v in 0x10 +5 ' 5' 1e2 010x 5.0 -0; do
    expect_usage_error walk --frames "$v"
done
expect_usage_error walk --start-cell +1,0
expect_usage_error walk --start-cell 0x1,0
expect_usage_error bench --sweep T=0x10
expect_usage_error bench --sweep view_distance=1e3
expect_usage_error bench --sweep T=inf
"$tw" walk --view-distance 0x10 2>"$tmp/err"
grep -q -- "--view-distance: '0x10' is not a decimal number" "$tmp/err" && ok || bad "0x10: $(cat "$tmp/err")"
"$tw" walk --frames=99999999999999999999 2>"$tmp/err"
grep -q -- "--frames: '99999999999999999999' is out of range \[1, 10000000\]" "$tmp/err" && ok ||
    bad "range message: $(cat "$tmp/err")"

# Control characters from argv are escaped in messages.
expect_usage_error walk --tileset "$(printf 'a\033[31mb')"
"$tw" walk --tileset "$(printf 'a\033[31mb')" 2>"$tmp/err"
if grep -q "a\\\\x1b\[31mb" "$tmp/err" && ! grep -q "$(printf '\033')" "$tmp/err"; then ok; else
    bad "control characters not escaped: $(od -c "$tmp/err" | head -3)"; fi
expect_usage_error $'wa\nlk'
expect_usage_error walk $'--fr\x01ames' 2

# --help prints the usage on stdout, exit 0.
if "$tw" walk --help >"$tmp/out" 2>"$tmp/err" && grep -q '^usage: tileworld walk' "$tmp/out" &&
   [ ! -s "$tmp/err" ]; then ok; else bad "walk --help"; fi
if "$tw" --help >"$tmp/out" && grep -q -- '--opt=VALUE' "$tmp/out"; then ok; else bad "--help"; fi
# Every option of the tables is in the usage.
src=$(dirname "$0")/..
options=$(sed -n 's/^ *{"\([a-z-]*\)", \(no\|required\)_argument.*/\1/p' \
    "$src/tools/cli.h" "$src/tools/tileworld/tileworld.c")
[ "$(wc -w <<<"$options")" -ge 25 ] && ok || bad "found only $(wc -w <<<"$options") options in the tables"
for o in $options; do
    grep -q -- "--$o\b" "$tmp/out" && ok || bad "tileworld --help does not list --$o"
done
grep -q -- '--mutate-query-shrink F  testing only' "$tmp/out" && ok || bad "--help: --mutate-query-shrink not marked testing only"

# --opt=value is applied as --opt value is.
if "$tw" walk --size=96x54 --frames=3 --png-every=0 --quiet --method=vfc "${full[@]}" --out="$tmp/eq" 2>"$tmp/err" &&
   [ "$(wc -l <"$tmp/eq/frames.csv")" -eq 4 ] && grep -q '"size": "96x54"' "$tmp/eq/summary.json" &&
   [ "$(tail -n +2 "$tmp/eq/frames.csv" | cut -d, -f2 | sort -u)" = vfc ]; then ok; else
    bad "walk with --opt=value: $(cat "$tmp/err")"; fi

# --fps paces the frames: 24 frames at 8 a second take at least 2.875 s
# (23 intervals), whatever a frame costs (unpaced, this walk takes about
# 0.3 s here).
t0=$(date +%s.%N)
"$tw" walk --size 64x36 --frames 24 --fps 8 --max-screen-error 0 --png-every 0 --quiet \
    --out "$tmp/fps" >/dev/null 2>"$tmp/err" &&
    awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { exit !(b - a >= 2.875) }' && ok ||
    bad "walk --fps 8: 24 frames did not take 2.875 s or more: $(cat "$tmp/err")"

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
if "$tw" walk --path "$tmp/good.csv" --size 96x54 --png-every 0 --quiet "${full[@]}" --out "$tmp/csv" 2>"$tmp/err" &&
   [ "$(wc -l <"$tmp/csv/frames.csv")" -eq 4 ]; then ok; else bad "walk over a CSV path: $(cat "$tmp/err")"; fi

# A walk writes frames.csv (header + one row per frame), summary.json, PNGs.
if "$tw" walk --tileset city --path street --frames 5 --method vfc --size 160x90 --png-every 2 \
      --quiet --out "$tmp/walk" 2>"$tmp/err"; then
    [ "$(wc -l <"$tmp/walk/frames.csv")" -eq 6 ] && ok || bad "frames.csv row count"
    head -1 "$tmp/walk/frames.csv" | grep -q '^frame,method,ms_frame,ms_cull,ms_wait,triangles,clusters,draws,queries,tiles_queried,tiles_visible,tiles_new,tiles_cached,cache_bytes,predict_fail,missed_pixels,missed_clusters,overdraw_triangles,cpu_ms,depth_errors,tiles_pending,loads_requested,loads_done,evictions,bytes_cpu,bytes_gpu,bytes_state,bytes_needed,over_budget,ms_upload,blocking_reads,queries_skipped,hzb_boxes,ms_hzb_build,ms_hzb_read,bytes_loading,tiles_loading,set_cpu_ms,set_ms,set_triangles,set_draws,overdraw_box_triangles,gpu_ms,gpu_ms_id,waits,flushes,bytes_read_back,tiles_late,hzb_lag,lod_pixels,lod_pixels_exact,lod_depth_m,objects,object_cells,object_rebuilds,ms_objects$' \
        && ok || bad "frames.csv header"
    for key in '"methods"' '"vfc"' '"mean_ms"' '"median_ms"' '"p95_ms"' '"p99_ms"' '"mean_triangles"' \
               '"mean_queries"' '"missed_pixels_total"' '"frames_with_missed_pixels"' \
               '"tiles_new_total"' '"peak_instance_bytes"' '"peak_tile_cache_bytes"' '"predict_fail_rate"' '"tileset"' '"path"' \
               '"size"' '"seed"' '"mean_cpu_ms"' '"median_cpu_ms"' '"p99_cpu_ms"' \
               '"depth_errors_total"' '"frames_with_depth_errors"' '"deterministic": false' \
               '"mean_gpu_ms": [0-9]' '"median_gpu_ms": [0-9]' '"gpu_frames_unknown": 0' \
               '"run": {' '"context": "[a-z-]' '"gl_vendor": "' '"gl_renderer": "' '"gl_version": "' \
               '"software": ' '"build_type": "[a-z]' '"commit": "[0-9a-z]'; do
        grep -q "$key" "$tmp/walk/summary.json" && ok || bad "summary.json lacks $key"
    done
    # Each frame was finished, so its GPU time came back; no ID pass without --verify.
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
        !($c["gpu_ms"] >= 0 && $c["gpu_ms_id"] == 0) { exit 1 }' "$tmp/walk/frames.csv" && ok ||
        bad "frames.csv: a frame without its GPU time"
    [ -s "$tmp/walk/frame-00000.png" ] && [ -s "$tmp/walk/frame-00004.png" ] && ok || bad "PNG snapshots"
    [ ! -e "$tmp/walk/frame-00001.png" ] && ok || bad "--png-every 2 wrote frame 1"
    awk -F, 'NR > 1 && ($6 <= 0 || $11 <= 0) { exit 1 }' "$tmp/walk/frames.csv" && ok || bad "frames draw nothing"
else
    bad "walk failed: $(cat "$tmp/err")"
fi

# Far from the origin: the same PNG files, byte for byte (DESIGN §3).
common=(walk --tileset city --path street --frames 12 --method vfc --size 160x90 --png-every 4 --repeat 4 --quiet
        "${full[@]}")
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

# The accuracy options reach the run and its summaries (the mutation misses
# pixels: --allow-missed keeps the exit status 0).
if "$tw" bench --methods vfc,chc --frames 3 --size 96x54 --verify --verify-tolerance 0.001 "${full[@]}" \
      --deterministic --mutate-query-shrink 0.25 --allow-missed --png-every 0 --quiet --out "$tmp/acc" \
      >"$tmp/out" 2>"$tmp/err"; then
    grep -q '"verify_tolerance": 0.001,' "$tmp/acc/summary.json" && ok || bad "summary.json: verify_tolerance"
    grep -q '"deterministic": true' "$tmp/acc/summary.json" && ok || bad "summary.json: deterministic"
    grep -q '"mutate_query_shrink": 0.25' "$tmp/acc/summary.json" && ok || bad "summary.json: mutate_query_shrink"
    grep -q 'Testing only: every query box shrunk by 0.25' "$tmp/acc/summary.md" && ok || bad "summary.md: mutation"
    grep -q 'CPU / vfc' "$tmp/acc/summary.md" && grep -q 'CPU / oracle' "$tmp/acc/summary.md" && ok ||
        bad "summary.md: CPU-time ratios"
    grep -q '| mean CPU ms | p99 CPU ms | mean GPU ms |' "$tmp/acc/summary.md" && ok ||
        bad "summary.md: no GPU time column"
    grep -Eq '^Ran on .+ \(.+, GL .+\) through [a-z-]+; [a-z]+ build of [0-9a-z-]+; tileset city, path street, 96x54, 3 frames, seed 1\.$' "$tmp/acc/summary.md" &&
        ok || bad "summary.md: no line saying what ran"
    # --verify times the ID pass apart from the frame.
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
        !($c["gpu_ms"] >= 0 && $c["gpu_ms_id"] > 0) { exit 1 }' "$tmp/acc/frames.csv" && ok ||
        bad "frames.csv: a verified frame without its ID pass's GPU time"
else
    bad "bench with the accuracy options: $(cat "$tmp/err")"
fi

# --split draws each frame's set again: the same triangles, counted apart,
# and each method's CPU time parted in summary.md and summary.json.
expect_usage_error walk --split "${small[@]}"
expect_usage_error bench --split --scenario spin "${small[@]}"
expect_usage_error bench --split --sweep n_av=1,2 "${small[@]}"
if "$tw" bench --methods chc,tilequery+chc,oracle --frames 3 --size 96x54 --split --png-every 0 "${full[@]}" \
      --quiet --out "$tmp/split" 2>"$tmp/err"; then
    rows=$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) c[$i] = i; next }
        { n++; if ($c["set_triangles"] == $c["triangles"] && $c["set_triangles"] > 0 &&
                   $c["set_draws"] <= $c["draws"] && $c["set_cpu_ms"] > 0) same++ }
        END { print same + 0 "/" n + 0 }' "$tmp/split/frames.csv")
    [ "$rows" = 9/9 ] && ok || bad "--split: $rows rows redrew the frame's triangles in no more draws"
    for m in chc tilequery+chc oracle; do
        grep -Fq "| $m | " <(sed -n '/Where the CPU time goes/,$p' "$tmp/split/summary.md") && ok ||
            bad "summary.md: no --split row for $m"
    done
    [ "$(grep -c '"mean_finding_cpu_ms"' "$tmp/split/summary.json")" -eq 3 ] && ok ||
        bad "summary.json: no set figures per method"
else
    bad "bench --split: $(cat "$tmp/err")"
fi
"$tw" bench --methods chc --frames 2 --size 96x54 --png-every 0 --quiet "${full[@]}" --out "$tmp/nosplit" 2>"$tmp/err" &&
    ! grep -q 'Where the CPU time goes' "$tmp/nosplit/summary.md" &&
    [ "$(awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "set_triangles") k = i; next } { s += $k } END { print s + 0 }' "$tmp/nosplit/frames.csv")" = 0 ] &&
    ok || bad "a bench without --split reports a split"

# --scenario honours --frames and --size; a check that does not hold is exit
# status 3: with every query box shrunk, the missed-pixel checks fail (at
# full detail: at 96x54 and 1 px the tiles are drawn at levels of a few large
# clusters, whose fringe a shrunk query seldom hides).
scen=(bench --scenario spin --frames 6 --size 96x54 --methods chc,tilequery+chc --deterministic
      --max-screen-error 0 --png-every 0 --quiet)
"$tw" "${scen[@]}" --mutate-query-shrink 0.1 --out "$tmp/scen-broken" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 3 ] && ok || bad "scenario with shrunk query boxes exited $rc (expected 3): $(cat "$tmp/err")"
for m in chc tilequery+chc; do
    grep -Fq "| spin | temporal coherence | $m: no missed pixels, no depth errors |" "$tmp/scen-broken/scenarios.md" &&
        grep -F "| $m: no missed pixels" "$tmp/scen-broken/scenarios.md" | grep -q '| \*\*no\*\* |$' && ok ||
        bad "scenarios.md: $m's missed pixels held under the mutation"
done
grep -Eq '"all_held": ?false' "$tmp/scen-broken/scenarios.json" && ok || bad "scenarios.json: all_held"
grep -q 'Testing only' "$tmp/scen-broken/scenarios.md" && ok || bad "scenarios.md: mutation not said"
# The same without the mutation: the missed-pixel checks hold (the timing
# checks are not this test's business).
"$tw" "${scen[@]}" --out "$tmp/scen" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] || [ "$rc" -eq 3 ] && ok || bad "scenario exited $rc: $(cat "$tmp/err")"
for m in chc tilequery+chc; do
    grep -F "| $m: no missed pixels" "$tmp/scen/scenarios.md" | grep -q '| yes |$' && ok ||
        bad "scenarios.md: $m missed pixels without the mutation: $(grep -F "| $m: no missed" "$tmp/scen/scenarios.md")"
done
grep -q '^Frames per scenario (--frames): spin 6\.$' "$tmp/scen/scenarios.md" && ok ||
    bad "scenarios.md: frames header: $(grep '^Frames' "$tmp/scen/scenarios.md")"
[ "$(tail -n +2 "$tmp/scen/scenario-spin/frames.csv" | wc -l)" -eq 12 ] && ok || bad "scenario ran other than 6 frames x 2 methods"
grep -q '"size": "96x54"' "$tmp/scen/scenario-spin/summary.json" && ok || bad "scenario ignored --size"

# info prints a row per prototype and the common box.
if "$tw" info --tileset city >"$tmp/info" 2>"$tmp/err"; then
    grep -q '^tile ' "$tmp/info" && grep -q '^common box:' "$tmp/info" && ok || bad "info output"
    rows=$(awk '/^tile /{on=1; next} /^total:/{on=0} on' "$tmp/info" | wc -l)
    [ "$rows" -ge 8 ] && ok || bad "info lists $rows prototypes"
else
    bad "info failed: $(cat "$tmp/err")"
fi

# info --calibrate prints the cost model measured in a world at --size:
# a query and a draw that cost something, a query dearer than a draw.
if "$tw" info --tileset city --calibrate --size 96x54 "${full[@]}" >"$tmp/cal" 2>"$tmp/err"; then
    awk '/^cost model at 96x54 \(measured/ {m=1} $1 == "query" && $2 > 0 {q=$2}
         $1 == "draw" && $3 > 0 {d=$3} END {exit !(m && q > 0 && d > 0 && q > d)}' "$tmp/cal" &&
        ok || bad "info --calibrate output: $(cat "$tmp/cal")"
else
    bad "info --calibrate failed: $(cat "$tmp/err")"
fi

# ---- providers and the streaming options -----------------------------
for a in "--budget 12X" "--budget -1" "--budget 1.5M" "--budget ''" "--budget 99999999999999999999" \
         "--budget 2000000T" "--budget 64m5" "--policy nope" "--policy" "--workers 0" "--workers 65" \
         "--workers x" "--upload-budget 0"; do
    eval "expect_usage_error walk $a \"\${small[@]}\""
done
# A world the library refuses for the user's settings: its one line, exit 2.
expect_usage_error walk --view-distance 100000 "${small[@]}"
"$tw" walk --view-distance 100000 "${small[@]}" 2>"$tmp/err"
grep -q 'view distance of 100000 m' "$tmp/err" && ok || bad "--view-distance 100000: $(cat "$tmp/err")"
expect_usage_error bench --tileset city-gen --scenario spin "${small[@]}"
expect_usage_error bench --tileset city-gen --sweep cluster_triangles=512,1024 "${small[@]}"
# city-gen walks, with a budget, workers and either policy; frames.csv has
# the streaming columns.
for pol in wait skip; do
    if "$tw" walk --tileset city-gen --frames 4 --size 96x54 --png-every 0 --quiet --budget 64M \
          --workers 2 --policy $pol --upload-budget 8M --out "$tmp/gen-$pol" 2>"$tmp/err" &&
       [ "$(wc -l <"$tmp/gen-$pol/frames.csv")" -eq 5 ] && [ ! -s "$tmp/err" ]; then ok; else
        bad "city-gen walk under $pol: $(cat "$tmp/err")"; fi
done
# The oracle and --verify over generated tiles (the oracle sorts each tile's
# clusters by the tile's own content, not a shared tileset's): 0 missed.
if "$tw" bench --tileset city-gen --frames 3 --size 96x54 --png-every 0 --quiet --verify \
       --methods tilequery+chc,oracle,hzb --out "$tmp/gen-verify" 2>"$tmp/err" &&
   [ "$(awk -F, 'NR == 1 {for (i = 1; i <= NF; i++) if ($i == "missed_pixels") c = i; next}
                 {s += $c} END {print s + 0}' "$tmp/gen-verify/frames.csv")" = 0 ] &&
   [ "$(wc -l <"$tmp/gen-verify/frames.csv")" -eq 10 ]; then ok; else
    bad "bench --verify over city-gen: $(cat "$tmp/err")"; fi
# --views 2: a chase camera as a second view of the same world, every method
# that has a frame of its own; said in the verdict and summary.json, and
# the out-of-range counts refused.
if "$tw" bench --tileset city-gen --frames 3 --size 96x54 --png-every 0 --quiet --views 2 \
       --methods vfc,tilequery+chc,hzb,oracle --out "$tmp/views2" >"$tmp/out" 2>"$tmp/err" &&
   grep -q 'and a chase camera as a second view' "$tmp/out" &&
   grep -Eq '"views": *2' "$tmp/views2/summary.json" &&
   [ "$(wc -l <"$tmp/views2/frames.csv")" -eq 13 ]; then ok; else
    bad "bench --views 2: $(cat "$tmp/out" "$tmp/err")"; fi
expect_usage_error walk --views 3 "${small[@]}"
expect_usage_error walk --views 0 "${small[@]}"
# --cars N: moving cars on the city's streets. Every method misses no pixel
# with them under --verify (the ID pass draws them too); every frame has
# them all, some moved into other cells; said in the verdict, summary.md and
# summary.json.
if "$tw" bench --tileset city-gen --cars 300 --frames 4 --size 96x54 --png-every 0 --quiet \
       --verify --methods chc,tilequery+chc,hzb,box-oracle --out "$tmp/cars" >"$tmp/out" \
       2>"$tmp/err" &&
   grep -q 'tileset city-gen, 300 moving cars, path street' "$tmp/out" &&
   grep -q 'with 300 moving cars' "$tmp/cars/summary.md" &&
   grep -Eq '"cars": *300' "$tmp/cars/summary.json" &&
   grep -Eq '"mean_ms_objects": *[0-9.]+' "$tmp/cars/summary.json" &&
   awk -F, 'NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k; next }
            $col["missed_pixels"] != 0 || $col["objects"] != 300 || $col["object_cells"] < 50 { exit 1 }
            { rebuilt += $col["object_rebuilds"] } END { exit NR == 17 && rebuilt > 0 ? 0 : 1 }' \
       "$tmp/cars/frames.csv"; then ok; else
    bad "bench --cars 300 --verify: $(cat "$tmp/out" "$tmp/err"; tail -3 "$tmp/cars/frames.csv")"; fi
# The cars are drawn, and where they are is a function of the frame: the
# same images twice, other images than without cars.
for run in a b none; do
    n=$([ $run = none ] && echo 0 || echo 2000)
    "$tw" walk --cars $n --frames 3 --size 160x90 --png-every 1 --quiet "${full[@]}" --out "$tmp/cars-$run" \
        >/dev/null 2>"$tmp/err" || bad "walk --cars $n: $(cat "$tmp/err")"
done
same=0 other=0
for f in 00000 00001 00002; do
    cmp -s "$tmp/cars-a/frame-$f.png" "$tmp/cars-b/frame-$f.png" && same=$((same + 1))
    cmp -s "$tmp/cars-a/frame-$f.png" "$tmp/cars-none/frame-$f.png" || other=$((other + 1))
done
[ $same = 3 ] && [ $other -gt 0 ] && ok || bad "walk --cars 2000: $same of 3 images the same twice, $other other than without cars"
# They move: after the first frame, cars crossing into other cells rebuild
# those cells' objects.
awk -F, 'NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k; next }
         $col["objects"] != 2000 { exit 1 }
         $col["frame"] > 1 { rebuilt += $col["object_rebuilds"] } END { exit rebuilt > 0 ? 0 : 1 }' \
    "$tmp/cars-a/frames.csv" && ok || bad "walk --cars 2000: no car moved: $(cat "$tmp/cars-a/frames.csv")"
# A sweep of the number of cars: one row per method and value.
if "$tw" bench --sweep cars=0,200 --methods vfc,tilequery+chc --frames 2 --size 96x54 "${full[@]}" \
       --png-every 0 --quiet --out "$tmp/cars-sweep" >/dev/null 2>"$tmp/err" &&
   [ "$(grep -c ',cars,200,' "$tmp/cars-sweep/sweep.csv")" = 2 ] &&
   grep -Eq '"cars": *200' "$tmp/cars-sweep/sweep-cars-200/summary.json"; then ok; else
    bad "bench --sweep cars=0,200: $(cat "$tmp/err")"; fi
expect_usage_error walk --cars 10 --tileset forest "${small[@]}"
expect_usage_error walk --cars 10 --tileset forest-gen "${small[@]}"
expect_usage_error walk --cars 100001 "${small[@]}"
expect_usage_error walk --cars -1 "${small[@]}"
expect_usage_error walk --cars 10 --hlod-levels 2 "${small[@]}"
expect_usage_error bench --cars 10 --scenario spin "${small[@]}"
expect_usage_error bench --sweep cars=0,10 --tileset forest "${small[@]}"
expect_usage_error bench --sweep cars=0,100001 "${small[@]}"
expect_usage_error info --cars 10
awk -F, 'NR == 1 { for (k = 1; k <= NF; k++) col[$k] = k; next }
         $col["bytes_cpu"] <= 0 || $col["bytes_gpu"] <= 0 || $col["bytes_needed"] <= 0 { exit 1 }
         { loads += $col["loads_done"] } END { exit loads > 0 ? 0 : 1 }' "$tmp/gen-wait/frames.csv" &&
    ok || bad "city-gen frames.csv: no bytes or no loads: $(head -3 "$tmp/gen-wait/frames.csv")"
if "$tw" info --tileset city-gen >"$tmp/info" 2>"$tmp/err" && grep -q '^provider city-gen: footprint 80 x 80 m' "$tmp/info" &&
   grep -q '^bound (the query box): ' "$tmp/info"; then ok; else bad "info city-gen: $(cat "$tmp/info" "$tmp/err")"; fi
if "$tw" bench --tileset forest-gen --methods vfc,tilequery+chc --frames 2 --size 96x54 --png-every 0 \
      --quiet --path forest --out "$tmp/forest-gen" 2>"$tmp/err" >/dev/null; then ok; else
    bad "bench forest-gen: $(cat "$tmp/err")"; fi

# ---- output that never lies ----------------------------------------------------
# expect_write_error NAME PATTERN CMD...: exit status 1 and exactly one
# stderr line matching the extended regex PATTERN.
expect_write_error() {
    local name=$1 pattern=$2
    shift 2
    "$@" 2>"$tmp/err"
    local rc=$?
    if [ "$rc" -eq 1 ] && [ "$(wc -l <"$tmp/err")" -eq 1 ] && grep -Eq -- "$pattern" "$tmp/err"; then
        ok
    else
        bad "$name: exit $rc, stderr: $(cat "$tmp/err")"
    fi
}
# limited BLOCKS CMD...: CMD with files limited to BLOCKS kB; SIGXFSZ is
# ignored, so that a write past the limit fails with EFBIG.
limited() { ( trap '' XFSZ; ulimit -f "$1"; shift; exec "$@" ); }

# no_temporaries DIR: no .NAME.tmp left.
no_temporaries() { [ -z "$(ls -A "$1" | grep '\.tmp$')" ] && ok || bad "temporaries left in $1: $(ls -A "$1")"; }

# A run removes what an earlier one left, and only that: a failed run
# leaves no stale summary.json beside nothing. A full disk is an output
# file size limit here (ulimit -f, with SIGXFSZ ignored so that write fails
# with EFBIG): deterministic and needs no root.
out="$tmp/never"
if "$tw" walk --frames 30 --size 96x54 --png-every 10 --quiet --out "$out" 2>"$tmp/err"; then ok; else
    bad "walk into $out: $(cat "$tmp/err")"; fi
echo mine >"$out/notes.txt"
echo mine >"$out/frame-1.png"
mkdir -p "$out/chart-data" && echo mine >"$out/chart-data/mine.txt"
: >"$out/chart-sweep.png"            # an earlier bench's, to be removed
expect_write_error "write error" "^tileworld: $out/frames.csv: cannot write: File too large$" \
    limited 2 "$tw" walk --frames 40 --size 96x54 --png-every 0 --quiet "${full[@]}" --out "$out"
for f in frames.csv summary.json frame-00000.png frame-00010.png chart-sweep.png; do
    [ ! -e "$out/$f" ] && ok || bad "a failed run left $f"
done
no_temporaries "$out"
[ -f "$out/notes.txt" ] && [ -f "$out/frame-1.png" ] && [ -f "$out/chart-data/mine.txt" ] && ok ||
    bad "a run removed files it did not write: $(ls -A "$out")"

# A PNG that cannot be written stops the run at once, naming the PNG.
expect_write_error "PNG write error" "^tileworld: $out/frame-0000[0-2].png: cannot write: File too large$" \
    limited 8 "$tw" walk --frames 3 --size 640x360 --png-every 1 --quiet "${full[@]}" --out "$out"
no_temporaries "$out"

# A real full disk, where a small tmpfs can be mounted (as root; else skipped).
if [ "$(id -u)" -eq 0 ] && mkdir -p "$tmp/small" &&
   mount -t tmpfs -o size=64k tmpfs "$tmp/small" 2>/dev/null; then
    expect_write_error "full disk" ": cannot write: No space left on device$" \
        "$tw" walk --frames 20 --size 160x90 --png-every 1 --quiet "${full[@]}" --out "$tmp/small/run"
    [ ! -e "$tmp/small/run/frames.csv" ] && [ ! -e "$tmp/small/run/summary.json" ] && ok ||
        bad "full disk: summaries left"
    for f in "$tmp"/small/run/frame-*.png; do
        [ -e "$f" ] || continue
        cmp -s <(head -c 8 "$f") <(printf '\211PNG\r\n\032\n') && ok || bad "full disk: $f is not whole"
    done
    no_temporaries "$tmp/small/run"
    umount "$tmp/small"
else
    echo "skip: no tmpfs to fill (not root, or mount refused)"
fi

# A killed run leaves no file under a final name that it had not finished:
# no frames.csv, no summary.json; only its hidden temporary, which the next
# run removes.
killed="$tmp/killed"
"$tw" walk --frames 100000 --size 96x54 --png-every 0 --quiet "${full[@]}" --out "$killed" 2>/dev/null &
pid=$!
for _ in $(seq 1 600); do
    [ -s "$killed/.frames.csv.tmp" ] && break
    sleep 0.1
done
kill -KILL "$pid" 2>/dev/null
wait "$pid" 2>/dev/null
if [ -s "$killed/.frames.csv.tmp" ] && [ ! -e "$killed/frames.csv" ] && [ ! -e "$killed/summary.json" ]; then
    ok; else bad "after a kill: $(ls -A "$killed" 2>&1)"; fi
if "$tw" walk --frames 2 --size 96x54 --png-every 0 --quiet "${full[@]}" --out "$killed" 2>"$tmp/err" &&
   [ "$(wc -l <"$killed/frames.csv")" -eq 3 ] && [ -f "$killed/summary.json" ]; then ok; else
    bad "walk after a kill: $(cat "$tmp/err")"; fi
no_temporaries "$killed"

# The output folder cannot be made: bad input, exit 2, one line.
: >"$tmp/a-file"
expect_usage_error walk "${small[@]}" --out "$tmp/a-file/sub"

finish
