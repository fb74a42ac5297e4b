#!/usr/bin/env bash
# What CI runs (.ci/run), in this order, each phase printing its duration:
#  1. format: scripts/check_format.sh (clang-format), first, so that a formatting slip fails fast;
#  2. release build: scripts/setup.sh (missing Debian packages, Release build in build/);
#  3. tsan: the cache library's tests (label `cache`) under ThreadSanitizer in build-tsan/, since
#     the caches are shared by all render threads;
#  4. asan: the suite under AddressSanitizer + UndefinedBehaviorSanitizer in build-asan/, all but
#     the experiments' end-to-end runs, the long convergence tests, the examples and the
#     benchmarks' smoke runs (below);
#  5. the whole suite in the Release build, last, so that its CTest summary closes the output.
# Every build treats warnings in project code as errors (TEXCACHE_WERROR), here as in CI, so that
# a run that passes here passes there; the setting stays in build/'s CMake cache. Extra arguments
# go to the two whole-suite ctest runs (e.g. -R Render). A failed format check or build stops the
# script at once; a failed test phase lets the later ones run. Exits non-zero if any phase failed.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc)"
failed=()
phase() { echo "== $1 =="; t0=$SECONDS; }
took() { echo "-- $1: $((SECONDS - t0)) s"; }

# clang-format comes with the packages: install those (only) before the check.
SETUP_PACKAGES_ONLY=1 "$root/scripts/setup.sh"
phase "format check"
"$root/scripts/check_format.sh"
took "format check"

phase "Release build (build/)"
"$root/scripts/setup.sh" -DTEXCACHE_WERROR=ON
took "Release build"

# A sanitizer build of `targets` in `dir`: -O1 with line tables (-g1), which is what sanitizer
# reports need, and compiles in about half the time of -O2 -g on 2 cores; the screen-space
# kernels in one ISA, not three (TEXCACHE_NO_ISA_CLONES). Warnings as errors are
# the Release build's job (other optimization levels warn differently).
sanitizer_build() {
  local dir="$1" sanitizer="$2"
  shift 2
  cmake -S "$root" -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DTEXCACHE_SANITIZE="$sanitizer" >/dev/null
  cmake --build "$dir" -j"$jobs" "$@" >/dev/null   # compiler messages go to stderr
}

phase "ThreadSanitizer: libtexcache tests (build-tsan/)"
# The cache library's tests of what render threads share: texel keys, the direct-mapped cache,
# footprints and visible sets, the shading cache, the record cache, the hit bins and the store
# built on them.
sanitizer_build "$root/build-tsan" thread --target texel_key_test direct_mapped_cache_test \
    footprint_test shading_cache_test record_cache_test hit_bins_test texture_store_test
took "TSan build"
t0=$SECONDS
# halt_on_error: a race fails the test instead of only printing a report.
(cd "$root/build-tsan" && TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" \
    ctest --output-on-failure -L cache -j"$jobs") || failed+=("ThreadSanitizer tests")
took "TSan tests"

phase "AddressSanitizer + UBSan: whole suite (build-asan/)"
# Exported before the build too: gtest_discover_tests runs each test program to list its tests.
# UBSan findings abort in this build (-fno-sanitize-recover, cmake/Warnings.cmake); the options
# add stack traces. Leaks are checked (the preview tests excepted: tests/CMakeLists.txt says why).
asan_skip='Experiment\.|SpeedVsError\.'
# Convergence tests that measure error against references of hundreds of samples a pixel: under
# ASan they are the suite's longest tests by far, and what they check is error levels, which the
# Release suite checks. The code they render through runs under ASan in the short tests beside
# them (hard cages, thread counts, the split lobes, the store).
asan_skip+='|HitLight\.(LowerErrorThanPerHitAndConverges|GlossyMaterialsBinTheirDiffuseBase)'
asan_skip+='|HitLight\.(DirectIntegratorBinsItsLight|NoPixelKeepsAnError)'
asan_skip+='|FrameBuffers\.ComposeIsUnbiased|Lights\.PerHitAndTextureSpaceConverge'
asan_skip_labels='example|bench'
export ASAN_OPTIONS="detect_leaks=1:check_initialization_order=1:strict_init_order=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
sanitizer_build "$root/build-asan" address --target texcache_test_programs
took "ASan build"
t0=$SECONDS
# The experiments' end-to-end runs are left to the Release suite: they render dozens of images
# (about half the ASan suite's time on a fresh clone), their rendering code is what the other
# tests run under ASan, and what is theirs alone is writing CSV, plots and markdown. So are the
# examples and the benchmarks' smoke runs (labels example, bench; not built here): they check
# that the programs still run and give their answers, on library code the tests run under ASan.
(cd "$root/build-asan" && ctest --output-on-failure -j"$jobs" -E "$asan_skip" \
    -LE "$asan_skip_labels" "$@") ||
    failed+=("ASan + UBSan tests")
took "ASan tests"
unset ASAN_OPTIONS UBSAN_OPTIONS

if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED: %s\n' "${failed[@]}"
fi
echo "== Test suite (Release, build/) =="
cd "$root/build"
status=0
ctest --output-on-failure -j"$jobs" "$@" || status=$?
# Nothing is printed after the Release suite's summary: CI reads its closing lines.
[ ${#failed[@]} -eq 0 ] && exit "$status"
exit 1
