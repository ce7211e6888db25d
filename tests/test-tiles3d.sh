#!/usr/bin/env bash
# A baked tileset streamed back through the 3D Tiles provider (file://)
# draws what the generating provider draws:
#   - `bake` 6 x 6 cells of city-gen around the street path's start (the
#     corner of cell 0,0), then the same 60 frames walked (--deterministic,
#     view distance 150 m, so every cell in view is in the rectangle) over
#     file:// and over city-gen; the file:// walk under --verify misses no
#     pixel (exit status 0, not 3);
#   - every PNG frame of the two is the same image, pixel for pixel: the
#     bake writes the finished tile as it is drawn (instances with their
#     exact matrices, exact float materials, the merged meshes' own 8-bit
#     colours, the finished triangle order) and the provider rebuilds it
#     one to one, so its tw_tileset_finish() makes the same parts and
#     clusters;
#   - a URL that does not exist, or a scheme that is not supported, is one
#     line and exit status 1 or 2, never a crash.
# Usage: test-tiles3d.sh TILEWORLD PNG_CHECK
set -u
tw=$1
check=$2
. "$(dirname "$0")/test-lib.sh"
fail() { bad "$@"; }

"$tw" bake --tileset city-gen --cells -3,-3:2,2 --out "$tmp/baked" --workers 2 --quiet ||
    { echo "FAIL: the bake failed"; exit 1; }
walk=(walk --frames 60 --view-distance 150 --deterministic --png-every 20 --size 320x180
      --workers 2)
"$tw" "${walk[@]}" --tileset "file://$tmp/baked/tileset.json" --verify --out "$tmp/file" \
    >"$tmp/file.out" 2>"$tmp/file.err"
rc=$?
[ "$rc" = 0 ] || fail "the file:// walk exits $rc: $(tail -3 "$tmp/file.err" "$tmp/file.out")"
grep -q "3D Tiles: .*, 0 failures" "$tmp/file.err" && ok || fail "the file:// walk failed requests: $(grep '3D Tiles' "$tmp/file.err")"
"$tw" "${walk[@]}" --tileset city-gen --out "$tmp/gen" >"$tmp/gen.out" 2>"$tmp/gen.err" && ok ||
    fail "the city-gen walk fails: $(tail -3 "$tmp/gen.err")"
n=0
for f in "$tmp"/gen/frame-*.png; do
    name=${f##*/}
    [ -f "$tmp/file/$name" ] || { fail "the file:// walk wrote no $name"; continue; }
    line=$("$check" "$tmp/file/$name" "$f") || { fail "$name: $line"; continue; }
    echo "$name: $line"
    awk -v l="$line" 'BEGIN { split(l, a, " "); for (k = 1; k < length(a); k++)
        if (a[k] == "pixels_differ") exit !(a[k + 1] == 0); exit 1 }' ||
        fail "$name: the images differ ($line)"
    n=$((n + 1))
done
[ "$n" -ge 3 ] && ok || fail "only $n frames compared"

# Bad URLs: one line, never a crash.
"$tw" info --tileset "file://$tmp/nothing/tileset.json" >"$tmp/bad.out" 2>"$tmp/bad.err"
rc=$?
{ [ "$rc" = 1 ] || [ "$rc" = 2 ]; } || fail "a missing tileset.json exits $rc"
grep -q "tileset.json" "$tmp/bad.err" && ok || fail "a missing tileset.json is not named: $(cat "$tmp/bad.err")"
"$tw" info --tileset "file://$tmp/baked/bake.json" >"$tmp/bad.out" 2>"$tmp/bad.err"
rc=$?
[ "$rc" = 2 ] || fail "a JSON that is no baked tileset exits $rc: $(cat "$tmp/bad.err")"
grep -q "extras.tileworld" "$tmp/bad.err" && ok || fail "no reason given: $(cat "$tmp/bad.err")"

echo "file:// draws what city-gen draws ($n frames compared)"
finish tiles3d
