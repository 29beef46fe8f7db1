#!/usr/bin/env bash
# Installs what the test suite needs beyond deploy/install-deps.sh, idempotently, before cmake
# configures the build (the viewer's and the scene oracle's tests are registered from what is
# installed): the deploy checks' tools, clang for the sanitizer and fuzz jobs and clang-format,
# splat-transform (the scene formats' oracle) and Chromium for the viewer's end-to-end test.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bash "$root/tests/deploy/install-deps.sh"
bash "$root/tests/ci/install-deps.sh"
bash "$root/tests/oracle/install-deps.sh"
bash "$root/client/web/install-deps.sh"
