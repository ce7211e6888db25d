#!/usr/bin/env bash
# tileworld memtest (issue 14), slow suite: 2.5 km of city-gen at memtest's
# default size (the one its latency bound is stated for) under a small
# budget; exit status 0 (every check held) and every check in summary.json
# with its verdict. Known to fail today on "RSS flat": the process's RSS
# grows by 15-20 % over the first kilometres of tile churn before it levels
# off (about 7 km into a 20 km walk); see the README's known limits.
set -u
tw=${1:?usage: test-memtest-slow.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

if "$tw" memtest --tileset city-gen --distance 2.5 --budget 48M --quiet \
       --out "$tmp/m" >"$tmp/out" 2>"$tmp/err"; then ok; else
    bad "memtest exited $?: $(cat "$tmp/err") $(cat "$tmp/m/summary.md" 2>/dev/null)"; fi
for what in 'cache bytes <= the budget' 'RSS flat' 'no leak' 'load latency p99'; do
    grep -A2 "\"must_hold\": \"$what" "$tmp/m/summary.json" | grep -q '"held": "yes"' && ok ||
        bad "summary.json: '$what' not held: $(grep -A2 "$what" "$tmp/m/summary.json")"
done
grep -Eq '"all_held": ?true' "$tmp/m/summary.json" && ok || bad "all_held"
finish test-memtest-slow
