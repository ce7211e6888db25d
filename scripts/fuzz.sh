#!/usr/bin/env bash
# Fuzzes one target with libFuzzer for a fixed time:
#
#   scripts/fuzz.sh TARGET SECONDS      TARGET: gltf, manifest, frame, path or glb3d
#
# Configures build-fuzz/ once with clang, libFuzzer, AddressSanitizer and
# UndefinedBehaviorSanitizer (the C++ shim instrumented too), builds only the
# target, and runs it over its seed corpus. New inputs go to
# build-fuzz/fuzz-corpus/TARGET (kept between runs), crashes, leaks, hangs
# and out-of-memory inputs to build-fuzz/fuzz-artifacts/TARGET/; copy a
# finding into tests/corpus/TARGET/ once it is fixed: the unit suite replays
# that folder. Prints libFuzzer's final line (execs/s, cov, ft) at the end.
# Debian 12 packages: clang libclang-rt-14-dev (libFuzzer and the sanitizer
# runtimes), plus the project's usual build dependencies.
# Environment: TW_SHARED_DIR (default ../shared, the test assets),
# TW_FUZZ_BUILD (default build-fuzz), TW_FUZZ_JOBS (default 1; more: libFuzzer's -fork mode).
set -euo pipefail

if [ $# -ne 2 ] || ! [[ $2 =~ ^[0-9]+$ ]]; then
    echo "usage: $0 gltf|manifest|frame|path|glb3d SECONDS" >&2
    exit 2
fi
target=$1
seconds=$2
cd "$(dirname "$0")/.."
root=$PWD
shared=${TW_SHARED_DIR:-$root/../shared}
build=${TW_FUZZ_BUILD:-build-fuzz}
jobs=${TW_FUZZ_JOBS:-1}

seeds=()
add_seed() { if [ -e "$1" ]; then seeds+=("$1"); fi; }
case $target in
gltf | frame)
    add_seed "$root/tests/corpus/$target"
    add_seed "$shared/assets/bad"
    add_seed "$shared/assets/models"
    max_len=262144
    ;;
manifest)
    add_seed "$root/tests/corpus/manifest"
    # libFuzzer takes folders: the shipped manifests are copied into one
    # once build-fuzz/ exists (below).
    seeds+=("$build/fuzz-seeds/manifest")
    max_len=65536
    ;;
path)
    add_seed "$root/tests/corpus/path"
    max_len=16384
    ;;
glb3d)
    # Small synthetic tiles, one baked cell whole (hence max_len) and
    # broken variants.
    add_seed "$root/tests/corpus/glb3d"
    max_len=524288
    ;;
*)
    echo "$0: unknown target $target (gltf, manifest, frame, path, glb3d)" >&2
    exit 2
    ;;
esac
if [ ${#seeds[@]} -eq 0 ]; then
    echo "$0: no seed corpus for $target" >&2
    exit 1
fi
for tool in clang clang++ meson ninja; do
    command -v "$tool" >/dev/null || {
        echo "$0: $tool not found (apt-get install clang libclang-rt-14-dev meson ninja-build)" >&2
        exit 1
    }
done

if [ ! -f "$build/build.ninja" ]; then
    flags=-fsanitize=fuzzer-no-link,address,undefined
    CC=clang CXX=clang++ meson setup "$build" -Dc_args=$flags -Dcpp_args=$flags \
        -Db_lundef=false -Dviewer=disabled >/dev/null
fi
ninja -C "$build" "tests/fuzz-$target" >/dev/null
if [ "$target" = manifest ]; then
    mkdir -p "$build/fuzz-seeds/manifest"
    cp "$root"/tilesets/*/*.json "$build/fuzz-seeds/manifest/"
fi

corpus=$build/fuzz-corpus/$target
artifacts=$build/fuzz-artifacts/$target
mkdir -p "$corpus" "$artifacts"
log=$build/fuzz-$target.log
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$root/tests/lsan.supp}
parallel=()
if [ "$jobs" -gt 1 ]; then
    parallel=(-fork="$jobs")
fi
status=0
"$build/tests/fuzz-$target" -max_total_time="$seconds" -max_len="$max_len" -timeout=25 \
    -rss_limit_mb=2048 -print_final_stats=1 "${parallel[@]}" \
    -artifact_prefix="$artifacts/" "$corpus" "${seeds[@]}" >"$log" 2>&1 || status=$?
grep -E '^#[0-9]+[[:space:]]+(INITED|DONE)' "$log" | tail -n 2 || true
grep -E 'stat::' "$log" || true
if [ "$status" -ne 0 ]; then
    echo "$0: $target found something (exit $status): see $log and $artifacts/" >&2
    grep -E 'ERROR|SUMMARY|runtime error' "$log" | head -n 5 >&2 || true
fi
exit "$status"
