#!/usr/bin/env bash
# The GPU benchmark suite: every method over the standard scenes
# at 1920x1080, then a short --verify run per scene, within a wall-time
# budget, summarised in OUT/gpu-bench.md. Runs from a pack made by
# scripts/gpu-pack.sh on a machine that has a GPU driver and nothing else of
# ours: needs bash, coreutils, awk, gzip and tar (dpkg-deb, ar and xz when
# the machine has no libEGL.so.1 of its own). See README "GPU bench".
set -euo pipefail

usage() {
    local status=${1:-2}
    [ "$status" -eq 0 ] && exec 3>&1 || exec 3>&2
    cat >&3 <<'EOF'
usage: scripts/gpu-bench.sh [--pack DIR | --tileworld PATH] [--out DIR] [--budget-s S] [--quick]
                            [--gl auto|egl|osmesa] [--size WxH] [--frames N] [--verify-frames N]
EOF
    exit "$status"
}
die() { echo "gpu-bench: $*" >&2; exit 1; }
bad_input() { echo "gpu-bench: $*" >&2; exit 2; }
note() { echo "gpu-bench: $*"; }
now_ms() { date +%s%3N; }
# quote ARGS...: a command line that a shell reads back as ARGS.
quote() {
    local a words=()
    for a; do
        if [[ $a =~ ^[A-Za-z0-9_./,:+=@%-]+$ ]]; then words+=("$a"); else words+=("$(printf %q "$a")"); fi
    done
    echo "${words[*]}"
}

root=$(cd "$(dirname "$0")/.." && pwd)
command_line=$(quote "$0" "$@")
t_start=$(now_ms)

pack=$root/pack
tileworld=
out=out/gpu-bench
budget_s=
quick=false
gl=
size=
frames=
verify_frames=
while [ $# -gt 0 ]; do
    case $1 in
    --*=*) opt=${1%%=*} val=${1#*=}; shift; set -- "$opt" "$val" "$@"; continue ;;
    --quick) quick=true; shift; continue ;;
    -h | --help) usage 0 ;;
    --pack | --tileworld | --out | --budget-s | --gl | --size | --frames | --verify-frames)
        [ $# -ge 2 ] || bad_input "$1 needs a value" ;;
    *) bad_input "unknown option '$1'" ;;
    esac
    case $1 in
    --pack) pack=$2 ;;
    --tileworld) tileworld=$2 ;;
    --out) out=$2 ;;
    --budget-s) budget_s=$2 ;;
    --gl) gl=$2 ;;
    --size) size=$2 ;;
    --frames) frames=$2 ;;
    --verify-frames) verify_frames=$2 ;;
    esac
    shift 2
done

# --quick: a CI-sized run that llvmpipe finishes, two scenes; options given
# explicitly still win.
methods=vfc,tilequery,chc,tilequery+chc,hzb,tilequery+hzb,box-oracle,oracle
# name|tileset|path|view distance (empty: the default)[|more bench options];
# a tileset starting with @ is a folder of the pack (or of the repository,
# with --tileworld).
if $quick; then
    : "${size:=320x180}" "${frames:=5}" "${verify_frames:=1}" "${budget_s:=120}"
    scenes=(
        "city-street|city|street|"
        "cesium-buildings-street-vd40|@tilesets/cesium-buildings/cesium-buildings.json|street|40"
    )
else
    : "${size:=1920x1080}" "${frames:=300}" "${verify_frames:=30}" "${budget_s:=420}"
    scenes=(
        "city-street|city|street|"
        "city-flyover|city|flyover|"
        "forest-forest|forest|forest|"
        "hybrid-street|hybrid|street|"
        "kenney-city-street|@tilesets/kenney-city/kenney-city.json|street|"
        "city-gen-street|city-gen|street|"
        "cesium-buildings-street|@tilesets/cesium-buildings/cesium-buildings.json|street|"
        "city-flyover-vd400|city|flyover|400"
        "city-flyover-vd800|city|flyover|800"
        "city-flyover-vd1600|city|flyover|1600"
        "city-flyover-vd6400|city|flyover|6400"
        "city-flyover-vd1600-full-detail|city|flyover|1600|--max-screen-error 0"
    )
fi
[[ $budget_s =~ ^[1-9][0-9]*$ && $budget_s -ge 10 ]] || bad_input "--budget-s wants whole seconds, at least 10 (got '$budget_s')"
[[ $frames =~ ^[1-9][0-9]*$ ]] || bad_input "--frames wants a count, at least 1 (got '$frames')"
[[ $verify_frames =~ ^(0|[1-9][0-9]*)$ ]] || bad_input "--verify-frames wants a count (got '$verify_frames')"
[[ $size =~ ^[0-9]+x[0-9]+$ ]] || bad_input "--size wants WxH (got '$size')"
case $gl in '' | auto | egl | osmesa) ;; *) bad_input "--gl wants auto, egl or osmesa (got '$gl')" ;; esac
budget_ms=$((budget_s * 1000))

mkdir -p "$out" || die "cannot make $out"
out=$(cd "$out" && pwd)
rm -f "$out/gpu-bench.md" "$out/setup.txt" "$out/calibrate.txt"
work=$(mktemp -d "${TMPDIR:-/tmp}/gpu-bench.XXXXXX")
trap 'rm -rf "$work"' EXIT

# ---- the program and its libraries ------------------------------------------
# Libraries are unpacked into a temporary folder, not into the pack, so that
# the pack stays as gpu-pack.sh made it (and within what can be carried).
ldconfig_bin=$(command -v ldconfig || { [ -x /sbin/ldconfig ] && echo /sbin/ldconfig; } || true)
ld_cache=
if [ -n "$ldconfig_bin" ]; then ld_cache=$("$ldconfig_bin" -p 2>/dev/null || true); fi
# system_has SONAME: the dynamic loader finds SONAME without our help.
system_has() {
    grep -q "^[[:space:]]*${1//./\\.} " <<<"$ld_cache" && return 0
    local d
    for d in /lib/x86_64-linux-gnu /usr/lib/x86_64-linux-gnu /lib64 /usr/lib64 /usr/lib; do
        [ -e "$d/$1" ] && return 0
    done
    return 1
}

# deb_data_member DEB: writes its data.tar.* member to $work/data.tar and
# prints its name, with coreutils alone (neither dpkg-deb nor ar is there):
# an ar archive is a magic line, then 60-byte headers (name 16, size 10 at
# byte 48) each before its data, padded to even sizes.
deb_data_member() {
    local deb=$1 off=8 total hdr name size
    total=$(stat -c %s "$deb")
    [ "$(head -c 8 "$deb")" = '!<arch>' ] || die "$deb is not an ar archive"
    while [ "$off" -lt "$total" ]; do
        hdr=$(dd if="$deb" iflag=skip_bytes,count_bytes skip="$off" count=60 status=none)
        name=${hdr:0:16} size=${hdr:48:10}
        name=${name%% *} size=${size%% *}
        [[ $size =~ ^[0-9]+$ ]] || die "$deb: a broken ar header at byte $off"
        if [[ $name == data.tar* ]]; then
            dd if="$deb" of="$work/data.tar" iflag=skip_bytes,count_bytes skip=$((off + 60)) \
                count="$size" bs=65536 status=none
            echo "${name%/}"
            return 0
        fi
        off=$((off + 60 + size + size % 2))
    done
    die "$deb holds no data.tar member"
}
extract_deb() {
    local deb=$1 dest=$2 member flag
    if command -v dpkg-deb >/dev/null; then
        dpkg-deb -x "$deb" "$dest" || die "dpkg-deb -x $deb failed"
        return
    fi
    if command -v ar >/dev/null; then
        member=$(ar t "$deb") || die "ar t $deb failed"
        member=$(grep -m1 '^data\.tar' <<<"$member") || die "$deb holds no data.tar member"
        ar p "$deb" "$member" >"$work/data.tar" || die "ar p $deb $member failed"
    else
        member=$(deb_data_member "$deb")
    fi
    case $member in
    *.xz) flag=-J ;;
    *.gz) flag=-z ;;
    *.zst) flag=--zstd ;;
    *) flag= ;;
    esac
    tar -x $flag -f "$work/data.tar" -C "$dest" || die "tar could not unpack $member of $deb (xz missing?)"
    rm -f "$work/data.tar"
}

sysroot_used=no
vendor_note="glvnd's own search (/usr/share/glvnd/egl_vendor.d, /etc/glvnd/egl_vendor.d)"
if [ -n "$tileworld" ]; then
    [ "$pack" = "$root/pack" ] || bad_input "--pack and --tileworld exclude each other"
    bin=$tileworld
    data=$root
else
    [ -f "$pack/PACK.txt" ] || die "$pack is not a pack (no PACK.txt): make one with scripts/gpu-pack.sh"
    pack=$(cd "$pack" && pwd)
    bin=$pack/bin/tileworld
    data=$pack
    mkdir -p "$work/lib"
    for z in "$pack"/lib/*.gz; do
        [ -e "$z" ] || continue
        gzip -dc "$z" >"$work/lib/$(basename "$z" .gz)" || die "gunzip $z failed"
    done
    libpath=$work/lib:$pack/lib
    if [ "${TW_FORCE_SYSROOT:-0}" = 1 ] || ! system_has libEGL.so.1; then
        mkdir -p "$work/sysroot"
        for deb in "$pack"/debs/*.deb; do
            [ -e "$deb" ] || die "$pack/debs holds no .deb, and the system has no libEGL.so.1"
            extract_deb "$deb" "$work/sysroot"
        done
        egl=$(find "$work/sysroot" -name libEGL.so.1)
        [ -n "$egl" ] || die "the glvnd packages in $pack/debs hold no libEGL.so.1"
        sysdir=$(dirname "$(head -n 1 <<<"$egl")")
        libpath=$sysdir:$libpath
        sysroot_used="yes: $(basename "$sysdir") of $(cd "$pack/debs" && echo *.deb)"
    fi
    export LD_LIBRARY_PATH=$libpath${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
[ -x "$bin" ] || die "$bin is missing or not executable"

# glvnd picks its EGL vendor from JSON files; a container given the NVIDIA
# driver's libraries does not always get the file naming them.
named=false
for f in /usr/share/glvnd/egl_vendor.d/*.json /etc/glvnd/egl_vendor.d/*.json; do
    [ -e "$f" ] && grep -q libEGL_nvidia "$f" && named=true
done
if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}${__EGL_VENDOR_LIBRARY_DIRS:-}" ] && ! $named; then
    nvidia=$(awk '$1 == "libEGL_nvidia.so.0" { p = $NF } END { print p }' <<<"$ld_cache")
    nvidia_path=libEGL_nvidia.so.0
    if [ -z "$nvidia" ]; then
        nvidia=$(find /usr/lib /usr/lib64 /usr/lib/x86_64-linux-gnu /usr/local/nvidia -maxdepth 4 \
            -name libEGL_nvidia.so.0 2>/dev/null | head -n 1 || true)
        if [ -n "$nvidia" ]; then
            # Not in the loader's cache: its own dependencies lie beside it.
            nvidia_path=$nvidia
            LD_LIBRARY_PATH=$(dirname "$nvidia")${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
            export LD_LIBRARY_PATH
        fi
    fi
    if [ -n "$nvidia" ]; then
        printf '{"file_format_version":"1.0.0","ICD":{"library_path":"%s"}}\n' "$nvidia_path" \
            >"$work/10_nvidia.json"
        export __EGL_VENDOR_LIBRARY_FILENAMES=$work/10_nvidia.json
        vendor_note="written: {\"library_path\":\"$nvidia_path\"} (no vendor file named libEGL_nvidia; found $nvidia)"
    fi
fi

gl_args=()
help=$("$bin" --help 2>&1 || true)
if grep -q -- '--gl ' <<<"$help"; then
    gl_args=(--gl "${gl:-auto}")
elif [ -n "$gl" ]; then
    die "$bin has no --gl option (built before it was added); run without --gl"
fi

{
    echo "tileworld: $bin"
    if [ -n "$tileworld" ]; then
        echo "pack: none (--tileworld; tilesets from $root)"
    else
        echo "pack: $pack ($(sed -n 2p "$pack/PACK.txt"))"
    fi
    echo "glvnd sysroot: $sysroot_used"
    echo "EGL vendor: $vendor_note"
    echo "LD_LIBRARY_PATH=${LD_LIBRARY_PATH:-}"
    echo "__EGL_VENDOR_LIBRARY_FILENAMES=${__EGL_VENDOR_LIBRARY_FILENAMES:-}"
    echo "uname: $(uname -srm)"
    if command -v nvidia-smi >/dev/null; then
        echo "nvidia-smi -L:"
        nvidia-smi -L 2>&1 | sed 's/^/  /' || true
    fi
    if command -v ldd >/dev/null; then
        echo "ldd tileworld:"
        ldd "$bin" 2>&1 | sed 's/^/  /' || true
    fi
} >"$out/setup.txt"

secs() { awk -v ms="$1" 'BEGIN { printf "%.1f", ms / 1000 }'; }
left_ms() { echo $((budget_ms - ($(now_ms) - t_start))); }

# ---- calibration --------------------------------------------------------------
cal_cmd=("$bin" info --calibrate --size "$size" "${gl_args[@]}")
t=$(now_ms)
rc=0
timeout -k 5 $(($(left_ms) / 1000 + 1)) "${cal_cmd[@]}" >"$out/calibrate.txt" 2>&1 || rc=$?
cal_ms=$(($(now_ms) - t))
[ "$rc" -eq 0 ] || die "tileworld info --calibrate failed (exit $rc): $(tail -n 1 "$out/calibrate.txt") (see $out/calibrate.txt, $out/setup.txt)"
note "calibrated in $(secs "$cal_ms") s: $(grep -m1 '^OpenGL:' "$out/calibrate.txt" || echo 'renderer not printed')"
# The cost of a run that renders nothing: creating its worlds and context.
startup_ms=$((cal_ms > 200 ? cal_ms : 200))

# ---- the runs -----------------------------------------------------------------
declare -A b_rc=() b_frames=() b_ms=() v_rc=() v_frames=() v_ms=() rate=()
verify_factor=4       # a verify frame's cost over a bench frame's, until measured
margin_ms=3000        # for the report
commands=()

# fdiv A B: A / B as a float.
fdiv() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.6f", (b > 0 ? a / b : 0) }'; }
mean_rate() {
    local sum=0 n=0 r
    for r in "${rate[@]}"; do
        sum=$(awk -v s="$sum" -v r="$r" 'BEGIN { printf "%.6f", s + r }')
        n=$((n + 1))
    done
    fdiv "$sum" "$n"
}
# plan_frames WANT RUNS_LEFT FRAMES_LEFT RATE: the frames this run may have so
# that RUNS_LEFT runs of, in all, FRAMES_LEFT frames at RATE ms a frame (each
# with its start-up) fit what is left of the budget, at most WANT; at least
# one, so that early runs are not starved by estimates that later runs
# correct; and no more than this run alone can finish (0: do not start it).
plan_frames() {
    awk -v want="$1" -v runs="$2" -v total="$3" -v rate="$4" -v left="$(($(left_ms) - margin_ms))" \
        -v start="$startup_ms" 'BEGIN {
        s = (total * rate > 0) ? (left - runs * start) / (total * rate) : 1
        if (s > 1) s = 1
        f = int(want * s)
        if (f < 1) f = 1
        alone = (rate > 0) ? int((left - start) / rate) : want
        if (f > alone) f = alone
        if (f < 0) f = 0
        print f
    }'
}
# run_tileworld RUNS_LEFT LOG OUTDIR ARGS...: runs with a timeout of twice
# its share of the budget left (RUNS_LEFT runs, this one included; at least a
# minute, at most all that is left): a scene far slower than the ones it was
# planned from (heavy tiles on a software renderer: 17 s a frame) is cut
# there instead of starving every run after it. Sets rc (the exit status)
# and ms (the milliseconds taken).
run_tileworld() {
    local runs=$1 log=$2 dir=$3 t limit left
    shift 3
    left=$(($(left_ms) / 1000))
    limit=$((2 * left / (runs > 0 ? runs : 1)))
    [ "$limit" -ge 60 ] || limit=60
    [ "$limit" -le "$left" ] || limit=$left
    [ "$limit" -ge 1 ] || limit=1
    commands+=("$(quote tileworld "$@" --out "$dir")")
    rm -rf "${dir:?}"
    t=$(now_ms)
    rc=0
    timeout -k 5 "$limit" "$bin" "$@" --out "$dir" >"$log" 2>&1 || rc=$?
    ms=$(($(now_ms) - t))
}

# scene I: sets name, tileset, path, vd and args (the bench's, less
# --frames and --out) of scenes[I].
scene() {
    local more
    IFS='|' read -r name tileset path vd more <<<"${scenes[$1]}"
    [[ $tileset == @* ]] && tileset=$data/${tileset#@}
    local -a extra=()
    read -r -a extra <<<"$more"
    args=(bench --tileset "$tileset" --path "$path" ${vd:+--view-distance "$vd"} "${extra[@]}"
        --methods "$methods" --size "$size" --png-every 0 --quiet "${gl_args[@]}")
}

# A long suite's first scene is timed over a few frames first, so that the
# first full run is planned like the others: a slow renderer (a software
# fallback) then finishes within the budget, with fewer frames, and says so.
probe_frames=10
probed="none (the first scene ran in full and timed the others)"
if [ "$frames" -gt $((2 * probe_frames)) ]; then
    scene 0
    run_tileworld $((2 * ${#scenes[@]})) "$out/probe.log" "$work/probe" "${args[@]}" --frames "$probe_frames"
    if [ "$rc" -eq 0 ]; then
        rate[probe]=$(fdiv $((ms > startup_ms ? ms - startup_ms : 1)) "$probe_frames")
    fi
    note "probe: $name, $probe_frames frames in $(secs "$ms") s, exit $rc"
    probed="$name, $probe_frames frames in $(secs "$ms") s, exit $rc (probe.log)"
fi

names=()
for i in "${!scenes[@]}"; do
    scene "$i"
    names+=("$name")
    if [ ${#rate[@]} -eq 0 ]; then
        f=$frames           # timed in full: the others are planned from it
    else
        r=$(mean_rate)
        nb=$((${#scenes[@]} - i)) ns=${#scenes[@]}
        total=$(awk -v nb="$nb" -v f="$frames" -v ns="$ns" -v v="$verify_frames" -v k="$verify_factor" \
            'BEGIN { print nb * f + ns * v * k }')
        f=$(plan_frames "$frames" $((nb + ns)) "$total" "$r")
    fi
    b_frames[$name]=$f
    if [ "$f" -lt 1 ]; then
        b_rc[$name]=skipped
        note "$name: bench not run (budget)"
        continue
    fi
    run_tileworld $((2 * ${#scenes[@]} - i)) "$out/$name.log" "$out/$name" "${args[@]}" --frames "$f"
    b_rc[$name]=$rc b_ms[$name]=$ms
    if [ "$rc" -eq 0 ]; then
        rate[$name]=$(fdiv $((ms > startup_ms ? ms - startup_ms : 1)) "$f")
        unset 'rate[probe]'
    fi
    note "$name: bench $f frames in $(secs "$ms") s, exit $rc"
done

for i in "${!names[@]}"; do
    scene "$i"
    if [ "${b_rc[$name]}" != 0 ]; then
        v_rc[$name]=nobench v_frames[$name]=0
        continue
    elif [ "$verify_frames" -eq 0 ]; then
        v_rc[$name]=skipped v_frames[$name]=0
        continue
    fi
    nv=$((${#names[@]} - i))
    r=$(awk -v r="${rate[$name]}" -v k="$verify_factor" 'BEGIN { printf "%.6f", r * k }')
    f=$(plan_frames "$verify_frames" "$nv" $((nv * verify_frames)) "$r")
    v_frames[$name]=$f
    if [ "$f" -lt 1 ]; then
        v_rc[$name]=skipped
        note "$name: verify not run (budget)"
        continue
    fi
    run_tileworld "$nv" "$out/$name-verify.log" "$out/$name-verify" "${args[@]}" --verify --allow-missed --frames "$f"
    v_rc[$name]=$rc v_ms[$name]=$ms
    if [ "$rc" -eq 0 ]; then
        verify_factor=$(awk -v ms="$ms" -v s="$startup_ms" -v f="$f" -v r="${rate[$name]}" \
            'BEGIN { k = (ms > s ? ms - s : 1) / f / r; printf "%.3f", (k < 1 ? 1 : k) }')
    fi
    note "$name: verify $f frames in $(secs "$ms") s, exit $rc"
done

# ---- the report ---------------------------------------------------------------
# The table's rows of one scene, from its bench's and its verify run's
# frames.csv: columns found by their header names; gpu_ms is optional, -1
# when unknown.
table_awk='
BEGIN { FS = ","; nm = split(methods, order, ",") }
FNR == 1 {
    file++
    delete col
    for (i = 1; i <= NF; i++) col[$i] = i
    split("method ms_frame cpu_ms triangles queries draws missed_pixels", need, " ")
    for (k in need)
        if (!(need[k] in col)) { print "frames.csv has no column " need[k] > "/dev/stderr"; bad = 1; exit 1 }
    gcol = ("gpu_ms" in col) ? col["gpu_ms"] : 0
    next
}
file == 1 {
    m = $col["method"]; n[m]++
    wall[m] += $col["ms_frame"]; cpu[m] += $col["cpu_ms"]
    tri[m] += $col["triangles"]; q[m] += $col["queries"]; dr[m] += $col["draws"]
    if (gcol && $gcol >= 0) { gpu[m] += $gcol; gn[m]++ }
}
file == 2 { m = $col["method"]; vn[m]++; miss[m] += $col["missed_pixels"] }
function ratio(a, b) { return (b > 0 && a != "") ? sprintf("%.3f", a / b) : "n/a" }
function mean_gpu(m) { return gn[m] ? gpu[m] / gn[m] : "" }
END {
    if (bad) exit 1
    for (k = 1; k <= nm; k++) {
        m = order[k]
        if (!n[m]) { printf "| %s | %s | not in frames.csv |\n", scene, m; continue }
        w = wall[m] / n[m]; g = mean_gpu(m)
        if (!verified) mp = "-"
        else if (!vn[m]) mp = "not in frames.csv"
        else {
            mp = miss[m]
            if (miss[m] > 0 && m !~ /hzb/) { mp = "**" mp "**"; printf "%s %s %d\n", name, m, miss[m] >> failfile }
        }
        vw = n["vfc"] ? wall["vfc"] / n["vfc"] : 0
        bw = n["box-oracle"] ? wall["box-oracle"] / n["box-oracle"] : 0
        ow = n["oracle"] ? wall["oracle"] / n["oracle"] : 0
        printf "| %s | %s | %s | %.3f | %.3f | %s | %.0f | %.1f | %.1f | %s | %s | %s | %s | %s | %s | %s | %s |\n",
            scene, m, fr, w, cpu[m] / n[m], (g == "" ? "n/a" : sprintf("%.3f", g)),
            tri[m] / n[m], q[m] / n[m], dr[m] / n[m], mp, vfr,
            ratio(w, vw), ratio(w, bw), ratio(w, ow),
            ratio(g, mean_gpu("vfc")), ratio(g, mean_gpu("box-oracle")), ratio(g, mean_gpu("oracle"))
    }
}'

# frames_cell GOT WANT RC: what the table says of a run's frames.
frames_cell() {
    case $3 in
    0) [ "$1" -eq "$2" ] && echo "$1" || echo "$1 of $2 (budget)" ;;
    skipped) [ "$2" -eq 0 ] && echo "none asked" || echo "not run (budget)" ;;
    nobench) echo "not run (no bench)" ;;
    124 | 137) echo "killed at the budget ($1 frames)" ;;
    *) echo "failed (exit $3)" ;;
    esac
}

failures=()
: >"$work/missed"
rows=$work/rows
: >"$rows"
for i in "${!names[@]}"; do
    name=${names[$i]}
    IFS='|' read -r _ tileset path vd <<<"${scenes[$i]}"
    scene="${tileset##*/}"
    scene="${scene%.json}/$path${vd:+ (view ${vd} m)}"
    if [ "${b_rc[$name]}" != 0 ]; then
        echo "| $scene | all | $(frames_cell "${b_frames[$name]}" "$frames" "${b_rc[$name]}") |" >>"$rows"
        [ "${b_rc[$name]}" = skipped ] || failures+=("$name: bench exit ${b_rc[$name]} (see $name.log)")
        continue
    fi
    vcsv=/dev/null verified=0
    if [ "${v_rc[$name]}" = 0 ]; then
        vcsv=$out/$name-verify/frames.csv verified=1
    elif [ "${v_rc[$name]}" != skipped ]; then
        failures+=("$name: verify exit ${v_rc[$name]} (see $name-verify.log)")
    fi
    awk -v methods="$methods" -v scene="$scene" -v name="$name" -v verified="$verified" \
        -v fr="$(frames_cell "${b_frames[$name]}" "$frames" 0)" \
        -v vfr="$(frames_cell "${v_frames[$name]}" "$verify_frames" "${v_rc[$name]}")" \
        -v failfile="$work/missed" "$table_awk" "$out/$name/frames.csv" "$vcsv" >>"$rows" ||
        failures+=("$name: its frames.csv could not be read")
done
while read -r s m px; do
    failures+=("$s: $m missed $px pixels under --verify")
done <"$work/missed"

# The renderer, from the first summary.json that has a "run" object.
json_field() {
    sed -n 's/^ *"'"$1"'": "\(.*\)",\{0,1\}$/\1/p; s/^ *"'"$1"'": \([a-z0-9.]*\),\{0,1\}$/\1/p' "$2" |
        sed -n '1{s/\\\//\//g; s/\\"/"/g; p}'
}
renderer="unknown: no summary.json with a \"run\" object (a build before it was added)"
for name in "${names[@]}"; do
    s=$out/$name/summary.json
    if [ -f "$s" ] && grep -q '"gl_renderer"' "$s"; then
        renderer="$(json_field gl_renderer "$s") ($(json_field gl_vendor "$s"), GL $(json_field gl_version "$s"))"
        renderer+=" through $(json_field context "$s"); software renderer: $(json_field software "$s");"
        renderer+=" $(json_field build_type "$s") build of $(json_field commit "$s")"
        [ "$(json_field software "$s")" != true ] || renderer+=" (**software: not a GPU's figures**)"
        break
    fi
done
used_ms=$(($(now_ms) - t_start))

{
    echo "# tileworld GPU bench"
    echo
    echo "- renderer: $renderer"
    echo "- calibration: $(grep -m1 '^OpenGL:' "$out/calibrate.txt" || echo 'no OpenGL line') (calibrate.txt, $(secs "$cal_ms") s)"
    echo "- command: \`$command_line\`"
    echo "- runs: \`tileworld bench --tileset T --path P [--view-distance M] --methods $methods --size $size --frames N --png-every 0 --quiet ${gl_args[*]} --out OUT/NAME\`, then the same with \`--verify --allow-missed\` into OUT/NAME-verify (each command below)"
    echo "- budget: ${budget_s} s, used $((used_ms / 1000)) s; $frames frames a method, $verify_frames under --verify, cut to fit where the frames column says so; probe: $probed; glvnd sysroot: $sysroot_used (setup.txt)"
    echo
    echo "Means over each method's frames (the first included). gpu ms: the GPU's time of the frame's own work (gpu_ms, n/a where unknown). missed px: pixels missed in the --verify run (its frames in the next column); only the hzb methods may miss pixels."
    echo
    echo "| scene | method | frames | wall ms | cpu ms | gpu ms | triangles | queries | draws | missed px | verify frames | wall / vfc | wall / box-oracle | wall / oracle | gpu / vfc | gpu / box-oracle | gpu / oracle |"
    echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    cat "$rows"
    echo
    if [ ${#failures[@]} -gt 0 ]; then
        echo "## Failures"
        echo
        printf -- '- %s\n' "${failures[@]}"
        echo
    fi
    echo "## Commands"
    echo
    for i in "${!names[@]}"; do
        name=${names[$i]}
        echo "- $name: bench frames $(frames_cell "${b_frames[$name]}" "$frames" "${b_rc[$name]}"), $(secs "${b_ms[$name]:-0}") s; verify frames $(frames_cell "${v_frames[$name]}" "$verify_frames" "${v_rc[$name]}"), $(secs "${v_ms[$name]:-0}") s"
    done
    echo
    echo '```'
    printf '%s\n' "$(quote "${cal_cmd[@]}")" "${commands[@]}"
    echo '```'
} >"$out/gpu-bench.md"

note "wrote $out/gpu-bench.md ($((used_ms / 1000)) s of ${budget_s} s)"
if [ ${#failures[@]} -gt 0 ]; then
    printf 'gpu-bench: FAILED: %s\n' "${failures[@]}" >&2
    exit 1
fi
