#!/usr/bin/env bash
# Installs the Debian 12 packages catgs builds and tests with. Idempotent: packages already
# present are not touched, and nothing runs apt-get when all are installed. Run as root.
# CUDA is not installed here: the build uses /usr/local/cuda/bin/nvcc when it exists.
# Then, where the checkout has it, the browser viewer's build tools (client/web/install-deps.sh
# --no-browser: node, npm and the pinned npm packages), so that cmake finds them.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
web_deps() {
  # The Docker build copies this script alone: no viewer there.
  [ -f "$root/client/web/install-deps.sh" ] || return 0
  bash "$root/client/web/install-deps.sh" --no-browser
}

packages=(
  build-essential cmake pkg-config git ca-certificates
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libglm-dev libopenimageio-dev libspdlog-dev libgtest-dev libgmock-dev libcli11-dev
  nlohmann-json3-dev libturbojpeg0-dev libpng-dev patchelf gnuplot-nox
  grpc-proto openssl
  libwebp-dev libzip-dev libtinygltf-dev libboost-dev libdeflate-dev libspng-dev libssl-dev libzstd-dev
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  web_deps
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
sudo_cmd=()
[ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
"${sudo_cmd[@]}" apt-get update -q
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
web_deps
