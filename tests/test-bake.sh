#!/usr/bin/env bash
# tileworld bake: 4 x 3 cells of city and of city-gen into a temporary
# folder, checked by bake-check against the library (tileset.json's implicit
# tiling, every .glb read back by the project's importer with its cell's
# triangles, the root subtree's bits); a rerun rewrites nothing; shards 0/2
# and 1/2 then --finish give the same files, byte for byte; bad input is one
# line and exit status 2.
# Usage: test-bake.sh TILEWORLD BAKE-CHECK
set -u
tw=${1:?usage: test-bake.sh PATH/TO/tileworld PATH/TO/bake-check}
check=${2:?usage: test-bake.sh PATH/TO/tileworld PATH/TO/bake-check}
. "$(dirname "$0")/test-lib.sh"

expect_usage_error() {
    "$tw" bake "$@" >"$tmp/out" 2>"$tmp/err"
    local rc=$?
    if [ "$rc" -ne 2 ] || [ "$(wc -l <"$tmp/err")" -ne 1 ] || ! grep -q '^tileworld: ' "$tmp/err"; then
        bad "bake $* exited $rc with: $(head -c 300 "$tmp/err")"
    else
        ok
    fi
}
expect_usage_error --cells 0,0 --out "$tmp/bad"
expect_usage_error --cells 0,0:3 --out "$tmp/bad"
expect_usage_error --cells a,0:3,3 --out "$tmp/bad"
expect_usage_error --cells 0,0:3,3:4,4 --out "$tmp/bad"
expect_usage_error --cells 3,0:0,3 --out "$tmp/bad"
expect_usage_error --cells 0,3:3,0 --out "$tmp/bad"
expect_usage_error --cells 0,0:1023,1024 --out "$tmp/bad"
expect_usage_error --cells 0,0:9,9 --max-cells 99 --out "$tmp/bad"
expect_usage_error --cells 0,0:3,3
expect_usage_error --out "$tmp/bad"
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --tileset nope
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --shard 2/2
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --shard 1
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --shard 0/2 --finish
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --frames 10
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --levels 0
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --levels 9
: >"$tmp/file"
expect_usage_error --cells 0,0:3,3 --out "$tmp/file/sub"
[ -e "$tmp/bad" ] && bad "a refused bake made its folder" || ok

"$tw" bake --help >"$tmp/help" && grep -q '^usage: tileworld bake ' "$tmp/help" && ok ||
    bad "bake --help"

for world in city city-gen; do
    out=$tmp/$world
    if "$tw" bake --tileset "$world" --cells -2,5:1,7 --out "$out" --workers 2 2>"$tmp/err"; then
        ok
    else
        bad "bake $world failed: $(head -c 300 "$tmp/err")"
        continue
    fi
    grep -q "12 written" "$tmp/err" && ok || bad "bake $world: $(cat "$tmp/err")"
    [ "$(find "$out/content" -name '*.glb' | wc -l)" -eq 12 ] && ok || bad "$world: not 12 .glb"
    "$check" "$out" && ok || bad "bake-check $world"
    find "$out" -name '*.tmp*' | grep -q . && bad "$world: temporaries left" || ok

    # A rerun skips every cell: no file rewritten.
    find "$out/content" -type f -printf '%p %T@\n' | sort >"$tmp/mtimes-before"
    "$tw" bake --tileset "$world" --cells -2,5:1,7 --out "$out" --workers 2 2>"$tmp/err" && ok ||
        bad "rerun of $world: $(cat "$tmp/err")"
    grep -q "12 already there" "$tmp/err" && ok || bad "rerun of $world: $(cat "$tmp/err")"
    find "$out/content" -type f -printf '%p %T@\n' | sort >"$tmp/mtimes-after"
    cmp -s "$tmp/mtimes-before" "$tmp/mtimes-after" && ok || bad "rerun of $world rewrote cells"

    # Other settings into the same folder are refused.
    expect_usage_error --tileset "$world" --cells -2,5:2,7 --out "$out"

    # Two shards and --finish: the same files, byte for byte.
    sharded=$tmp/$world-sharded
    "$tw" bake --tileset "$world" --cells -2,5:1,7 --out "$sharded" --shard 1/2 --quiet &&
        "$tw" bake --tileset "$world" --cells -2,5:1,7 --out "$sharded" --shard 0/2 --quiet &&
        ok || bad "shards of $world"
    [ -e "$sharded/tileset.json" ] && bad "a shard wrote tileset.json" || ok
    [ "$(find "$sharded/content" -name '*.glb' | wc -l)" -eq 12 ] && ok ||
        bad "$world: the shards made not 12 .glb"
    "$tw" bake --tileset "$world" --cells -2,5:1,7 --out "$sharded" --finish --quiet 2>"$tmp/err" &&
        ok || bad "--finish of $world: $(cat "$tmp/err")"
    diff -r "$out" "$sharded" >"$tmp/diff" && ok || bad "shards of $world differ: $(head -c 300 "$tmp/diff")"
done

# A cell removed, then --finish: the subtree says so.
rm "$tmp/city/content/2/1/1.glb"
"$tw" bake --tileset city --cells -2,5:1,7 --out "$tmp/city" --finish --quiet && ok || bad "--finish"
"$check" "$tmp/city" partial && ok || bad "bake-check after a cell was removed"
# Coarser levels: every level with content, each tile simplified from its
# children; shards then --finish make them too, the same bytes.
"$tw" bake --tileset city --cells -2,5:1,7 --levels 3 --out "$tmp/levels" --quiet &&
    "$check" "$tmp/levels" && ok || bad "--levels 3"
[ "$(find "$tmp/levels/content/0" "$tmp/levels/content/1" -name '*.glb' | wc -l)" -eq 5 ] && ok ||
    bad "--levels 3: not 1 + 4 coarser tiles"
grep -q '"geometricError"' "$tmp/levels/content/0/0/0.glb" && ok || bad "--levels 3: no error"
"$tw" bake --tileset city --cells -2,5:1,7 --levels 3 --out "$tmp/levels-sharded" --shard 0/1 \
    --quiet && [ ! -e "$tmp/levels-sharded/content/0" ] && ok || bad "a shard made coarser levels"
# (--finish of a folder baked without --levels adds them.)
"$tw" bake --tileset city --cells -2,5:1,7 --out "$tmp/levels-sharded" --finish --quiet && ok ||
    bad "--finish without --levels"
"$tw" bake --tileset city --cells -2,5:1,7 --levels 3 --out "$tmp/levels-sharded" --finish --quiet &&
    diff -r "$tmp/levels" "$tmp/levels-sharded" >"$tmp/diff" && ok ||
    bad "--levels 3 by shards differs: $(head -c 300 "$tmp/diff")"
expect_usage_error --cells 0,0:3,3 --out "$tmp/bad" --levels 4
# A prototype tileset's blocks above the 2x2 ones come from the cells' own
# coarser levels: on these 4 x 4 cells the 4x4 block merged from its
# children's files kept all they had (3 074 064 bytes against 3 075 464),
# from the cells' levels it holds 0.38 of them.
"$tw" bake --tileset city --cells 0,0:3,3 --levels 3 --out "$tmp/blocks" --quiet &&
    "$check" "$tmp/blocks" && ok || bad "--levels 3 over 0,0:3,3"
bytes_of() { find "$1" -name '*.glb' -printf '%s\n' | awk '{ s += $1 } END { print s + 0 }'; }
b0=$(bytes_of "$tmp/blocks/content/0") b1=$(bytes_of "$tmp/blocks/content/1")
[ "$b1" -gt 0 ] && [ $((10 * b0)) -le $((6 * b1)) ] && ok ||
    bad "the 4x4 block holds $b0 bytes against its 2x2 blocks' $b1: not made from the cells' levels"
# One cell: a quadtree of one level.
"$tw" bake --tileset forest --cells 7,7:7,7 --out "$tmp/one" --quiet && "$check" "$tmp/one" &&
    ok || bad "one cell"
finish bake
