#!/usr/bin/env bash
# Installs what the viewer (client/web) needs to build and test on Debian 12, idempotently:
#   node, npm   Debian packages nodejs and npm, only when node is missing
#   chromium    Debian package chromium, for the headless end-to-end test (tests/e2e.mjs);
#               puppeteer-core drives it and downloads no browser
#   protoc      Debian package protobuf-compiler (deploy/install-deps.sh installs it too)
# and the pinned npm packages (npm ci from package-lock.json). Run it before cmake: the
# catgs-viewer target exists only when client/web/node_modules does.
# Usage: install-deps.sh [--no-browser]   (--no-browser: only what building the viewer needs;
# deploy/install-deps.sh calls it so, the tests' tests/install-deps.sh without it)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
browser=1
[ "${1:-}" = --no-browser ] && browser=0

missing=()
command -v node >/dev/null || missing+=(nodejs)
command -v npm >/dev/null || missing+=(npm)
command -v protoc >/dev/null || missing+=(protobuf-compiler)
[ $browser = 0 ] || [ -x /usr/bin/chromium ] || missing+=(chromium)
if [ ${#missing[@]} -gt 0 ]; then
  echo "client/web/install-deps: installing ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update -q
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "client/web/install-deps: node, npm, protoc and chromium present"
fi
cd "$here"
# esbuild's install script only checks its platform binary, which npm installs as an optional
# dependency (@esbuild/linux-x64) anyway; no other package runs install scripts.
npm ci --no-audit --no-fund --loglevel=error
