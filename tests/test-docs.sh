#!/usr/bin/env bash
# The README says what the programs accept, and the programs say the same:
#   - `tileworld CMD --help` exits 0 and opens with CMD's synopsis (its first
#     paragraph); the README's "Commands" block is those synopses, one after
#     the other, word for word (runs of blanks aside);
#   - every option of every synopsis has its meaning in the README (a row or
#     an item that starts with `--opt`), and `--help` explains it too;
#   - every long option in the programs' getopt tables is in a synopsis, and
#     every option in a synopsis is accepted by its command (never "unknown
#     option");
#   - no user-facing text of the README names an issue or a commit.
# Usage: test-docs.sh TILEWORLD SOURCE_ROOT
set -u
tw=$1
src=$2
readme=$src/README.md
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

commands="walk bench info import memtest view bake"
viewer="$(dirname "$tw")/tileworld-view"

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The synopsis of CMD: the first paragraph of `tileworld CMD --help`.
synopsis() {
    awk 'NF == 0 { exit } { print }' "$tmp/help-$1"
}
norm() { sed -e 's/^usage: //' -e 's/[[:space:]]\+/ /g' -e 's/^ //' -e 's/ $//'; }

: >"$tmp/help-synopses"
for c in $commands; do
    if [ "$c" = view ] && [ ! -x "$viewer" ]; then
        echo "no viewer in this build: view's help not checked"
        continue
    fi
    "$tw" "$c" --help >"$tmp/help-$c" 2>"$tmp/help-$c.err"
    rc=$?
    [ "$rc" = 0 ] || fail "tileworld $c --help exits $rc: $(head -c 300 "$tmp/help-$c.err")"
    [ -s "$tmp/help-$c.err" ] && fail "tileworld $c --help writes to stderr"
    head -n 1 "$tmp/help-$c" | grep -q "^usage: tileworld $c " ||
        fail "tileworld $c --help does not open with 'usage: tileworld $c ...'"
    synopsis "$c" | norm >>"$tmp/help-synopses"
done

# The README's Commands block.
awk '/^## Commands/ { inside = 1; next }
     inside && /^```/ { if (fence) exit; fence = 1; next }
     fence { print }' "$readme" | norm >"$tmp/readme-synopses"
[ -s "$tmp/readme-synopses" ] || fail "README has no Commands block"
if [ ! -x "$viewer" ]; then
    # Without a viewer, compare all but view's lines.
    awk '/^tileworld view /{ skip = 1 } /^tileworld [a-z]+ / && !/^tileworld view /{ skip = 0 }
         !skip' "$tmp/readme-synopses" >"$tmp/readme-synopses.noview"
    mv "$tmp/readme-synopses.noview" "$tmp/readme-synopses"
fi
if ! diff -u "$tmp/readme-synopses" "$tmp/help-synopses" >"$tmp/diff"; then
    fail "README's Commands block differs from the programs' --help synopses (- README, + --help):"
    cat "$tmp/diff"
fi

# Options of the synopses.
grep -o -- '--[a-z][a-z0-9-]*' "$tmp/help-synopses" | sort -u >"$tmp/synopsis-options"
[ "$(wc -l <"$tmp/synopsis-options")" -gt 30 ] || fail "too few options found in the synopses"
# The README without its Commands block: where options are explained.
awk '/^## Commands/ { inside = 1 } inside && /^```/ { n++; if (n == 2) { inside = 0 }; next }
     !(inside && n == 1) { print }' "$readme" >"$tmp/readme-rest"
while read -r opt; do
    grep -q -- "^| \`$opt\|^- \`$opt\|^\`$opt" "$tmp/readme-rest" ||
        fail "README explains no '$opt' (a table row or an item starting with \`$opt)"
done <"$tmp/synopsis-options"

# Every option a command's synopsis lists is explained by its --help and
# accepted by it.
for c in $commands; do
    [ -f "$tmp/help-$c" ] || continue
    synopsis "$c" | grep -o -- '--[a-z][a-z0-9-]*' | sort -u | while read -r opt; do
        [ "$opt" = --help ] && continue
        awk 'NF == 0 { body = 1; next } body' "$tmp/help-$c" | grep -q -- "$opt" ||
            echo "FAIL: tileworld $c --help lists $opt but explains nothing of it"
        # A value that no option takes, then an option nobody knows: the
        # command stops at one or the other, never runs, and names $opt
        # only for its value.
        out=$(cd "$tmp" && timeout 20 "$tw" "$c" "$opt=@bad@" --no-such-option-zz 2>&1 </dev/null)
        case $out in
        *"$opt: unknown option"* | *"unrecognized option '$opt"* | *"unrecognised option '$opt"*)
            echo "FAIL: tileworld $c does not accept $opt: $out" ;;
        esac
    done >>"$tmp/option-fails"
done
if [ -s "$tmp/option-fails" ]; then
    cat "$tmp/option-fails"
    fails=$((fails + $(wc -l <"$tmp/option-fails")))
fi

# Every long option of the programs' getopt tables is in a synopsis.
grep -rhoE '\{"[a-z][a-z0-9-]*", *(no|required|optional)_argument' "$src/tools" |
    sed -E 's/\{"([^"]*)".*/--\1/' | sort -u >"$tmp/table-options"
[ "$(wc -l <"$tmp/table-options")" -gt 30 ] || fail "too few options found in the getopt tables"
while read -r opt; do
    [ "$opt" = --help ] && continue
    grep -qx -- "$opt" "$tmp/synopsis-options" || fail "$opt is accepted but in no synopsis"
done <"$tmp/table-options"

# The README's example of a prefix works, and its example of an ambiguous
# one is refused as such.
out=$(cd "$tmp" && "$tw" walk --view-d=@bad@ 2>&1)
case $out in *"--view-distance:"*) ;; *) fail "walk --view-d is not --view-distance: $out" ;; esac
out=$(cd "$tmp" && "$tw" bench --meth=@bad@ 2>&1)
case $out in *ambiguous*) ;; *) fail "bench --meth is not ambiguous: $out" ;; esac
out=$(cd "$tmp" && "$tw" walk --view=@bad@ 2>&1)
case $out in *ambiguous*) ;; *) fail "walk --view is not ambiguous: $out" ;; esac
grep -q '`--view-d 800` is' "$readme" || fail "README lost its prefix example"

# No issue numbers or commit hashes in what users read (the design notes at
# the end, for developers, may cite the design's sections).
awk '/^## Departures from DESIGN.md/ { exit } { print }' "$readme" >"$tmp/readme-user"
if grep -nE '\bissue [0-9]+|\(issue|\b[0-9a-f]{7,40}\b' "$tmp/readme-user" |
    grep -vE '\b[0-9]{7,}\b' >"$tmp/history"; then
    fail "README names issues or commits where users read it:"
    cat "$tmp/history"
fi

if [ "$fails" != 0 ]; then
    echo "$fails failure(s)"
    exit 1
fi
echo "docs: the README and --help agree"
