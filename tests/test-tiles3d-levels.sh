#!/usr/bin/env bash
# A bake's coarser levels streamed back: far cells drawn as the bake's
# blocks (README "Hierarchical cells", "Beyond one machine"):
#   - `bake --levels 3` of 8 x 8 hybrid cells (buildings, parks, woods) from
#     0,0 writes the levels' errors into tileset.json
#     (extras.tileworld.levels);
#   - a walk over file:// 440 to 1080 m from the cells, at 16 px, reads
#     blocks of 2x2 and 4x4 cells from the tileset and fewer cells than
#     the same walk with `--hlod-levels 1` (cells only), which reads no
#     block;
#   - under --verify no method misses a pixel with blocks, and the image
#     differs from full detail by no more than 1.5 times (plus 1 % of the
#     image) what the cells' own levels make it differ, its surfaces there
#     no farther from full detail's than 1.5 times theirs: a block is its
#     cells, simplified, in its place;
#   - a bake whose corner is not a multiple of 2 cells has no level the
#     world's blocks can use: a warning, and no block is read;
#   - levels that are not {cells: 2^k, geometricError} are refused with
#     the field named (exit status 2).
# Usage: test-tiles3d-levels.sh TILEWORLD
set -u
tw=$1
. "$(dirname "$0")/test-lib.sh"
fail() { bad "$@"; }
# summary.json's number after "KEY": (the first one).
num() { sed -n "s/.*\"$2\": \\([0-9.eE+-]*\\).*/\\1/p" "$1" | head -1; }

"$tw" bake --tileset hybrid --cells 0,0:7,7 --levels 3 --out "$tmp/baked" --workers 2 --quiet ||
    { echo "FAIL: the bake failed"; exit 1; }
grep -q '"levels":' "$tmp/baked/tileset.json" && ok || fail "tileset.json has no extras.tileworld.levels"

printf 'cell_i,cell_j,x,y,z,yaw,pitch\n' >"$tmp/far.csv"
for z in 20 40 60 80; do echo "-6,4,40,120,$z,90,-8" >>"$tmp/far.csv"; done
url="file://$tmp/baked/tileset.json"
walk=(walk --tileset "$url" --path "$tmp/far.csv" --frames 4 --size 160x90 --view-distance 2000
      --max-screen-error 16 --deterministic --workers 2 --png-every 0)

for run in blocks cells; do
    extra=()
    [ "$run" = cells ] && extra=(--hlod-levels 1)
    "$tw" "${walk[@]}" "${extra[@]}" --out "$tmp/$run" >"$tmp/$run.out" 2>"$tmp/$run.err" && ok ||
        fail "the $run walk fails: $(tail -3 "$tmp/$run.err")"
    "$tw" "${walk[@]}" "${extra[@]}" --verify --out "$tmp/$run-v" >"$tmp/$run-v.out" \
        2>"$tmp/$run-v.err"
    rc=$?
    [ "$rc" = 0 ] && ok || fail "the $run walk under --verify exits $rc: $(tail -3 "$tmp/$run-v.out")"
    grep -q "3D Tiles: .*, 0 failures" "$tmp/$run.err" && ok ||
        fail "the $run walk failed requests: $(grep '3D Tiles' "$tmp/$run.err")"
done
bc=$(num "$tmp/blocks/summary.json" cells)
bb=$(num "$tmp/blocks/summary.json" blocks)
cc=$(num "$tmp/cells/summary.json" cells)
cb=$(num "$tmp/cells/summary.json" blocks)
echo "with blocks: $bc cells and $bb blocks read; cells only: $cc cells and $cb blocks"
[ "${bb:-0}" -gt 0 ] && ok || fail "no block was read: $(grep '3D Tiles' "$tmp/blocks.err")"
[ "${cb:-1}" = 0 ] && ok || fail "--hlod-levels 1 read $cb blocks"
[ -n "$bc" ] && [ -n "$cc" ] && [ "$bc" -lt "$cc" ] && ok ||
    fail "blocks did not spare cells: $bc cells read with them, $cc without"
fb=$(num "$tmp/blocks-v/summary.json" lod_pixel_fraction)
fc=$(num "$tmp/cells-v/summary.json" lod_pixel_fraction)
echo "pixels differing from full detail: $fb with blocks, $fc with cells only"
awk -v b="$fb" -v c="$fc" 'BEGIN { exit !(b != "" && c != "" && b <= 1.5 * c + 0.01) }' && ok ||
    fail "blocks change the image too much: $fb of it differs from full detail ($fc with cells)"
# Where the image differs, how far apart the surfaces are: a block drawn in
# another's place (each block's neighbour, a mutation) makes it 73 m here,
# the cells' own levels 21 m, the blocks 15 m.
db=$(num "$tmp/blocks-v/summary.json" lod_depth_m_mean)
dc=$(num "$tmp/cells-v/summary.json" lod_depth_m_mean)
echo "their surfaces apart: $db m with blocks, $dc m with cells only"
awk -v b="$db" -v c="$dc" 'BEGIN { exit !(b != "" && c != "" && b <= 1.5 * c) }' && ok ||
    fail "blocks' surfaces lie too far from full detail's: $db m against $dc m with cells"

# A corner the world's blocks do not start at.
"$tw" bake --tileset city --cells 1,1:4,4 --levels 2 --out "$tmp/odd" --workers 2 --quiet && ok ||
    fail "the bake at 1,1 failed"
"$tw" "${walk[@]}" --tileset "file://$tmp/odd/tileset.json" --frames 2 --out "$tmp/odd-walk" \
    >/dev/null 2>"$tmp/odd.err" && ok || fail "the walk over the bake at 1,1 fails: $(tail -3 "$tmp/odd.err")"
grep -q "0 of its 1 coarser levels are used: its corner 1,1" "$tmp/odd.err" && ok ||
    fail "no warning for the corner at 1,1: $(grep '3D Tiles' "$tmp/odd.err")"
[ "$(num "$tmp/odd-walk/summary.json" blocks)" = 0 ] && ok || fail "blocks read from the bake at 1,1"

# Malformed levels.
sed 's/"cells":4/"cells":3/' "$tmp/baked/tileset.json" >"$tmp/bad.json"
cp "$tmp/bad.json" "$tmp/baked/bad.json"
"$tw" info --tileset "file://$tmp/baked/bad.json" >/dev/null 2>"$tmp/bad.err"
rc=$?
[ "$rc" = 2 ] && ok || fail "levels of 3 cells exit $rc: $(cat "$tmp/bad.err")"
grep -q "extras.tileworld.levels" "$tmp/bad.err" && ok || fail "the bad field is not named: $(cat "$tmp/bad.err")"

echo "$bb blocks read, $bc cells instead of $cc"
finish tiles3d-levels
