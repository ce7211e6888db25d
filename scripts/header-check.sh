#!/bin/sh
# Writes a one-line C (or C++) file that includes one header, to prove that
# it compiles alone. Public headers (include/tileworld/) are included as a
# host includes them.
# usage: header-check.sh HEADER OUTPUT SOURCE_ROOT
hdr=$(realpath "$1"); root=$(realpath "$3")
rel=${hdr#"$root"/}
rel=${rel#include/}
printf '#include "%s"\n' "$rel" > "$2"
