#!/usr/bin/env bash
# tileworld memtest, slow suite: 10 km of city-gen at a tiny size
# under a small budget (48M: more than most frames draw, less than the walk
# would prefetch); exit status 0 (every check held) and every check in
# summary.json with its verdict. malloc keeps glibc's own settings; a
# tile's packed blocks of 64 KiB or more are the library's own mappings.
# Measured so, one run: RSS +0.1 % (last 10 % against 40-50 % of the
# distance; the bound is 5 %), rising over the first 2 km while the cache
# fills and the heap settles, flat after.
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
