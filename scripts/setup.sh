#!/usr/bin/env bash
# Installs the Debian 12 packages tileworld needs to build, test and run.
# Does nothing when they are all present already.
set -euo pipefail
packages=(build-essential meson ninja-build pkg-config libembree-dev libmeshoptimizer-dev libosmesa6-dev
          mesa-common-dev libgl-dev libglfw3-dev libpng-dev libjson-c-dev gnuplot-nox
          libegl-dev libegl1 libegl-mesa0 # EGL: headers, glvnd's loader, Mesa's vendor (llvmpipe)
          g++ libtinygltf-dev nlohmann-json3-dev
          libstb-dev                    # the viewer's overlay text (stb_easy_font)
          libcurl4-openssl-dev          # the 3D Tiles provider's HTTP (tilesets/http.c)
          xvfb xauth libgl1-mesa-dri)   # the viewer's test: a GLFW window under xvfb-run
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "scripts/setup.sh: installing ${missing[*]}" >&2
sudo=()
[ "$(id -u)" -eq 0 ] || sudo=(sudo)
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
