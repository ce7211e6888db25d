#!/usr/bin/env bash
# Library hygiene (suite unit), read from the built files with nm:
#  - the runtime module (runtime/libtw-runtime.a, runtime/libtw-headless.a)
#    references no json-c, no libpng and nothing that spawns a process, and
#    libtileworld.so / libtileworld-headless.so nothing that spawns a process
#    (DESIGN.md §2: that is tools/' business);
#  - libtileworld.so and libtileworld-headless.so export exactly the public
#    API: every symbol they export is declared in include/tileworld/*.h, and
#    every function and object declared there is exported by one of them
#    (else a host gets a link error), by one only, functions as code and
#    objects as data;
#  - the public API is the pinned list PINNED (tests/public-api.txt): a
#    function added to or removed from the headers is a change to that file
#    too, seen in review.
#
# usage: test-symbols.sh INCLUDE_DIR PUBLIC_API_SH PINNED RUNTIME_ARCHIVE... -- [LIBTILEWORLD_SO LIBTILEWORLD_HEADLESS_SO]
# (no shared libraries in a -Ddefault_library=static build: then only the
# archives are checked)
# environment: NM, CC (commands, may hold arguments)
set -u
inc=$1 public_api=$2 pinned=$3
shift 3
archives=()
while [ $# -gt 0 ] && [ "$1" != -- ]; do archives+=("$1"); shift; done
shift
world_so=${1:-} headless_so=${2:-}
read -r -a nm <<<"${NM:-nm}"
command -v "${nm[0]}" >/dev/null || { echo "SKIP: ${nm[0]} not found"; exit 77; }

tmp=$(mktemp -d "${TMPDIR:-/tmp}/tw-symbols.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# Spawning a process: fork, the exec family, posix_spawn*, system, popen.
spawn_re='^(v?fork|exec(l|lp|le|v|vp|vpe|ve)|fexecve|posix_spawnp?|posix_spawn_.*|system|popen)$'

# ---- the runtime archives: nm -u -A prints "archive:member: U symbol" ----
for a in "${archives[@]}"; do
    if ! "${nm[@]}" -u -A "$a" >"$tmp/undef" 2>"$tmp/nm.err"; then
        cat "$tmp/nm.err"; fail "nm cannot read $a"; continue
    fi
    [ -s "$tmp/undef" ] || fail "$a: nm lists no undefined symbol at all (not an archive of objects?)"
    while read -r where sym; do
        case "$sym" in
            json_*) fail "${where%:} references $sym: the runtime links no json-c" ;;
            png_*) fail "${where%:} references $sym: the runtime links no libpng" ;;
            *) [[ $sym =~ $spawn_re ]] && fail "${where%:} references $sym: the runtime spawns no process" ;;
        esac
    done < <(awk '$(NF-1) == "U" { print $1, $NF }' "$tmp/undef")
done

if [ -z "$world_so" ]; then
    [ $failures -eq 0 ] || exit 1
    echo "ok: ${#archives[@]} runtime archives clean; no shared libraries in this build: exports not checked"
    exit 0
fi

# ---- the shared libraries ----
# "TYPE NAME" of each defined dynamic symbol, version suffix dropped.
exports() {
    "${nm[@]}" -D --defined-only "$1" | awk 'NF >= 3 { sub(/@.*/, "", $3); print $2, $3 }'
}
for so in "$world_so" "$headless_so"; do
    "${nm[@]}" -D -u "$so" | awk '{ sub(/@.*/, "", $NF); print $NF }' >"$tmp/undef" ||
        fail "nm -D cannot read $so"
    while read -r sym; do
        [[ $sym =~ $spawn_re ]] && fail "${so##*/} references $sym: the library spawns no process"
    done <"$tmp/undef"
done

if ! bash "$public_api" "$inc" >"$tmp/api"; then
    echo "FAIL: cannot list the public API of $inc/tileworld"
    exit 1
fi
# A broken extraction must not pass for an empty API.
n_api=$(wc -l <"$tmp/api")
[ "$n_api" -ge 50 ] || fail "only $n_api declarations found in $inc/tileworld: the extraction is broken"
grep -q '^func tw_world_create$' "$tmp/api" || fail "tw_world_create not found among the declarations"
if ! diff -u "$pinned" "$tmp/api" >"$tmp/pin.diff"; then
    fail "the public API differs from the pinned list $pinned (- pinned, + declared):"
    sed -n '3,$p' "$tmp/pin.diff"
fi

exports "$world_so" >"$tmp/world" || fail "nm -D cannot read $world_so"
exports "$headless_so" >"$tmp/headless" || fail "nm -D cannot read $headless_so"
declare -A kind owner
while read -r k name; do kind[$name]=$k; done <"$tmp/api"
for lib in world headless; do
    so_name=libtileworld.so
    [ $lib = headless ] && so_name=libtileworld-headless.so
    while read -r type name; do
        if [ -z "${kind[$name]:-}" ]; then
            fail "$so_name exports $name ($type), which no public header declares"
            continue
        fi
        if [ -n "${owner[$name]:-}" ]; then
            fail "$name is exported by both ${owner[$name]} and $so_name"
        fi
        owner[$name]=$so_name
        case "${kind[$name]}:$type" in
            func:[TWi] | data:[DRBVG]) ;;
            *) fail "$so_name exports $name as type $type, but the header declares it as ${kind[$name]}" ;;
        esac
    done <"$tmp/$lib"
done
while read -r k name; do
    [ -n "${owner[$name]:-}" ] ||
        fail "$name ($k) is declared in a public header but exported by neither library: a host gets a link error"
done <"$tmp/api"
# The headless context is its own library, and only it.
for name in "${!owner[@]}"; do
    case "$name" in
        tw_context_*) [ "${owner[$name]}" = libtileworld-headless.so ] ||
            fail "$name is exported by ${owner[$name]}, not by libtileworld-headless.so" ;;
        *) [ "${owner[$name]}" = libtileworld.so ] ||
            fail "$name is exported by ${owner[$name]}, not by libtileworld.so" ;;
    esac
done

[ $failures -eq 0 ] || exit 1
echo "ok: ${#archives[@]} runtime archives clean; $n_api public symbols, all exported, nothing else"
