#!/usr/bin/env bash
# tileworld memtest, slow suite: 10 km of city-gen at a tiny size
# under a small budget (48M: more than most frames draw, less than the walk
# would prefetch); exit status 0 (every check held) and every check in
# summary.json with its verdict. Measured with tiles packed (one block each
# for a tile's tileset and BVH): RSS +1.1, -0.5, +1.2 and +0.2 % in four
# runs (last 10 % against the first; the bound is 5 %), about 500 loads of
# which 49-55 reloads, latency p99 2-3 frames.
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
