#!/usr/bin/env bash
# What texcache is for, in one run: the default scene (scenes/car.json, path traced) rendered per
# hit and with texture-space shading in the same time, each compared with a reference; the two
# pictures side by side in out/demo.png and in a file named with the figures,
# out/demo_per-hit_relMSE<A>_texture-space_relMSE<B>_<S>s.png.
#
# Usage: scripts/demo.sh [texcache render options...]   (e.g. --resolution 320x180)
# Extra options go to every `texcache render` call (--seconds S replaces the time budget, default
# DEMO_SECONDS or 10 s each). The reference (512 spp, the same options) is rendered once and
# cached under out/ by a hash of the scene file and the options: the first run takes minutes more.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
bin="$root/build/bin/texcache"
scene="$root/scenes/car.json"
out="$root/out"
mkdir -p "$out"

# The time budget, and the options the reference shares (all but the budget and sample counts).
seconds="${DEMO_SECONDS:-10}"
shared=()
while [ $# -gt 0 ]; do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --seconds=*) seconds="${1#*=}"; shift ;;
    --spp) shift 2 ;;   # equal time, not equal samples
    --spp=*) shift ;;
    *) shared+=("$1"); shift ;;
  esac
done

# Keyed by the scene, the options and the renderer's build: a reference of another build (say,
# before a change to the BSDF) would measure the difference between the builds.
key="$( (cat "$scene" "$bin"; printf '%s\n' "${shared[@]+"${shared[@]}"}") | sha1sum | cut -c1-12)"
ref="$out/demo_ref_$key.exr"
if [ ! -f "$ref" ]; then
  echo "demo: rendering the reference once: $ref (512 spp, minutes; later runs reuse it)"
  "$bin" render "$scene" --spp 512 -q --no-png -o "$ref" "${shared[@]+"${shared[@]}"}"
fi

# Texture space: diffuse light of the ground (indirect and direct: the courtyard's light is soft)
# shaded at the camera hits and binned per texel of a coarser level (the default for path
# tracing); the glossy paint stays per hit. Why these settings: docs/texture-space.md.
# It renders first: its passes are 4 camera samples, so it may overrun the budget; per hit (passes
# of one sample) then gets the time texture space took.
texture=(--shading texture --cached-light all)
echo "demo: texture space (${texture[*]}), ${seconds} s"
# --spp 65536: the scene file's spp would otherwise end a render before its time is up.
log="$("$bin" render "$scene" --seconds "$seconds" --spp 65536 -q -o "$out/demo_texture.exr" "${texture[@]}" \
  "${shared[@]+"${shared[@]}"}")"
echo "$log" | grep -E "^(rendered|time)"
taken="$(echo "$log" | sed -nE 's/^time: ([0-9.]+) s render.*/\1/p')"
echo "demo: per hit, the same ${taken} s"
"$bin" render "$scene" --seconds "$taken" --spp 65536 -q -o "$out/demo_hit.exr" \
  "${shared[@]+"${shared[@]}"}" | grep -E "^(rendered|time)"

relmse() { "$bin" compare "$1" "$ref" --json | sed -E 's/.*"relmse": ([^,]*),.*/\1/'; }
hit="$(relmse "$out/demo_hit.exr")"
tex="$(relmse "$out/demo_texture.exr")"
awk -v h="$hit" -v t="$tex" 'BEGIN { printf "relMSE against the reference (eps = 0.001): " \
  "per hit %.4f, texture space %.4f (%.2fx per hit)\n", h, t, t / h }'
named="$out/$(printf 'demo_per-hit_relMSE%.4f_texture-space_relMSE%.4f_%.1fs.png' "$hit" "$tex" "$taken")"
"$bin" montage "$out/demo_hit.exr" "$out/demo_texture.exr" -o "$named" >/dev/null
cp "$named" "$out/demo.png"
echo "demo: wrote $named (left per hit, right texture space) and out/demo.png"
