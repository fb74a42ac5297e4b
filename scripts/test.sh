#!/usr/bin/env bash
# Runs the whole test suite through CTest (sets everything up first). The cache library's tests
# also run under ThreadSanitizer (label `cache`, build-tsan/), since the caches are shared by all
# render threads; that run comes first so the main suite's summary closes the output.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"

echo "== ThreadSanitizer: libtexcache tests =="
tsan="$root/build-tsan"
cmake -S "$root" -B "$tsan" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEXCACHE_SANITIZE=thread >/dev/null
cmake --build "$tsan" --target cache_test -j"$(nproc)" >/dev/null
# halt_on_error: a race fails the test instead of only printing a report.
(cd "$tsan" && TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" \
    ctest --output-on-failure -L cache -j"$(nproc)")

echo "== Test suite =="
cd "$root/build"
ctest --output-on-failure -j"$(nproc)" "$@"
