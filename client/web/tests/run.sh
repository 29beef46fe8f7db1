#!/usr/bin/env bash
# ctest's entry to the viewer's tests: run.sh unit|e2e BUILD_DIR (BUILD_DIR: where the
# catgs-viewer target put dist/, node/ and tests/). Exits 77 (ctest SKIP_RETURN_CODE) when node,
# node_modules, the build or chromium is missing, unless CATGS_REQUIRE_BROWSER=1 (CI), where a
# missing piece fails the test.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
kind=$1 build=$2

skip() {
  if [ "${CATGS_REQUIRE_BROWSER:-0}" = 1 ]; then
    echo "web $kind: FAIL: $1 (CATGS_REQUIRE_BROWSER=1)" >&2
    exit 1
  fi
  echo "web $kind: SKIPPED: $1"
  exit 77
}

command -v node >/dev/null || skip "node is not installed (bash client/web/install-deps.sh)"
[ -d "$here/node_modules" ] || skip "client/web/node_modules is missing (bash client/web/install-deps.sh, then re-run cmake)"
[ -d "$build/tests" ] || skip "$build/tests is missing: the catgs-viewer target has not been built"
case $kind in
  unit) exec node --test "$build"/tests/*.test.mjs ;;
  e2e)
    [ -x "${CATGS_CHROMIUM:-/usr/bin/chromium}" ] || skip "chromium is not installed (bash client/web/install-deps.sh)"
    exec node "$here/tests/e2e.mjs" --dist "$build/dist" ;;
  *) echo "usage: run.sh unit|e2e BUILD_DIR" >&2; exit 2 ;;
esac
