#!/usr/bin/env bash
# Installs what tests/ci/sanitizers.sh needs beyond deploy/install-deps.sh on Debian 12,
# idempotently: clang 14 with its sanitizer and libFuzzer runtimes, and llvm-14 for
# llvm-symbolizer (reports with file and line), and clang-format for tests/ci/check-format.sh.
# Run as root, or with sudo available.
set -euo pipefail

packages=(clang-14 libclang-rt-14-dev llvm-14 clang-format)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "tests/ci/install-deps: ${packages[*]} present"
  exit 0
fi
echo "tests/ci/install-deps: installing ${missing[*]}"
sudo_cmd=()
[ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
"${sudo_cmd[@]}" apt-get update -q
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
