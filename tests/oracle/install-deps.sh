#!/usr/bin/env bash
# Installs the scene-format oracle, @playcanvas/splat-transform (pinned with its dependencies
# in tests/oracle/package-lock.json), into tests/oracle/node_modules with `npm ci`.
# tests/test_scene_oracle.cpp runs node_modules/.bin/splat-transform; it skips without it
# (fails when CATGS_REQUIRE_ORACLE=1, as CI sets). Needs node and npm (Debian packages nodejs
# and npm; tests/deploy/install-deps.sh installs them when missing).
# --ignore-scripts: the only install script in the tree is webgpu's postinstall, which only
# clears macOS's quarantine attribute from its prebuilt binding (a no-op here). Without a GPU
# (no Vulkan), SOG output needs splat-transform's `-g cpu`.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
if ! command -v npm >/dev/null; then
  echo "tests/oracle/install-deps: npm missing; installing nodejs and npm"
  sudo_cmd=()
  [ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update -q
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends nodejs npm
fi
cd "$here"
npm ci --no-audit --no-fund --ignore-scripts --loglevel=error
