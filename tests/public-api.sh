#!/usr/bin/env bash
# Prints tileworld's public API as its headers declare it, sorted, one line
# each: "func NAME" for a function, "data NAME" for an extern object. The
# headers are read through the preprocessor, so that names in comments and
# macros do not count; static and inline functions are not API a library
# exports, and neither are typedefs.
# Used by test-symbols.sh and test-install.sh.
#
# usage: public-api.sh INCLUDE_DIR    (the folder that holds tileworld/*.h)
# environment: CC (a command, may hold arguments)
set -u
inc=$1
read -r -a cc <<<"${CC:-cc}"

shopt -s nullglob
headers=("$inc"/tileworld/*.h)
if [ ${#headers[@]} -eq 0 ]; then
    echo "public-api.sh: no headers in $inc/tileworld" >&2
    exit 1
fi
for h in "${headers[@]}"; do
    printf '#include "tileworld/%s"\n' "${h##*/}"
done | "${cc[@]}" -std=c11 -E -P -I"$inc" -x c - | awk '
    # One record per declaration (or per piece of a struct body).
    BEGIN { RS = "[;{}]" }
    {
        gsub(/[ \t\r\n]+/, " ")
        if ($0 ~ /(^| )(typedef|static|inline)( |$)/)
            next
        if (match($0, /tw_[a-z0-9_]+ ?\(/)) {
            name = substr($0, RSTART, RLENGTH)
            sub(/ ?\($/, "", name)
            print "func " name
        } else if ($0 ~ /^ ?extern / && match($0, /tw_[a-z0-9_]+ ?(\[[^]]*\])? ?$/)) {
            name = substr($0, RSTART, RLENGTH)
            sub(/ ?(\[[^]]*\])? ?$/, "", name)
            print "data " name
        }
    }' | sort -u
