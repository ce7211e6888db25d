#!/usr/bin/env bash
# The viewer (tileworld-view) under Xvfb: built-in paths flown for a few
# frames, screenshots decoded by png-check (valid, the size asked for, not
# one flat colour), the overlay and the debug views visibly drawn, freeze,
# every method, the hand-over from `tileworld view`, and the fallback to
# standard depth when the context has no glClipControl.
# Usage: test-view.sh TILEWORLD-VIEW PNG-CHECK TILEWORLD
# xvfb-run missing is a failure, not a skip: scripts/setup.sh installs it.
set -uo pipefail
view=$1
check=$2
tileworld=$3

if ! command -v xvfb-run >/dev/null 2>&1; then
    echo "test-view: xvfb-run is missing: install xvfb and xauth (scripts/setup.sh)" >&2
    exit 1
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0
pass() { echo "ok: $1"; passed=$((passed + 1)); }
fail() { echo "FAIL: $1" >&2; failed=$((failed + 1)); }

# One X server per run; -a picks a free display number.
xrun() { xvfb-run -a -s "-screen 0 1024x768x24" "$@"; }

# Under the sanitizer CI run, no leak checking in this process: Mesa's GLX
# driver is unloaded by glfwTerminate() and what it still held then counts
# as leaked from an unknown module, which no suppression can name (they
# vanish when it stays loaded). ASan and UBSan stay on; the runtime's debug
# views are leak-checked in test-debug-views (OSMesa).
export ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0"

# field NAME LINE: the number after NAME in png-check's output.
field() { awk -v k="$1" '{ for (i = 1; i < NF; i++) if ($i == k) print $(i + 1) }' <<<"$2"; }

# shot NAME SIZE [viewer options...]: runs the viewer to a screenshot;
# passes when it exits 0 and the PNG decodes at SIZE with more than one colour.
shot() {
    local name=$1 size=$2
    shift 2
    if ! xrun "$view" --size "$size" --quiet --screenshot "$tmp/$name.png" "$@" \
        2>"$tmp/$name.err"; then
        fail "$name: tileworld-view failed: $(head -c 400 "$tmp/$name.err")"
        return 1
    fi
    local out
    if ! out=$("$check" "$tmp/$name.png"); then
        fail "$name: the screenshot is not a valid PNG"
        return 1
    fi
    local colours stddev
    colours=$(field colours "$out")
    stddev=$(field stddev "$out")
    if [ "$(field size "$out")" != "$size" ]; then
        fail "$name: screenshot is $(field size "$out"), not $size"
    elif [ "$colours" -lt 32 ] || awk -v s="$stddev" 'BEGIN { exit !(s < 8) }'; then
        fail "$name: screenshot looks empty ($out)"
    else
        pass "$name ($out)"
        return 0
    fi
    return 1
}

# differs A B MIN: screenshots A and B differ in at least a MIN fraction of pixels.
differs() {
    local out
    out=$("$check" "$tmp/$1.png" "$tmp/$2.png") || { fail "$1 vs $2: cannot compare"; return; }
    local d
    d=$(field differ "$out")
    if awk -v d="$d" -v m="$3" 'BEGIN { exit !(d >= m) }'; then
        pass "$1 differs from $2 in $d of the pixels (>= $3)"
    else
        fail "$1 should differ from $2 in >= $3 of the pixels, differs in $d"
    fi
}

# The issue's run, with and without the overlay and with each debug view.
shot plain 640x360 --path street --frames 20
shot no-overlay 640x360 --path street --frames 20 --no-overlay
shot cells 640x360 --path street --frames 20 --debug cells
shot nodes 640x360 --path street --frames 20 --debug nodes
shot queries 640x360 --path street --frames 20 --debug queries
differs plain no-overlay 0.03
differs cells plain 0.05
differs nodes plain 0.03
differs queries plain 0.03

# Freeze at frame 5 while the flyover rises: the frozen set, seen from above.
shot frozen 640x360 --path flyover --frames 60 --freeze-at 5 --debug all

# Every method, a few frames each (1-7 in the window).
for m in vfc tilequery chc tilequery+chc oracle hzb tilequery+hzb; do
    shot "method-$m" 320x180 --path street --frames 4 --method "$m" --debug all
done

# No glClipControl (a 3.3 context without ARB_clip_control): the renderer
# says so and draws with standard 24-bit depth; the image stays the same
# but for depth precision.
if MESA_GL_VERSION_OVERRIDE=3.3 MESA_EXTENSION_OVERRIDE=-GL_ARB_clip_control \
    xrun "$view" --size 640x360 --path street --frames 20 --no-overlay \
    --screenshot "$tmp/no-clip.png" 2>"$tmp/no-clip.err"; then
    if grep -q "glClipControl" "$tmp/no-clip.err"; then
        pass "without glClipControl: logged ($(grep glClipControl "$tmp/no-clip.err"))"
    else
        fail "without glClipControl: no log line about it"
    fi
    out=$("$check" "$tmp/no-clip.png" "$tmp/no-overlay.png") || out=""
    d=$(field differ "$out")
    if [ -n "$d" ] && awk -v d="$d" 'BEGIN { exit !(d < 0.02) }'; then
        pass "without glClipControl: the image matches reversed depth's but for $d of the pixels"
    else
        fail "without glClipControl: the image differs from reversed depth's ($out)"
    fi
else
    fail "without glClipControl: tileworld-view failed: $(head -c 400 "$tmp/no-clip.err")"
fi

# `tileworld view` hands its arguments to tileworld-view beside it.
if xrun "$tileworld" view --path street --frames 3 --size 320x180 --quiet \
    --screenshot "$tmp/via.png" 2>"$tmp/via.err" &&
    [ "$(field size "$("$check" "$tmp/via.png")")" = 320x180 ]; then
    pass "tileworld view execs tileworld-view with the arguments"
else
    fail "tileworld view: $(head -c 400 "$tmp/via.err")"
fi

# Without tileworld-view beside it: one line on stderr, exit status 2.
mkdir "$tmp/alone"
cp "$tileworld" "$tmp/alone/tileworld"
"$tmp/alone/tileworld" view --frames 1 >/dev/null 2>"$tmp/alone.err"
rc=$?
if [ "$rc" -eq 2 ] && [ "$(wc -l <"$tmp/alone.err")" -eq 1 ]; then
    pass "tileworld view without the viewer: exit 2, '$(cat "$tmp/alone.err")'"
else
    fail "tileworld view without the viewer: exit $rc, stderr: $(cat "$tmp/alone.err")"
fi

# Bad options: exit 2 and one line, before any window opens.
for bad in "--size 12" "--method fastest" "--debug pixels" "--frames 0" "--path nowhere" "--bogus"; do
    # shellcheck disable=SC2086
    "$view" $bad >/dev/null 2>"$tmp/bad.err"
    rc=$?
    if [ "$rc" -eq 2 ] && [ "$(wc -l <"$tmp/bad.err")" -eq 1 ]; then
        pass "tileworld-view $bad: exit 2, '$(cat "$tmp/bad.err")'"
    else
        fail "tileworld-view $bad: exit $rc, stderr: $(cat "$tmp/bad.err")"
    fi
done

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
