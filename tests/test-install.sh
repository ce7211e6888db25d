#!/usr/bin/env bash
# tileworld as a host gets it from `meson install` (suite gl): installs the
# build into a temporary DESTDIR, checks the installed tree, compiles every
# installed header alone as C and as C++, and builds examples/host.c, and a
# program that takes the address of every public function and object, with
# pkg-config against the installed files, shared and static, and runs them.
# A host runs without LD_LIBRARY_PATH: the .pc files give an rpath to their
# libdir when the dynamic loader does not search it by itself, and the
# headless library finds libtileworld through $ORIGIN.
#
# usage: test-install.sh BUILD_DIR SOURCE_DIR VERSION PUBLIC_API_SH DEFAULT_LIBRARY
# (DEFAULT_LIBRARY: the build's default_library, both by default: which kinds
# of library to expect)
# environment: MESON, PKG_CONFIG, CC, CXX (commands, may hold arguments);
# HOST_CFLAGS: flags a host needs to link this build (its sanitizers)
set -u
builddir=$1 srcdir=$2 version=$3 public_api=$4 default_library=$5
kinds=()
[ "$default_library" != static ] && kinds+=(shared)
[ "$default_library" != shared ] && kinds+=(static)
[ "$default_library" = both ] ||
    echo "note: default_library=$default_library: only ${kinds[*]} libraries are checked (the default is both)"
read -r -a meson <<<"${MESON:-meson}"
read -r -a pkgconfig <<<"${PKG_CONFIG:-pkg-config}"
read -r -a cc <<<"${CC:-cc}"
read -r -a cxx <<<"${CXX:-c++}"
read -r -a hostflags <<<"${HOST_CFLAGS:-}"

for tool in readelf ldd "${cxx[0]}"; do
    command -v "$tool" >/dev/null || { echo "SKIP: $tool not found"; exit 77; }
done

tmp=$(mktemp -d "${TMPDIR:-/tmp}/tw-install.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
root=$tmp/root
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

# ---- install ----
if ! "${meson[@]}" install -C "$builddir" --destdir "$root" --no-rebuild --quiet \
        >"$tmp/install.log" 2>&1; then
    cat "$tmp/install.log"
    echo "FAIL: meson install --destdir failed"
    exit 1
fi

mapfile -t pcs < <(find "$root" -name tileworld.pc)
if [ ${#pcs[@]} -ne 1 ]; then
    echo "FAIL: expected one installed tileworld.pc, found ${#pcs[@]}"
    exit 1
fi
pcdir=$(dirname "${pcs[0]}")
[ -f "$pcdir/tileworld-headless.pc" ] || fail "tileworld-headless.pc not installed beside tileworld.pc"

# pkg-config as it would run after a real install (paths without $root) ...
pc_plain() { PKG_CONFIG_PATH=$pcdir "${pkgconfig[@]}" "$@"; }
# ... and pointed at the DESTDIR: -I and -L flags get $root in front.
pc() { PKG_CONFIG_PATH=$pcdir PKG_CONFIG_SYSROOT_DIR=$root "${pkgconfig[@]}" "$@"; }

includedir=$(pc_plain --variable=includedir tileworld)
libdir=$(pc_plain --variable=libdir tileworld)
[ "$(pc_plain --modversion tileworld)" = "$version" ] || fail "tileworld.pc: version is not $version"
[ "$(pc_plain --modversion tileworld-headless)" = "$version" ] || fail "tileworld-headless.pc: version is not $version"
[ "$pcdir" = "$root$libdir/pkgconfig" ] || fail "tileworld.pc is in $pcdir, not in \$libdir/pkgconfig"

# ---- the installed tree ----
# Headers: the public ones, exactly, all under include/tileworld/ and
# nowhere else.
(cd "$srcdir/include/tileworld" && ls -- *.h) >"$tmp/headers.src"
if [ -d "$root$includedir/tileworld" ]; then
    (cd "$root$includedir/tileworld" && ls) >"$tmp/headers.inst"
else
    : >"$tmp/headers.inst"
fi
diff "$tmp/headers.src" "$tmp/headers.inst" >"$tmp/headers.diff" ||
    fail "installed headers differ from include/tileworld/ (< source, > installed): $(tr '\n' ' ' <"$tmp/headers.diff")"
others=$(cd "$root$includedir" 2>/dev/null && find . -mindepth 1 -maxdepth 1 ! -name tileworld)
[ -z "$others" ] || fail "more than tileworld/ installed in $includedir: $others"
stray=$(find "$root" \( -name '*.h' -o -name '*.hpp' \) ! -path "$root$includedir/tileworld/*")
[ -z "$stray" ] || fail "headers installed outside $includedir/tileworld: $stray"

# Libraries: shared (with its soname links) and static, for both.
for lib in tileworld tileworld-headless; do
    files=()
    [[ " ${kinds[*]} " = *" shared "* ]] && files+=("lib$lib.so" "lib$lib.so.0" "lib$lib.so.$version")
    [[ " ${kinds[*]} " = *" static "* ]] && files+=("lib$lib.a")
    for f in "${files[@]}"; do
        [ -e "$root$libdir/$f" ] || fail "$libdir/$f not installed"
    done
    so=$root$libdir/lib$lib.so.$version
    [ -f "$so" ] || continue
    readelf -d "$so" >"$tmp/dyn"
    grep -q "Library soname: \[lib$lib.so.0\]" "$tmp/dyn" || fail "lib$lib.so: soname is not lib$lib.so.0"
    if grep -E 'R(UN)?PATH' "$tmp/dyn" | grep -qF "$builddir"; then
        fail "lib$lib.so: an rpath into the build directory survived the install"
    fi
done
# runpath FILE: its RUNPATH and RPATH, their folders joined by colons.
runpath() { readelf -d "$1" | sed -n 's/.*(R\(UN\)\{0,1\}PATH).*\[\(.*\)\]$/\2/p' | paste -sd:; }
# The headless library finds libtileworld.so in its own folder, wherever the
# two are installed ($ORIGIN: a host's rpath does not reach the libraries'
# own needs). It needs libtileworld.so only when it calls into it: then the
# loader, without LD_LIBRARY_PATH, takes it from beside it.
so=$root$libdir/libtileworld-headless.so.$version
if [ -f "$so" ]; then
    readelf -d "$so" >"$tmp/dyn"
    case ":$(runpath "$so"):" in
        *':$ORIGIN:'* | *':${ORIGIN}:'*) ;;
        *) fail "libtileworld-headless.so: no \$ORIGIN in its RUNPATH ('$(runpath "$so")'), so it cannot find libtileworld.so beside it" ;;
    esac
    if grep -q 'NEEDED.*\[libtileworld\.so\.0\]' "$tmp/dyn"; then
        env -u LD_LIBRARY_PATH ldd "$so" >"$tmp/ldd" 2>&1
        grep -q "libtileworld.so.0 => $root$libdir/" "$tmp/ldd" ||
            fail "libtileworld-headless.so does not load libtileworld.so.0 from its own folder: $(grep libtileworld "$tmp/ldd")"
    fi
fi
# The world library links no GL: a program with a window loads libGL, the
# headless one OSMesa, and the two never meet.
if [ -f "$root$libdir/libtileworld.so.$version" ]; then
    readelf -d "$root$libdir/libtileworld.so.$version" | grep -Ei 'NEEDED.*(osmesa|libgl)' &&
        fail "libtileworld.so links a GL library"
fi

# ---- the headers, alone, from the installed location ----
cflags=$(pc --cflags tileworld tileworld-headless) || fail "pkg-config --cflags failed"
case " $cflags " in
    *" -I$root$includedir "*) ;;
    *) fail "pkg-config --cflags ($cflags) does not point at $root$includedir" ;;
esac
read -r -a cflags_a <<<"$cflags"
while read -r h; do
    hdr=$root$includedir/tileworld/$h
    # Every quoted include is another installed header, named as a host names it.
    while read -r inc; do
        case "$inc" in
            tileworld/*.h) [ -f "$root$includedir/$inc" ] ||
                fail "tileworld/$h includes \"$inc\", which is not installed" ;;
            *) fail "tileworld/$h includes \"$inc\": not of the form \"tileworld/NAME.h\"" ;;
        esac
    done < <(sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$hdr")
    printf '#include "tileworld/%s"\n' "$h" >"$tmp/hc.c"
    "${cc[@]}" -std=c11 -Wall -Wextra -Werror -fsyntax-only "${cflags_a[@]}" "$tmp/hc.c" \
        >"$tmp/hc.log" 2>&1 || { cat "$tmp/hc.log"; fail "tileworld/$h does not compile alone as C11"; }
    cp "$tmp/hc.c" "$tmp/hc.cpp"
    "${cxx[@]}" -std=c++11 -Wall -Wextra -Werror -fsyntax-only "${cflags_a[@]}" "$tmp/hc.cpp" \
        >"$tmp/hc.log" 2>&1 || { cat "$tmp/hc.log"; fail "tileworld/$h does not compile alone as C++11"; }
done <"$tmp/headers.inst"

# ---- a program that uses every declaration of the installed headers ----
# Linked against the libraries, it proves that each one is exported (shared)
# or archived with all it needs (static): no host meets a link error.
CC="${cc[*]}" bash "$public_api" "$root$includedir" >"$tmp/api" ||
    fail "cannot list the declarations of the installed headers"
[ "$(wc -l <"$tmp/api")" -ge 50 ] || fail "only $(wc -l <"$tmp/api") declarations listed: the extraction is broken"
{
    sed 's|.*|#include "tileworld/&"|' "$tmp/headers.inst"
    echo '#include <stdio.h>'
    echo 'typedef void (*any_fn)(void);'
    echo 'static const any_fn functions[] = {'
    awk '$1 == "func" { print "    (any_fn)" $2 "," }' "$tmp/api"
    echo '};'
    echo 'static const void *const objects[] = {'
    awk '$1 == "data" { print "    (const void *)" $2 "," }' "$tmp/api"
    echo '};'
    echo 'int main(void)'
    echo '{'
    echo '    size_t n = 0;'
    echo '    for (size_t k = 0; k < sizeof(functions) / sizeof(functions[0]); k++)'
    echo '        n += functions[k] != NULL;'
    echo '    for (size_t k = 0; k < sizeof(objects) / sizeof(objects[0]); k++)'
    echo '        n += objects[k] != NULL;'
    echo '    printf("%zu\n", n);'
    echo '    return 0;'
    echo '}'
} >"$tmp/use-all.c"

# ---- host.c and use-all.c, shared and static ----
# Shared, as a host types it:
#     cc host.c $(pkg-config --cflags --libs tileworld tileworld-headless)
# Static: a folder with only the archives, searched first, so that
# -ltileworld finds libtileworld.a; pkg-config --static adds what the
# archives need.
libs=$(pc --libs tileworld tileworld-headless) || fail "pkg-config --libs failed"
slibs=$(pc --static --libs tileworld tileworld-headless) || fail "pkg-config --static --libs failed"
read -r -a libs_a <<<"$libs"
read -r -a slibs_a <<<"$slibs"
mkdir "$tmp/static"
ln -s "$root$libdir/libtileworld.a" "$root$libdir/libtileworld-headless.a" "$tmp/static/"

# Does the dynamic loader search $libdir by itself? It says which folders it
# does (glibc 2.33 and later: its "system search path"); else the usual ones:
# /lib and /usr/lib with their multiarch folders, or without multiarch lib64.
# Where it does not, the .pc files must give an rpath to $libdir.
printf 'int main(void) { return 0; }\n' >"$tmp/empty.c"
system_dirs=()
if "${cc[@]}" "${hostflags[@]}" "$tmp/empty.c" -o "$tmp/empty" >"$tmp/cc.log" 2>&1; then
    interp=$(readelf -l "$tmp/empty" | sed -n 's/.*Requesting program interpreter: \(.*\)\]$/\1/p')
    [ -n "$interp" ] &&
        mapfile -t system_dirs < <("$interp" --help 2>/dev/null | sed -n 's/^ *\(\/.*\) (system search path)$/\1/p')
fi
if [ ${#system_dirs[@]} -eq 0 ]; then
    multiarch=$("${cc[@]}" -print-multiarch 2>/dev/null) || multiarch=
    if [ -n "$multiarch" ]; then
        system_dirs=(/lib /usr/lib "/lib/$multiarch" "/usr/lib/$multiarch")
    else
        system_dirs=(/lib /usr/lib /lib64 /usr/lib64)
    fi
fi
need_rpath=1
for d in "${system_dirs[@]}"; do
    [ "$d" = "$libdir" ] && need_rpath=0
done
[ $need_rpath -eq 1 ] ||
    echo "note: $libdir is searched by the dynamic loader: no rpath checked; shared hosts run with LD_LIBRARY_PATH into the DESTDIR"
# The flags of the .pc files as they are after a real install (-L and rpath
# to $libdir), and the same .pc files with their libdir where the files are
# now, as pkg-config relocates an installed tree (-L and rpath to $root$libdir).
libs_plain=$(pc_plain --libs tileworld tileworld-headless) || fail "pkg-config --libs failed"
libs_moved=$(pc_plain --define-variable=libdir="$root$libdir" --libs tileworld tileworld-headless) ||
    fail "pkg-config --define-variable=libdir=... --libs failed"
read -r -a libs_plain_a <<<"$libs_plain"
read -r -a libs_moved_a <<<"$libs_moved"

# build_and_run shared|static SOURCE: links SOURCE against the installed
# libraries and runs it (LD_BIND_NOW: every symbol resolved at start).
# Shared, where $libdir needs an rpath, it is linked with the relocated .pc
# files and runs without LD_LIBRARY_PATH, finding the libraries by the rpath
# alone; and once more with the flags of a real install, whose RUNPATH must
# name $libdir (checked, not run: nothing is installed there).
build_and_run() {
    local mode=$1 src=$2 exe=$tmp/${2##*/}-$1
    local link=("${libs_a[@]}")
    [ "$mode" = shared ] && [ $need_rpath -eq 1 ] && link=("${libs_moved_a[@]}")
    [ "$mode" = static ] && link=(-L"$tmp/static" "${slibs_a[@]}")
    if ! "${cc[@]}" -std=c11 -Wall -Wextra -Werror "${hostflags[@]}" "$src" "${cflags_a[@]}" "${link[@]}" \
            -o "$exe" >"$tmp/cc.log" 2>&1; then
        cat "$tmp/cc.log"
        fail "${src##*/} does not link against the installed $mode libraries: cc ${src##*/} $cflags ${link[*]}"
        return
    fi
    readelf -d "$exe" >"$tmp/dyn"
    local lib
    for lib in tileworld tileworld-headless; do
        if [ "$mode" = shared ]; then
            grep -q "NEEDED.*\[lib$lib.so.0\]" "$tmp/dyn" || fail "${src##*/} ($mode) does not need lib$lib.so.0"
        else
            grep -q "NEEDED.*lib$lib" "$tmp/dyn" && fail "${src##*/} ($mode) still needs a shared lib$lib"
        fi
    done
    local env_run=(env -u LD_LIBRARY_PATH LD_BIND_NOW=1)
    if [ "$mode" = shared ] && [ $need_rpath -eq 1 ]; then
        # The rpath alone finds the installed libraries.
        "${env_run[@]}" ldd "$exe" >"$tmp/ldd" 2>&1
        for lib in tileworld tileworld-headless; do
            grep -q "lib$lib.so.0 => $root$libdir/" "$tmp/ldd" ||
                fail "${src##*/} ($mode), without LD_LIBRARY_PATH, does not load lib$lib.so.0 from $root$libdir: $(grep "lib$lib\.so" "$tmp/ldd")"
        done
        # As linked after a real install: cc host.c $(pkg-config --libs ...),
        # with an -L into the DESTDIR first so that it links these libraries.
        if ! "${cc[@]}" -std=c11 -Wall -Wextra -Werror "${hostflags[@]}" "$src" "${cflags_a[@]}" \
                -L"$root$libdir" "${libs_plain_a[@]}" -o "$exe-real" >"$tmp/cc.log" 2>&1; then
            cat "$tmp/cc.log"
            fail "${src##*/} does not link with the flags of a real install: ${libs_plain_a[*]}"
        else
            case ":$(runpath "$exe-real"):" in
                *":$libdir:"*) ;;
                *) fail "${src##*/} ($mode): its RUNPATH ('$(runpath "$exe-real")') does not name $libdir, which the loader does not search (pkg-config --libs: $libs_plain)" ;;
            esac
        fi
    elif [ "$mode" = shared ]; then
        env_run=(env LD_LIBRARY_PATH="$root$libdir" LD_BIND_NOW=1)
        # The installed libraries are the ones it runs with.
        "${env_run[@]}" ldd "$exe" >"$tmp/ldd"
        for lib in tileworld tileworld-headless; do
            grep -q "lib$lib.so.0 => $root$libdir/" "$tmp/ldd" ||
                fail "${src##*/} ($mode) does not load lib$lib.so.0 from $root$libdir"
        done
    fi
    if ! "${env_run[@]}" "$exe" >"$tmp/run.log" 2>&1; then
        cat "$tmp/run.log"
        fail "${src##*/} ($mode) failed"
    fi
}

for mode in "${kinds[@]}"; do
    build_and_run "$mode" "$tmp/use-all.c"
    build_and_run "$mode" "$srcdir/examples/host.c"
done

[ $failures -eq 0 ] || exit 1
rpath_note=
[[ " ${kinds[*]} " = *" shared "* ]] && [ $need_rpath -eq 1 ] && rpath_note="; shared hosts run by their rpath to $libdir"
echo "ok: installed tree; $(wc -l <"$tmp/headers.inst") headers alone as C and C++; $(wc -l <"$tmp/api") declarations link; host.c ${kinds[*]}$rpath_note"
