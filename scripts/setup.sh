#!/usr/bin/env bash
# Installs missing Debian packages, then configures and builds texcache into build/.
# Usage: scripts/setup.sh [extra cmake args...]   (BUILD_DIR overrides build/;
#        SETUP_PACKAGES_ONLY=1 installs the packages and stops)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build}"

pkgs=(build-essential cmake pkg-config
      libembree-dev libosd-dev libopenimageio-dev libopenexr-dev libpng-dev libglm-dev libtbb-dev
      libeigen3-dev libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev gnuplot-nox
      zlib1g-dev      # texcache_ptex (libpng-dev and libopenexr-dev pull it in too)
      libglfw3-dev libimgui-dev xvfb xauth libgl1-mesa-dri
      clang-format    # scripts/check_format.sh
      embree-tools)   # Embree's pathtracer, the peer of `texcache bench peer` (optional at run time)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi
[ "${SETUP_PACKAGES_ONLY:-0}" = 1 ] && exit 0

cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$build" -j"$(nproc)" 2>&1 | grep -E "error|warning|Error" >&2 || true
cmake --build "$build" -j"$(nproc)" >/dev/null   # fails loudly if the build is broken
