#!/usr/bin/env bash
# Packs what scripts/gpu-bench.sh needs to run on a machine that has a GPU
# driver and nothing else of ours (no package registry, no Debian packages):
# a release tileworld, the shared libraries it links that glibc and the
# compiler's runtime do not provide (Embree gzipped), the tileset folders the
# suite loads, and Debian 12's glvnd loader packages (libEGL.so.1 and its
# kin, which tileworld opens at run time).
#   scripts/gpu-pack.sh [--out DIR]        (default: pack/ in the repository)
set -euo pipefail

die() { echo "gpu-pack: $*" >&2; exit 1; }
usage() { echo "usage: scripts/gpu-pack.sh [--out DIR]" >&2; exit 2; }

root=$(cd "$(dirname "$0")/.." && pwd)
out=$root/pack
while [ $# -gt 0 ]; do
    case $1 in
    --out) [ $# -ge 2 ] || usage; out=$2; shift 2 ;;
    --out=*) out=${1#--out=}; shift ;;
    -h | --help) usage ;;
    *) die "unknown option '$1'" ;;
    esac
done
[ -n "$out" ] || die "--out needs a folder"
# The carry limit of the GPU machine's working-tree copy is 64 MiB in all.
max_bytes=$((60 * 1024 * 1024))
marker=PACK.txt
tilesets=(kenney-city cesium-buildings)
debs=(libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)

for tool in meson ninja readelf ldd gzip apt-get; do
    command -v "$tool" >/dev/null || die "$tool is not installed"
done

# ---- the release build ----------------------------------------------------------
build=$root/build-release
opts=(-Dbuildtype=release -Dtests=disabled -Dviewer=disabled)
if [ -f "$build/build.ninja" ]; then
    meson configure "$build" "${opts[@]}" >/dev/null || die "meson configure $build failed"
else
    meson setup "$build" "${opts[@]}" >/dev/null || die "meson setup $build failed"
fi
if ! ninja -C "$build" tools/tileworld >"$build/gpu-pack-ninja.log" 2>&1; then
    tail -n 20 "$build/gpu-pack-ninja.log" >&2
    die "ninja -C $build failed (log: $build/gpu-pack-ninja.log)"
fi
bin=$build/tools/tileworld
[ -x "$bin" ] || die "$bin was not built"

# ---- the folder -----------------------------------------------------------------
# Only a folder this script made is emptied: --out could name anything.
if [ -e "$out" ]; then
    [ -d "$out" ] || die "$out exists and is not a folder"
    if [ -n "$(ls -A "$out")" ] && [ ! -f "$out/$marker" ]; then
        die "$out is not empty and holds no $marker: not a pack, left alone"
    fi
    rm -rf "$out"
fi
mkdir -p "$out/bin" "$out/lib" "$out/tilesets" "$out/debs"
out=$(cd "$out" && pwd)
cp "$bin" "$out/bin/tileworld"

# ---- shared libraries -----------------------------------------------------------
# Left out: what every Linux machine has (glibc, the C++ and GCC runtimes)
# and the GL stack, which must be the machine's own (the driver's vendor
# libraries; OSMesa is too big to carry and the GPU machine uses EGL).
skip_re='^(linux-vdso|ld-linux[^ ]*|libc|libm|libdl|libpthread|librt|libresolv|libutil|libstdc\+\+|libgcc_s|libOSMesa|libGL|libGLX|libGLdispatch|libEGL|libOpenGL|libGLESv[12]_CM|libGLESv2|libglapi|libgbm|libdrm|libX[^ ]*|libxcb[^ ]*)\.so'
needed() { readelf -d "$1" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'; }
# resolved FILE: "SONAME PATH" for each library ldd finds for FILE.
resolved() { ldd "$1" | awk '$2 == "=>" && $3 ~ /^\// { print $1, $3 }'; }

declare -A packed=()
add_lib() {
    local name=$1 path=$2
    [[ $name =~ $skip_re ]] && return 0
    [ -n "${packed[$name]:-}" ] && return 0
    packed[$name]=$path
    local dep dpath
    while read -r dep dpath; do
        add_lib "$dep" "$dpath"
    done < <(resolved "$path")
}
declare -A where=()
while read -r name path; do where[$name]=$path; done < <(resolved "$bin")
while read -r name; do
    [[ $name =~ $skip_re ]] && continue
    [ -n "${where[$name]:-}" ] || die "ldd does not find $name, which $bin needs"
    add_lib "$name" "${where[$name]}"
done < <(needed "$bin")
for name in "${!packed[@]}"; do
    case $name in
    libembree3.so*) gzip -9 -n -c "${packed[$name]}" >"$out/lib/$name.gz" ;;
    *) cp -L "${packed[$name]}" "$out/lib/$name" ;;
    esac
done
[ -f "$out/lib/libembree3.so.3.gz" ] || die "$bin does not link libembree3.so.3: not the build this script knows"

# ---- tilesets -------------------------------------------------------------------
for t in "${tilesets[@]}"; do
    [ -d "$root/tilesets/$t" ] || die "tilesets/$t is missing"
    cp -r "$root/tilesets/$t" "$out/tilesets/$t"
done

# ---- glvnd's loader, as Debian 12 packages --------------------------------------
fetch=$(mktemp -d)
trap 'rm -rf "$fetch"' EXIT
# apt's sandbox user cannot write into a private temporary folder.
download() { (cd "$fetch" && apt-get -q download -o APT::Sandbox::User=root "${debs[@]}") >"$fetch/log" 2>&1; }
if ! download; then
    apt-get -q update >/dev/null 2>&1 || die "apt-get update failed (needed to download ${debs[*]})"
    download || die "apt-get download ${debs[*]} failed: $(tail -n 1 "$fetch/log")"
fi
for d in "${debs[@]}"; do
    ls "$fetch/${d}_"*.deb >/dev/null 2>&1 || die "apt-get download did not fetch $d"
done
mv "$fetch"/*.deb "$out/debs/"

# ---- what is in it --------------------------------------------------------------
commit=$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)
if [ "$commit" != unknown ] && [ -n "$(git -C "$root" status --porcelain --untracked-files=no 2>/dev/null)" ]; then
    commit="$commit (with uncommitted changes)"
fi
{
    echo "tileworld GPU pack (scripts/gpu-pack.sh; run it with scripts/gpu-bench.sh --pack DIR)"
    echo "commit: $commit"
    echo "made: $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(uname -srm)"
    echo
    (cd "$out" && find . -type f ! -name "$marker" -printf '%s\t%P\n' | sort -k2)
} >"$out/$marker"

bytes=$(du -sb "$out" | awk '{ print $1 }')
mib=$(awk -v b="$bytes" 'BEGIN { printf "%.1f", b / 1048576 }')
echo "gpu-pack: $out: $mib MiB ($bytes bytes): bin/tileworld, lib/ (${!packed[*]}), tilesets/ (${tilesets[*]}), debs/ (${debs[*]})"
[ "$bytes" -le "$max_bytes" ] || die "$out is $mib MiB, over the 60 MiB limit"
