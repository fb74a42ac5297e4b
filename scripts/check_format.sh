#!/usr/bin/env bash
# Checks that the project's C++ sources are clang-format clean (.clang-format at the root); lists
# the files that are not and exits 1. `scripts/check_format.sh --fix` formats them in place.
# scripts/test.sh runs the check first, so CI fails fast on a formatting slip.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# The project's source folders only: build trees (build*/) sit at the root, outside them.
mapfile -t files < <(find libtexcache ptex filters screen_space renderer apps examples tests -type f \
    \( -name '*.cpp' -o -name '*.h' -o -name '*.hpp' -o -name '*.cc' -o -name '*.inl' \) | sort)
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${files[@]}"
  exit 0
fi
if out="$(clang-format --dry-run -Werror "${files[@]}" 2>&1)"; then
  echo "clang-format: ${#files[@]} files clean"
  exit 0
fi
bad="$(grep -oE '^[^ :]+:[0-9]+:[0-9]+: error: code should be clang-formatted' <<<"$out" |
       cut -d: -f1 | sort -u || true)"
echo "clang-format: these files are not formatted (scripts/check_format.sh --fix formats them):" >&2
[ -n "$bad" ] && sed 's/^/  /' <<<"$bad" >&2
head -n 30 <<<"$out" >&2   # the first differences (or clang-format's own error)
exit 1
