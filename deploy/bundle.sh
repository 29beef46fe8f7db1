#!/usr/bin/env bash
# Packs built catgs binaries with the shared libraries they need that a bare Ubuntu 24.04 +
# NVIDIA driver host lacks, into one relocatable folder:
#   OUT/bin/<binaries>   RUNPATH $ORIGIN/../lib
#   OUT/lib/<libraries>  RUNPATH $ORIGIN (a library's own dependencies are not covered by
#                        the binary's RUNPATH, so every copied library gets one too)
# glibc, libstdc++/libgcc (the target's are newer and backward compatible) and the NVIDIA
# driver libraries are left to the host. Usage:
#   deploy/bundle.sh OUT_DIR BINARY [BINARY...]
# BUNDLE_LIBS_FROM=BUNDLE_DIR: a variant for an A/B (renderer/tools/gpu_regression.sh EXTRA_BINS):
# OUT/lib is a relative link to that bundle's lib/, which must already hold every library the
# binaries need, so several variants travel to the GPU machine with one copy of the libraries.
set -euo pipefail

if [ $# -lt 2 ]; then
  echo "usage: $0 OUT_DIR BINARY [BINARY...]" >&2
  exit 2
fi
out=$1
shift
command -v patchelf >/dev/null || { echo "bundle: patchelf is missing (apt-get install patchelf)" >&2; exit 1; }
libs_from=${BUNDLE_LIBS_FROM:-}
mkdir -p "$out/bin"
if [ -n "$libs_from" ]; then
  [ -d "$libs_from/lib" ] || { echo "bundle: BUNDLE_LIBS_FROM=$libs_from has no lib/ folder" >&2; exit 1; }
  [ -e "$out/lib" ] && [ ! -L "$out/lib" ] && { echo "bundle: $out/lib exists and is not a link" >&2; exit 1; }
  ln -sfn "$(realpath --relative-to="$out" "$libs_from/lib")" "$out/lib"
else
  mkdir -p "$out/lib"
fi

# Host-provided: the C library family, the C++ runtime and the GPU driver.
host_provided='^(linux-vdso|ld-linux|libc\.so|libm\.so|libpthread|libdl\.so|librt\.so|libresolv|libutil|libanl|libstdc\+\+|libgcc_s|libcuda\.so|libnvidia-)'

declare -A copied=()
copy_deps() {
  local file=$1
  local line name path
  while read -r line; do
    name=$(awk '{print $1}' <<<"$line")
    path=$(awk '$2 == "=>" {print $3}' <<<"$line")
    [ -n "$path" ] && [ -f "$path" ] || continue
    [[ $name =~ $host_provided ]] && continue
    [ -n "${copied[$name]:-}" ] && continue
    copied[$name]=1
    if [ -n "$libs_from" ]; then
      [ -f "$out/lib/$name" ] || { echo "bundle: $name is not in $libs_from/lib (bundle it there first)" >&2; exit 1; }
      continue
    fi
    cp -L "$path" "$out/lib/$name"
    chmod u+w "$out/lib/$name"
    patchelf --set-rpath '$ORIGIN' "$out/lib/$name"
  done < <(ldd "$file" | grep '=>' || true)
}

for binary in "$@"; do
  [ -x "$binary" ] || { echo "bundle: $binary is not an executable" >&2; exit 1; }
  cp -L "$binary" "$out/bin/"
  target="$out/bin/$(basename "$binary")"
  chmod u+w "$target"
  patchelf --set-rpath '$ORIGIN/../lib' "$target"
  copy_deps "$binary"
done
if [ -n "$libs_from" ]; then
  echo "bundle: $(ls "$out/bin" | wc -l) binaries, their ${#copied[@]} libraries shared with $libs_from, in $out"
else
  echo "bundle: $(ls "$out/bin" | wc -l) binaries, ${#copied[@]} libraries ($(du -sh "$out" | cut -f1)) in $out"
fi
