#!/usr/bin/env bash
# Every .glb that tileworld bake writes (city, forest and city-gen cells,
# and the coarser level above them)
# passes the Khronos glTF validator with 0 errors. Skipped (77) without node
# or the npm package gltf-validator (npm install -g gltf-validator).
set -u
tw=${1:?usage: test-bake-validator.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"
command -v node >/dev/null || { echo "no node: skipped"; exit 77; }
NODE_PATH=${NODE_PATH:-}
if command -v npm >/dev/null; then
    NODE_PATH="${NODE_PATH:+$NODE_PATH:}$(npm root -g 2>/dev/null)"
fi
export NODE_PATH
node -e "require('gltf-validator')" 2>/dev/null ||
    { echo "no gltf-validator for node (npm install -g gltf-validator): skipped"; exit 77; }
for world in city forest city-gen; do
    "$tw" bake --tileset "$world" --cells 0,0:2,1 --levels 2 --out "$tmp/$world" --quiet ||
        { bad "bake $world"; continue; }
done
find "$tmp" -name '*.glb' | sort >"$tmp/files"
# 6 cells and 2 coarser tiles each.
[ "$(wc -l <"$tmp/files")" -eq 24 ] && ok || bad "not 24 .glb files"
if xargs node "$(dirname "$0")/gltf-validate.js" <"$tmp/files" >"$tmp/report"; then
    ok
else
    bad "the validator found errors:"
    cat "$tmp/report"
fi
finish bake-gltf-validator
