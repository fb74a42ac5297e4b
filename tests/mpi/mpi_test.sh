#!/usr/bin/env bash
# MPI tests of `texcache` on loopback (tests/CMakeLists.txt registers them when MPI is found):
#   mpi_test.sh BIN_DIR MPIRUN NP CASE
# CASE still-hit, still-texture, still-ao: a still image over NP ranks against one process
#   (same seed and samples): RMSE at most 1e-6 (the ranks split the rows, so every pixel is
#   summed by one rank as one process sums it, and the texture-space bins are integer sums:
#   the images are expected to be equal; the tolerance only absorbs the EXR's half floats).
# CASE frames: --frames 0:31 with temporal accumulation (--temporal-alpha 0.7) in contiguous
#   chunks over NP ranks, each after its default warm-up (13 frames), against one process's
#   sequence, one thread each (so that the grid cache's evictions do not follow a schedule):
#   every frame's relMSE at most 2e-3. Measured worst on 3 ranks: 6.0e-4 (RMSE 6.1e-4), without
#   warm-up 4.4e-3; a frame's own noise (another seed) is RMSE 0.13 (results/mpi_scaling.md).
# CASE denoise: --denoise baseline --frames 0:63 (1 spp) the same way, the default warm-up (21
#   frames: the stage keeps 0.8 of its history a frame) rebuilding the stage's history: every
#   frame's relMSE at most 1e-3. Measured worst: 6.7e-5 on 2 ranks, 1.8e-5 on 3; without
#   warm-up 2.8e-2; a denoised frame with another seed differs by 1.4e-2.
# CASE fail-read, fail-die: rank 1 cannot read the scene / is killed mid-render: the job exits
#   non-zero, its first line names the rank (fail-read; mpirun's report names it for fail-die),
#   and the earlier output is untouched.
set -euo pipefail
bin="$1" mpirun="$2" np="$3" case="$4"
tmp="$(mktemp -d "${TEST_TMPDIR:-/tmp}/mpi_${case}_${np}.XXXXXX")"
trap 'rm -rf "$tmp"' EXIT
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
scene="$root/scenes/meshes/catmark_torus.obj"
common=(--resolution 48x30 --seed 7 -q --no-png)
run_mpi() { "$mpirun" --oversubscribe -np "$np" "$bin/texcache" "$@"; }
fail() { echo "FAIL: $*" >&2; exit 1; }

equal_images() {  # options...
    "$bin/texcache" render "$scene" "${common[@]}" "$@" -o "$tmp/one.exr" >/dev/null
    run_mpi render "$scene" "${common[@]}" "$@" -o "$tmp/many.exr" >"$tmp/log" 2>&1 ||
        { cat "$tmp/log"; fail "mpirun exited $?"; }
    local json rmse
    json="$("$bin/texcache" compare --json "$tmp/many.exr" "$tmp/one.exr")"
    rmse="$(sed -n 's/.*"rmse": \([^,]*\),.*/\1/p' <<<"$json")"
    echo "$case np=$np: $json"
    awk -v e="$rmse" 'BEGIN { exit !(e <= 1e-6) }' || fail "RMSE $rmse > 1e-6"
}

chunked_frames() {  # last-frame bound options...
    local last="$1" bound="$2" anim="$root/scenes/anim_shadow.json" f json relmse
    shift 2
    local opts=(--frames "0:$last" --resolution 48x30 --seed 3 -q --no-png --threads 1 "$@")
    "$bin/texcache" render "$anim" "${opts[@]}" -o "$tmp/one_#.exr" >/dev/null
    run_mpi render "$anim" "${opts[@]}" -o "$tmp/many_#.exr" >"$tmp/log" 2>&1 ||
        { cat "$tmp/log"; fail "mpirun exited $?"; }
    for f in $(seq 0 "$last"); do
        json="$("$bin/texcache" compare --json "$tmp/many_$f.exr" "$tmp/one_$f.exr")"
        relmse="$(sed -n 's/.*"relmse": \([^,]*\),.*/\1/p' <<<"$json")"
        echo "frame $f np=$np: $json"
        awk -v e="$relmse" -v b="$bound" 'BEGIN { exit !(e <= b) }' ||
            fail "frame $f: relMSE $relmse > $bound"
    done
}

failure() {  # kind first-line-pattern any-line-pattern
    printf 'good' >"$tmp/out.exr"
    local code=0
    TEXCACHE_FAIL_RANK="$1" run_mpi render "$scene" "${common[@]}" --spp 4 -o "$tmp/out.exr" \
        >"$tmp/log" 2>&1 || code=$?
    echo "exit code $code; first line: $(grep -a -m1 . "$tmp/log" || true)"
    [ "$code" -ne 0 ] || fail "the job exited 0"
    [ -z "$2" ] || grep -m1 "texcache" "$tmp/log" | grep -q "$2" || { cat "$tmp/log"; fail "no line '$2'"; }
    [ -z "${3:-}" ] || grep -q "$3" "$tmp/log" || { cat "$tmp/log"; fail "no line '$3'"; }
    [ "$(cat "$tmp/out.exr")" = good ] || fail "the earlier output was replaced"
    ls "$tmp" | grep -q tmp- && fail "a temporary output was left behind" || true
}

case "$case" in
    still-hit) equal_images --integrator path --shading hit --spp 4 ;;
    still-texture) equal_images --integrator path --shading texture --spp 8 --pass-spp 4 ;;
    still-ao) equal_images --integrator ao --shading texture --spp 8 --pass-spp 4 ;;
    frames) chunked_frames 31 2e-3 --spp 2 --shading texture --integrator path --temporal-alpha 0.7 ;;
    denoise) chunked_frames 63 1e-3 --denoise baseline ;;
    fail-read) failure 1 "^texcache: error: rank 1 (1 of $np ranks failed): .*cannot read" ;;
    fail-die) failure 1:die "" "rank 1 with PID .* on signal 9" ;;
    *) fail "unknown case $case" ;;
esac
