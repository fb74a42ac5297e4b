#!/usr/bin/env bash
# MPI tests of `texcache` on loopback (tests/CMakeLists.txt registers them when MPI is found):
#   mpi_test.sh BIN_DIR MPIRUN NP CASE
# CASE still-hit, still-texture, still-ao: a still image over NP ranks against one process
#   (same seed and samples): RMSE at most 1e-6 (the ranks split the rows, so every pixel is
#   summed by one rank as one process sums it, and the texture-space bins are integer sums:
#   the images are expected to be equal; the tolerance only absorbs the EXR's half floats).
# CASE still-ao-grid: texture-space AO on the grid with visible footprints (AO's default), 2
#   passes: the ranks or their visible-texel marks before shading, so every footprint keeps
#   what one process's keeps: RMSE at most 1e-6 likewise.
# CASE experiment: `experiment speed-vs-error --quick` (car-ao, 3 methods, 2 budgets) with its
#   renders spread over NP ranks (rank 0 given --out A, the others --out B) against one
#   process: the same rows, every relMSE column within 1e-6 relative, the grid's counts of rays
#   and shaded samples within 1e-3 (they follow the thread schedule) (each render is one
#   process's render on one rank; the references are rendered over the ranks, equal to one
#   process's), and B stays empty: rank 0 alone writes. A bad --only fails as one line, exit 2.
# CASE experiment-cpis: `experiment cpis --quick` (3 methods, 1..64 spp) the same way: the same
#   rows and rays, relMSE within 1e-6 relative, the same number of record lookups (how they
#   split into records built and hit follows the thread schedule, in one process too).
# CASE experiment-filter-size: `experiment filter-size --quick` (21 renders) the same way:
#   relMSE within 1e-6 relative, samples shaded and their ratios within 1e-3 (measured: 21 of
#   153301 on 2 ranks; one process's runs differ by a few too).
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

spread_run() {  # markdown experiment-options...: one process in one/, NP ranks in many/
    local md="$1"
    shift
    "$bin/texcache" experiment "$@" --out "$tmp/one" >"$tmp/log_one" 2>&1 ||
        { cat "$tmp/log_one"; fail "one process exited $?"; }
    mkdir "$tmp/others"
    "$mpirun" --oversubscribe -np 1 "$bin/texcache" experiment "$@" --out "$tmp/many" : \
        -np "$((np - 1))" "$bin/texcache" experiment "$@" --out "$tmp/others" >"$tmp/log" 2>&1 ||
        { cat "$tmp/log"; fail "mpirun exited $?"; }
    grep "on rank" "$tmp/log" | head -4
    [ -z "$(ls -A "$tmp/others")" ] || fail "ranks other than 0 wrote: $(ls -A "$tmp/others")"
    [ "$(ls "$tmp/one")" = "$(ls "$tmp/many")" ] ||
        fail "files differ: $(ls "$tmp/one" | tr '\n' ' ') against $(ls "$tmp/many" | tr '\n' ' ')"
    grep -q "^## Ranks" "$tmp/many/$md" || fail "the markdown names no ranks"
}

same_rows() {  # csv skipped-columns relmse-columns count-columns count-bound
    # one/CSV against many/CSV: the same rows; relMSE columns within 1e-6 relative, counts
    # within the bound relative, the others equal (timings skipped).
    paste -d '\n' "$tmp/one/$1" "$tmp/many/$1" | awk -F, -v skip=",$2," -v rel=",$3," \
        -v counts=",$4," -v bound="$5" '
        NR % 2 == 1 { for (i = 1; i <= NF; ++i) a[i] = $i; n = NF; next }
        NF != n { print "row " NR / 2 ": " NF " values against " n; bad = 1; next }
        { for (i = 1; i <= NF; ++i) {
              if (index(skip, "," i ",")) continue
              d = a[i] - $i; d = d < 0 ? -d : d; m = a[i] < 0 ? -a[i] : a[i]
              if (index(rel, "," i ",")) {
                  r = m > 0 ? d / m : d > 0; worst = r > worst ? r : worst
                  if (r > 1e-6) { print "row " NR / 2 " column " i ": " a[i] " against " $i; bad = 1 }
              } else if (index(counts, "," i ",")) {
                  if (d > bound * m) { print "row " NR / 2 " column " i ": " a[i] " against " $i; bad = 1 }
              } else if (a[i] != $i) { print "row " NR / 2 " column " i ": " a[i] " against " $i; bad = 1 }
          } }
        END { printf "%d rows; worst relative relMSE difference %g\n", NR / 2 - 1, worst; exit bad }' ||
        fail "the CSVs differ"
}

spread_experiment() {
    spread_run speed_vs_error.md speed-vs-error --quick --only car-ao \
        --methods per-hit,ts-hits,ts-normal
    # Columns: case, method, budget, spp, rays_per_point, (seconds), rays, relmse,
    # samples_shaded, relmse_image, (cpu_seconds). Rays and samples shaded on the grid: two
    # threads that miss one sample at once may both shade it, so the counts follow the schedule
    # by a few.
    same_rows speed_vs_error.csv 6,11 8,10 7,9 1e-3
    # Bad input: every rank checks the options before any renders; one line, exit code 2.
    local code=0
    run_mpi experiment speed-vs-error --quick --only nope --out "$tmp/bad" >"$tmp/log" 2>&1 ||
        code=$?
    [ "$code" -eq 2 ] || { cat "$tmp/log"; fail "bad --only: exit code $code, expected 2"; }
    [ "$(grep -c '^texcache: error' "$tmp/log")" -eq 1 ] || { cat "$tmp/log"; fail "not one line"; }
    [ ! -e "$tmp/bad" ] || fail "bad --only left an empty --out behind"
}

spread_cpis() {
    spread_run cpis.md cpis --quick
    # Columns: method, spp, (seconds), rays, relmse, (cpu_seconds), (psr_built), (psr_hits).
    # Threads that miss one record at once may each build it, so how the lookups split into
    # records built and hit follows the schedule (one process's 64-spp render: 384 to 422
    # built); their sum, the lookups, does not.
    same_rows cpis.csv 3,6,7,8 5 "" 0
    local lookups=(awk -F, 'NR > 1 { print $1, $2, $7 + $8 }')
    [ "$("${lookups[@]}" "$tmp/one/cpis.csv")" = "$("${lookups[@]}" "$tmp/many/cpis.csv")" ] ||
        fail "record lookups differ"
}

spread_filter_size() {
    spread_run filter_size.md filter-size --quick
    # Columns: footprint, width, radius, (cpu_seconds), samples_shaded, (relative_time),
    # relative_invocations, relmse. Two threads that miss one sample at once may both shade
    # it, so the counts follow the schedule by a few.
    same_rows filter_size.csv 4,6 8 5,7 1e-3
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
    still-ao-grid) equal_images --integrator ao --shading texture --ts-samples grid --spp 8 \
        --pass-spp 4 ;;
    experiment) spread_experiment ;;
    experiment-cpis) spread_cpis ;;
    experiment-filter-size) spread_filter_size ;;
    frames) chunked_frames 31 2e-3 --spp 2 --shading texture --integrator path --temporal-alpha 0.7 ;;
    denoise) chunked_frames 63 1e-3 --denoise baseline ;;
    fail-read) failure 1 "^texcache: error: rank 1 (1 of $np ranks failed): .*cannot read" ;;
    fail-die) failure 1:die "" "rank 1 with PID .* on signal 9" ;;
    *) fail "unknown case $case" ;;
esac
