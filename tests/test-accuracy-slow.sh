#!/usr/bin/env bash
# The slow accuracy suite (meson test --suite slow): the done criterion of
# "speed against accuracy" at the default size, 640x360, under --verify, as
# a user runs it (timing as it comes, not --deterministic):
#   - bench --path flyover --frames 240 --methods chc,tilequery+chc: 0 missed
#     pixels;
#   - 300-frame walks of street, flyover, forest (forest tileset) and hybrid
#     (street path) with every method, all conservative: 0 missed pixels and
#     0 depth errors for each.
# Counts are read from frames.csv by column name.
#   test-accuracy-slow.sh PATH/TO/tileworld
set -u
tw=${1:?usage: test-accuracy-slow.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

# totals DIR: one line per method, "METHOD FRAMES MISSED_PIXELS DEPTH_ERRORS".
totals() {
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
             { m = $col["method"]; n[m]++; mp[m] += $col["missed_pixels"]; de[m] += $col["depth_errors"] }
             END { for (m in n) print m, n[m], mp[m], de[m] }' "$1/frames.csv" | sort
}

# expect_exact NAME DIR FRAMES METHODS...: each method ran FRAMES frames with
# 0 missed pixels and 0 depth errors.
expect_exact() {
    local name=$1 dir=$2 frames=$3
    shift 3
    local m line
    for m in "$@"; do
        line=$(totals "$dir" | awk -v m="$m" '$1 == m')
        if [ -z "$line" ]; then
            bad "$name: no frames of $m"
            continue
        fi
        read -r _ n missed depth <<<"$line"
        echo "$name: $m: $n frames, $missed missed pixels, $depth depth errors"
        [ "$n" -eq "$frames" ] && ok || bad "$name: $m ran $n frames, not $frames"
        [ "$missed" -eq 0 ] && ok || bad "$name: $m missed $missed pixels"
        [ "$depth" -eq 0 ] && ok || bad "$name: $m has $depth depth errors"
    done
}

# bench NAME ARGS...: a quiet bench into $tmp/NAME. Missed pixels are
# counted from frames.csv by expect_exact (--allow-missed: exit 0 with them).
bench() {
    local name=$1
    shift
    if "$tw" bench "$@" --verify --allow-missed --png-every 0 --quiet --out "$tmp/$name" \
          >"$tmp/$name.out" 2>"$tmp/$name.err"; then
        ok
        return 0
    fi
    bad "tileworld bench $*: $(head -c 400 "$tmp/$name.err")"
    return 1
}

all=(vfc tilequery chc tilequery+chc oracle)

bench flyover-240 --path flyover --frames 240 --methods chc,tilequery+chc &&
    expect_exact flyover-240 "$tmp/flyover-240" 240 chc tilequery+chc
rm -rf "$tmp/flyover-240"
for walk in street:city:street flyover:city:flyover forest:forest:forest hybrid:hybrid:street; do
    IFS=: read -r name tileset path <<<"$walk"
    bench "$name" --tileset "$tileset" --path "$path" --frames 300 &&
        expect_exact "$name" "$tmp/$name" 300 "${all[@]}"
    rm -rf "${tmp:?}/$name"
done

finish accuracy-slow
