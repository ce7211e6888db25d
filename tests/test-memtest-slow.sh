#!/usr/bin/env bash
# tileworld memtest (issue 14), slow suite: 10 km of city-gen at a tiny size
# under a small budget; exit status 0 (every check held) and every check in
# summary.json with its verdict. Known to fail today on "RSS flat" (+6.8 % on
# this walk): the process's RSS follows the high-water mark of malloc's heap,
# which keeps rising, by about 5 % over the first 2 km and 2-3 % over the next
# 18, while the heap in use (memory.csv's heap_used_bytes) has no trend; see
# the README's known limits.
set -u
tw=${1:?usage: test-memtest-slow.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

if "$tw" memtest --tileset city-gen --distance 10 --size 96x54 --budget 48M --quiet \
       --out "$tmp/m" >"$tmp/out" 2>"$tmp/err"; then ok; else
    bad "memtest exited $?: $(cat "$tmp/err") $(cat "$tmp/m/summary.md" 2>/dev/null)"; fi
for what in 'cache bytes <= the budget' 'RSS flat' 'no leak' 'load latency p99'; do
    grep -A2 "\"must_hold\": \"$what" "$tmp/m/summary.json" | grep -q '"held": "yes"' && ok ||
        bad "summary.json: '$what' not held: $(grep -A2 "$what" "$tmp/m/summary.json")"
done
grep -Eq '"all_held": ?true' "$tmp/m/summary.json" && ok || bad "all_held"
finish test-memtest-slow
