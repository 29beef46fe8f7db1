#!/usr/bin/env bash
# Installs what tests/deploy/check-manifests.sh needs on Debian 12, idempotently, and the
# pinned npm packages (npm ci from tests/deploy/package-lock.json):
#   yamllint            Debian package yamllint (1.29)
#   kubectl kustomize   Debian package kubernetes-client (kubectl 1.20, kustomize v2.0.3),
#                       only when no kubectl is on PATH already (a newer kubectl from another
#                       source ships /usr/bin/kubectl too and would conflict)
#   node, npm           Debian packages nodejs and npm, only when node is missing
# The health-probe build step uses libgrpc++-dev and pkg-config from deploy/install-deps.sh.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)

missing=()
have() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
have yamllint || missing+=(yamllint)
command -v kubectl >/dev/null || have kubernetes-client || missing+=(kubernetes-client)
command -v node >/dev/null || missing+=(nodejs)
command -v npm >/dev/null || missing+=(npm)
if [ ${#missing[@]} -gt 0 ]; then
  echo "tests/deploy/install-deps: installing ${missing[*]}"
  sudo_cmd=()
  [ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get update -q
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "tests/deploy/install-deps: yamllint, kubectl, node and npm present"
fi
cd "$here"
npm ci --no-audit --no-fund --loglevel=error
sha256sum package-lock.json | cut -d' ' -f1 > node_modules/.catgs-lock.sha256
