#!/bin/sh
# Writes a one-line C file that includes one header, to prove it compiles alone.
# usage: header-check.sh HEADER OUTPUT SOURCE_ROOT
hdr=$(realpath "$1"); root=$(realpath "$3")
printf '#include "%s"\n' "${hdr#"$root"/}" > "$2"
