#!/usr/bin/env bash
# Renders the default scene to out/demo.exr and out/demo.png (sets everything up first).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
mkdir -p "$root/out"
"$root/build/bin/texcache" render "$root/scenes/car.json" -o "$root/out/demo.exr" "$@"
