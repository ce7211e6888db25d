#!/usr/bin/env bash
# tileworld as a meson subproject (suite gl): configures and builds the host
# project of tests/subproject-host/ in a temporary folder, with
# subprojects/tileworld a link to this source tree, and checks that
#  - it builds and its host program (examples/host.c) runs;
#  - the subproject registers no test and builds no program: only libraries
#    (and the headers they are compiled with);
#  - switching the subproject to static libraries (-Dtileworld:default_library=static)
#    links the host without libtileworld.so, and it still runs.
#
# usage: test-subproject.sh SOURCE_DIR
# environment: MESON, NINJA (commands, may hold arguments); CC, CXX are
# passed on to meson setup.
set -u
srcdir=$1
read -r -a meson <<<"${MESON:-meson}"
read -r -a ninja <<<"${NINJA:-ninja}"
command -v python3 >/dev/null || { echo "SKIP: python3 not found (to read meson's introspection)"; exit 77; }

tmp=$(mktemp -d "${TMPDIR:-/tmp}/tw-subproject.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
host=$tmp/host build=$tmp/build
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

mkdir -p "$host/subprojects"
cp "$srcdir/tests/subproject-host/meson.build" "$srcdir/examples/host.c" "$host/"
ln -s "$srcdir" "$host/subprojects/tileworld"

# forcefallback: the subproject, even where a tileworld.pc is installed.
if ! "${meson[@]}" setup --wrap-mode=forcefallback "$build" "$host" >"$tmp/setup.log" 2>&1; then
    cat "$tmp/setup.log"
    echo "FAIL: meson setup of the host project failed"
    exit 1
fi
if ! "${ninja[@]}" -C "$build" >"$tmp/ninja.log" 2>&1; then
    tail -n 40 "$tmp/ninja.log"
    echo "FAIL: the host project does not build"
    exit 1
fi

run_host() {
    if [ ! -x "$build/host" ]; then
        fail "$1: no host program in the build folder"
    elif ! "$build/host" >"$tmp/run.log" 2>&1; then
        cat "$tmp/run.log"
        fail "$1: the host program failed"
    fi
}
run_host "shared"

# ---- nothing of tileworld but its libraries ----
"${meson[@]}" test -C "$build" --list --no-rebuild >"$tmp/tests" 2>"$tmp/tests.err" ||
    { cat "$tmp/tests.err"; fail "meson test --list failed in the host build"; }
grep -qx 'host' "$tmp/tests" || fail "the host's own test is not listed: $(tr '\n' ' ' <"$tmp/tests")"
if grep -q '^tileworld' "$tmp/tests"; then
    fail "the subproject registers tests: $(grep '^tileworld' "$tmp/tests" | tr '\n' ' ')"
fi

python3 - "$build/meson-info/intro-targets.json" >"$tmp/targets" <<'EOF' || fail "cannot read the host build's targets"
import json, sys
for t in json.load(open(sys.argv[1])):
    if t.get("subproject") == "tileworld":
        kind = t["type"].replace(" ", "-")
        # A custom target that makes only headers is a step of a library's build.
        if kind == "custom" and all(f.endswith(".h") for f in t.get("filename", [])):
            kind = "generated-header"
        print(kind, t["name"])
EOF
grep -q '^shared-library tileworld$' "$tmp/targets" || fail "the subproject defines no shared library tileworld"
grep -q '^shared-library tileworld-headless$' "$tmp/targets" || fail "the subproject defines no shared library tileworld-headless"
while read -r type name; do
    case "$type" in
        *library | generated-header) ;;
        *) fail "the subproject defines $type $name: only libraries belong in a host's build" ;;
    esac
    case "$name" in
        header-check*) fail "the subproject builds the header checks ($name): they are tests" ;;
    esac
done <"$tmp/targets"
# And on disk: no program of tileworld's was built.
progs=$(find "$build/subprojects" -type f -perm -u+x ! -name '*.so' ! -name '*.so.*' 2>/dev/null)
[ -z "$progs" ] || fail "programs built in the subproject: $progs"

# ---- the same host with tileworld static ----
if ! "${meson[@]}" configure "$build" -Dtileworld:default_library=static >"$tmp/conf.log" 2>&1; then
    cat "$tmp/conf.log"
    fail "meson configure -Dtileworld:default_library=static failed"
elif ! "${ninja[@]}" -C "$build" >"$tmp/ninja.log" 2>&1; then
    tail -n 40 "$tmp/ninja.log"
    fail "the host project does not build with tileworld static"
else
    if readelf -d "$build/host" | grep -q 'NEEDED.*libtileworld'; then
        fail "static: the host still needs a shared libtileworld"
    fi
    run_host "static"
fi

[ $failures -eq 0 ] || exit 1
echo "ok: host built with tileworld as a subproject, shared and static; no tileworld test or program"
