#!/usr/bin/env bash
# A baked tileset in real 3D Tiles clients: 3DTilesRendererJS (three.js)
# and, where its npm package is there, CesiumJS, in headless Debian Chromium
# (WebGL through SwiftShader), driven by playwright-core, the page and the
# baked folder served by node on 127.0.0.1. Four bakes of city: 4 x 4 cells
# at the origin with coarser levels, drawn at full detail (the 16 cells), at
# level 1 (4 tiles) and at the root (1 tile); 3 x 2 cells away from the
# origin (a transform, a grid with unavailable tiles); 2 x 2 cells a million
# cells from the origin; and a row of 64 cells, a quadtree of 7 levels whose
# cells are in 64 child subtrees. CesiumJS draws each with the tileset's
# frame east-north-up on the globe (no globe drawn). Each draw: exactly the
# tiles expected, each where the client's implicit tiling puts it
# (3DTilesRendererJS), no error in the page, the loader, the console or the
# server, and a screenshot of the city's colours, saved in OUTDIR.
#   test-bake-chromium.sh PATH/TO/tileworld PATH/TO/png-check OUTDIR
# Skipped (77) without node, /usr/bin/chromium (apt-get install chromium) or
# the npm packages of tests/web (npm ci --prefix tests/web).
set -u
tw=${1:?usage: test-bake-chromium.sh PATH/TO/tileworld PATH/TO/png-check OUTDIR}
check=${2:?usage: test-bake-chromium.sh PATH/TO/tileworld PATH/TO/png-check OUTDIR}
out=${3:?usage: test-bake-chromium.sh PATH/TO/tileworld PATH/TO/png-check OUTDIR}
. "$(dirname "$0")/test-lib.sh"
web=$(cd "$(dirname "$0")/web" && pwd)
command -v node >/dev/null || { echo "no node: skipped"; exit 77; }
[ -x "${CHROMIUM:-/usr/bin/chromium}" ] ||
    { echo "no ${CHROMIUM:-/usr/bin/chromium} (apt-get install chromium): skipped"; exit 77; }
for p in 3d-tiles-renderer three playwright-core; do
    [ -f "$web/node_modules/$p/package.json" ] ||
        { echo "no npm package $p in tests/web (npm ci --prefix tests/web): skipped"; exit 77; }
done
mkdir -p "$out"

# field NAME LINE: the number after NAME in png-check's output.
field() { awk -v k="$1" '{ for (i = 1; i < NF; i++) if ($i == k) print $(i + 1) }' <<<"$2"; }

# draw_in PAGE NAME DIR QUERY LEVEL MIN_DRAWN: draws DIR in PAGE with the
# page's QUERY; the tiles expected are every .glb of level LEVEL; at least
# MIN_DRAWN of the pixels drawn.
draw_in() {
    local page=$1 name=$2 dir=$3 query=$4 level=$5 min=$6 rc
    (cd "$dir" && find "content/$level" -name '*.glb' | sort) >"$tmp/$name.expected"
    node "$web/render-tileset.mjs" "$dir" "$out/$name.png" "$query" "$page" >"$out/$name.json" 2>"$tmp/$name.err"
    rc=$?
    if [ "$rc" -eq 77 ]; then
        cat "$tmp/$name.err"
        echo "skipped"
        exit 77
    fi
    [ "$rc" -eq 0 ] || { bad "$name: the page did not finish:"; cat "$tmp/$name.err" >&2; return; }
    ok
    if xargs node "$web/check-render.mjs" --min-drawn="$min" "$out/$name.json" <"$tmp/$name.expected" >"$tmp/$name.check"; then
        ok
    else
        bad "$name: $(grep -c FAIL "$tmp/$name.check") checks:"
        cat "$tmp/$name.check" >&2
    fi
    echo "$name: $(tail -n 1 "$tmp/$name.check")"
    local png
    png=$("$check" "$out/$name.png") || { bad "$name: the screenshot is no PNG"; return; }
    [ "$(field size "$png")" = 800x600 ] && [ "$(field colours "$png")" -ge 8 ] &&
        awk -v s="$(field stddev "$png")" 'BEGIN { exit !(s >= 1) }' && ok ||
        bad "$name: the screenshot is $png"
    echo "$name: screenshot $out/$name.png ($png)"
}

# draw NAME DIR QUERY LEVEL [MIN_DRAWN]: draw_in 3DTilesRendererJS (0.05 of
# the pixels unless MIN_DRAWN says otherwise), then in CesiumJS where its npm
# package is there (no placement check: the palette's hues are those that
# 3DTilesRendererJS read from the tiles' COLOR_0).
draw() {
    local name=$1 dir=$2 query=$3 level=$4 min=${5:-0.05} palette
    draw_in tileset-3dtr.html "$name" "$dir" "$query" "$level" "$min"
    [ -f "$web/node_modules/cesium/package.json" ] || return 0
    palette=$(node -e 'console.log(JSON.parse(require("fs").readFileSync(process.argv[1])).paletteHues.join(","))' \
        "$out/$name.json") || { bad "$name: no palette"; return; }
    draw_in tileset-cesium.html "cesium-$name" "$dir" "$query&palette=$palette" "$level" "$min"
    # Both clients drew the same triangles.
    node -e 'const t = (f) => JSON.parse(require("fs").readFileSync(f)).drawnTriangles;
             process.exit(t(process.argv[1]) === t(process.argv[2]) ? 0 : 1)' \
        "$out/$name.json" "$out/cesium-$name.json" && ok ||
        bad "$name: CesiumJS drew other triangles than 3DTilesRendererJS"
}

"$tw" bake --tileset city --cells 0,0:3,3 --levels 3 --out "$tmp/origin" --quiet || bad "bake 0,0:3,3"
# The renderers' error target in pixels: 0 refines to the cells; 250 stops
# at level 1 (from this camera its tiles' screen-space error is 120 to 190
# pixels, the root's 350 to 500); 600 at the root (CesiumJS draws nothing
# from 700 to 900 up: the tileset's geometricError, twice the root's, is
# then small enough on screen).
draw origin-cells "$tmp/origin" "error=0" 2
draw origin-level1 "$tmp/origin" "error=250" 1
draw origin-root "$tmp/origin" "error=600" 0
"$tw" bake --tileset city --cells 40,-7:42,-6 --levels 2 --out "$tmp/away" --quiet || bad "bake 40,-7:42,-6"
draw away-cells "$tmp/away" "error=0" 2
# A million cells from the origin (80,000 km): the transform holds the
# offset, each tile still where its box says within 1 cm.
"$tw" bake --tileset city --cells 1000000,1000000:1000001,1000001 --out "$tmp/far" --quiet ||
    bad "bake 1000000,1000000:1000001,1000001"
draw far-cells "$tmp/far" "error=0" 1
# The camera frames the root's box, 64 x 64 cells: the row is a thin strip.
"$tw" bake --tileset city --cells 0,0:63,0 --out "$tmp/row" --quiet || bad "bake 0,0:63,0"
[ "$(find "$tmp/row/subtrees" -name '*.subtree' | wc -l)" -eq 65 ] && ok || bad "row: not 65 subtrees"
draw row-cells "$tmp/row" "error=0" 6 0.002
finish bake-chromium
