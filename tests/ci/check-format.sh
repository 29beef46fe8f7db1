#!/usr/bin/env bash
# CI's format check: every tracked C++ and CUDA source must be what clang-format makes of it
# under the root .clang-format (Debian 12's clang-format 14; other versions format some
# constructs differently, so CI and developers use that one). Prints each file that differs
# with the start of its diff and the command that fixes it; exits 1 if any does.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
fmt=${CLANG_FORMAT:-clang-format}
command -v "$fmt" >/dev/null || { echo "check-format: $fmt not found (apt-get install clang-format)" >&2; exit 1; }
bad=0
checked=0
while IFS= read -r file; do
  checked=$((checked + 1))
  if ! "$fmt" --style=file "$file" | cmp -s - "$file"; then
    echo "check-format: $file is not formatted; fix with: $fmt -i --style=file $file"
    "$fmt" --style=file "$file" | diff -u "$file" - | head -20 || true
    bad=1
  fi
done < <(git ls-files '*.cpp' '*.hpp' '*.cu' '*.cuh' '*.h')
[ $bad -eq 0 ] && echo "check-format: $checked files formatted"
exit $bad
