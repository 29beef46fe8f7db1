#!/usr/bin/env bash
# Builds catgs-health-probe (deploy/docker/catgs-health-probe.cpp), the container image's
# HEALTHCHECK binary, against the system's libgrpc++ (deploy/install-deps.sh installs it).
# The Dockerfile runs this script, and tests/deploy/check-manifests.sh runs it too, so CI
# compiles exactly what the image compiles. Usage:
#   deploy/docker/build-health-probe.sh OUT_BINARY      (CXX and CXXFLAGS are honoured)
set -euo pipefail
if [ $# -ne 1 ]; then
  echo "usage: $0 OUT_BINARY" >&2
  exit 2
fi
src="$(cd "$(dirname "$0")" && pwd)/catgs-health-probe.cpp"
pkg-config --exists grpc++ || { echo "build-health-probe: pkg-config finds no grpc++ (run deploy/install-deps.sh)" >&2; exit 1; }
# shellcheck disable=SC2046,SC2086  # pkg-config's output and CXXFLAGS are word lists
"${CXX:-g++}" -std=c++17 -O2 -Wall -Wextra ${CXXFLAGS:-} "$src" -o "$1" $(pkg-config --cflags --libs grpc++)
echo "build-health-probe: built $1"
