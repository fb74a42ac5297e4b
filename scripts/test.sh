#!/usr/bin/env bash
# Runs the whole test suite through CTest (sets everything up first), then the cache library's
# tests again under ThreadSanitizer (label `cache`), since the caches are shared by all threads.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
cd "$root/build"
ctest --output-on-failure -j"$(nproc)" "$@"

echo "== ThreadSanitizer: libtexcache tests =="
tsan="$root/build-tsan"
cmake -S "$root" -B "$tsan" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEXCACHE_SANITIZE=thread >/dev/null
cmake --build "$tsan" --target cache_test -j"$(nproc)" >/dev/null
cd "$tsan"
# halt_on_error: a race fails the test instead of only printing a report.
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" ctest --output-on-failure -L cache -j"$(nproc)"
