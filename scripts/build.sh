#!/usr/bin/env bash
# Installs what is missing, configures build/ (once) and builds it.
# Extra arguments go to `meson setup`, e.g. scripts/build.sh -Dwerror=true.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
if [ ! -f build/build.ninja ]; then
    meson setup build "$@" >/dev/null
elif [ $# -gt 0 ]; then
    meson configure build "$@" >/dev/null
fi
ninja -C build >/dev/null
