#!/usr/bin/env bash
# The headless contexts (context.h) through the tileworld command: OSMesa,
# EGL's surfaceless platform and an EGL device (Mesa's software device here)
# render the same city walk byte for byte; a device that does not exist, an
# EGL that offers nothing and bad values of --gl, --gpu and TW_GPU are one
# line on stderr each, with the documented exit status.
# usage: test-context-cli.sh TILEWORLD
set -u
tw=$1
. "$(dirname "$0")/test-lib.sh"

# expect_fail STATUS PATTERN ARGS...: the command exits STATUS with exactly
# one line on stderr that matches PATTERN (an extended regular expression).
expect_fail() {
    local want=$1 pattern=$2
    shift 2
    "$@" >"$tmp/out" 2>"$tmp/err"
    local rc=$? lines
    lines=$(wc -l <"$tmp/err")
    if [ "$rc" -ne "$want" ] || [ "$lines" -ne 1 ] || ! grep -Eq -e "$pattern" "$tmp/err"; then
        bad "$* exited $rc (want $want) with $lines stderr lines (want 1 matching '$pattern'):"
        cat "$tmp/err" >&2
    else
        ok
    fi
}

# walk NAME ARGS...: a short deterministic city walk into $tmp/NAME.
walk() {
    local name=$1
    shift
    if "$tw" walk --frames 40 --png-every 13 --deterministic --quiet --out "$tmp/$name" "$@" \
        2>"$tmp/$name.err"; then
        ok
    else
        bad "walk $* failed: $(cat "$tmp/$name.err")"
    fi
}

# The context a run went through, as summary.json says it.
context_of() {
    grep -o '"context": *"[a-z-]*"' "$1/summary.json" | head -n 1 | sed 's/.*"\([a-z-]*\)"$/\1/'
}

# On llvmpipe every way renders the same images. A machine whose EGL has a
# GPU renders with it, whose images are its own: there only the failures
# below are checked.
if "$tw" info --gl egl 2>/dev/null | grep -q '^OpenGL: .*a software renderer'; then
    walk osmesa --gl osmesa
    walk egl --gl egl
    walk device --gpu 0
    walk auto

    # What each ran through: EGL here has no GPU, so --gl egl takes Mesa's
    # surfaceless platform and auto takes OSMesa.
    for pair in osmesa:osmesa egl:egl-surfaceless device:egl-device auto:osmesa; do
        name=${pair%%:*} want=${pair#*:}
        got=$(context_of "$tmp/$name")
        [ "$got" = "$want" ] && ok || bad "$name ran through '$got', not $want"
    done

    # The images are byte-identical, and so are the counts (every column but the
    # timings and blocking_reads, waits and hzb_lag, which timing decides: the
    # walk is deterministic).
    counts() {
        awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i !~ /ms/ && $i != "blocking_reads" && $i != "waits" && $i != "hzb_lag") keep[i] = 1 }
                 { row = ""; for (i = 1; i <= NF; i++) if (keep[i]) row = row $i ","; print row }' \
            "$1/frames.csv"
    }
    pngs=$(cd "$tmp/osmesa" && ls frame-*.png)
    [ "$(echo "$pngs" | wc -l)" -eq 4 ] && ok || bad "the osmesa walk wrote $(echo "$pngs" | wc -l) PNGs, not 4"
    for other in egl device auto; do
        for f in $pngs; do
            cmp -s "$tmp/osmesa/$f" "$tmp/$other/$f" && ok || bad "$other/$f differs from OSMesa's"
        done
        if cmp -s <(counts "$tmp/osmesa") <(counts "$tmp/$other"); then ok; else
            bad "$other's frames.csv counts differ from OSMesa's"
        fi
    done
else
    echo "SKIP: EGL has a GPU here: OSMesa and EGL are not compared byte for byte"
fi

# A device that does not exist: one line naming it, exit 1 (the machine's failure).
expect_fail 1 'EGL device 9: no such device' "$tw" walk --gpu 9 --frames 1 --out "$tmp/x"
expect_fail 1 'EGL device 9: no such device' env TW_GPU=9 "$tw" walk --frames 1 --out "$tmp/x"
# --gpu wins over TW_GPU.
if TW_GPU=9 "$tw" walk --gpu 0 --frames 2 --quiet --out "$tmp/x" 2>"$tmp/err"; then ok; else
    bad "--gpu 0 did not win over TW_GPU=9: $(cat "$tmp/err")"
fi

# An EGL with no vendor (glvnd finds no driver): --gl egl fails with one line
# that says what was tried, auto falls back to OSMesa.
export_none=(env __EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent/none.json)
expect_fail 1 'no OpenGL 3.3 core context \(--gl egl\): .*EGL' \
    "${export_none[@]}" "$tw" walk --gl egl --frames 1 --out "$tmp/x"
if "${export_none[@]}" "$tw" walk --frames 2 --quiet --out "$tmp/none" 2>"$tmp/err" &&
    [ "$(context_of "$tmp/none")" = osmesa ]; then ok; else
    bad "auto without an EGL vendor did not fall back to OSMesa: $(cat "$tmp/err")"
fi

# Bad values: the user's, exit 2.
expect_fail 2 "--gl: 'vulkan' is not auto, egl or osmesa" "$tw" walk --gl vulkan
expect_fail 2 "--gpu: " "$tw" walk --gpu -1
expect_fail 2 "--gpu: " "$tw" walk --gpu 64
expect_fail 2 "TW_GPU: " env TW_GPU=first "$tw" walk --frames 1 --out "$tmp/x"
expect_fail 2 "osmesa has no devices" "$tw" walk --gl osmesa --gpu 0
# info says what it ran on.
if "$tw" info --gl egl 2>"$tmp/err" | grep -Eq '^OpenGL: .* through egl-(surfaceless|device)'; then ok; else
    bad "info --gl egl does not say its renderer and context: $(cat "$tmp/err")"
fi

finish context-cli
