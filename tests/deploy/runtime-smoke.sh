#!/usr/bin/env bash
# Emulates deploy/Dockerfile's runtime stage without a Docker engine, on built binaries:
#   1. a Debian 12 minbase root (debootstrap; close to debian:12-slim), cached in ROOTFS;
#   2. /opt/catgs from deploy/bundle.sh, as the build stage makes it (catgs-server,
#      catgs-client, catgs-bench and catgs-health-probe from build-health-probe.sh);
#   3. the runtime stage's RUN commands, read from the Dockerfile and run in the root;
#   4. the Dockerfile's ENTRYPOINT as its USER, on a read-only root, in a private network
#      namespace (so its fixed ports clash with nothing), then its HEALTHCHECK command, a
#      scene listing and a short stream through the bundled catgs-client, and SIGTERM
#      (exit status 0 expected).
# Manual, not part of CI: needs root, debootstrap, unshare, and Debian's mirror for step 1.
# Usage: tests/deploy/runtime-smoke.sh [BUILD_DIR (default build)] [ROOTFS (default /tmp/catgs-slimroot)]
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
build=$(cd "${1:-$repo/build}" && pwd)
rootfs=${2:-/tmp/catgs-slimroot}
[ "$(id -u)" = 0 ] || { echo "runtime-smoke: needs root" >&2; exit 2; }
for t in debootstrap unshare chroot node; do command -v $t >/dev/null || { echo "runtime-smoke: $t is missing" >&2; exit 2; }; done

if [ ! -x "$rootfs/bin/bash" ]; then
  echo "runtime-smoke: debootstrap bookworm (minbase) into $rootfs"
  debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian > "$rootfs.log" 2>&1 ||
    { tail "$rootfs.log" >&2; exit 1; }
fi

# The Dockerfile's runtime stage: RUN commands, USER, ENTRYPOINT and HEALTHCHECK CMD.
stage=$(node -e '
  const text = require("fs").readFileSync(process.argv[1], "utf8").replace(/\\\n/g, " ");
  const lines = text.split("\n").map((l) => l.trim()).filter((l) => l && !l.startsWith("#"));
  const from = lines.map((l, i) => (/^FROM /i.test(l) ? i : -1)).filter((i) => i >= 0);
  const rt = lines.slice(from[from.length - 1] + 1);
  const get = (re) => rt.filter((l) => re.test(l));
  console.log(JSON.stringify({
    run: get(/^RUN /).map((l) => l.slice(4)),
    user: get(/^USER /).map((l) => l.slice(5))[0],
    entrypoint: JSON.parse(get(/^ENTRYPOINT /)[0].slice(11)),
    healthcheck: JSON.parse(get(/^HEALTHCHECK /)[0].match(/CMD (\[.*\])$/)[1]),
  }));' "$repo/deploy/Dockerfile")
field() { node -e 'const s=JSON.parse(process.argv[1]); const v=s[process.argv[2]]; console.log(Array.isArray(v) ? v.join("\n") : v)' "$stage" "$1"; }

echo "runtime-smoke: bundling into $rootfs/opt/catgs"
rm -rf "$rootfs/opt/catgs"
bash "$repo/deploy/docker/build-health-probe.sh" "$build/catgs-health-probe" > /dev/null
bash "$repo/deploy/bundle.sh" "$rootfs/opt/catgs" "$build/server/catgs-server" "$build/client/catgs-client" \
  "$build/renderer/catgs-bench" "$build/catgs-health-probe"

# Fresh user database each time: the RUN lines create the user.
chroot "$rootfs" /bin/bash -c 'userdel catgs 2>/dev/null; groupdel catgs 2>/dev/null; true'
mapfile -t entrypoint < <(field entrypoint)
mapfile -t healthcheck < <(field healthcheck)
user=$(field user)
export rootfs user
unshare -m -n /bin/bash -s -- "$(field run)" "${#entrypoint[@]}" "${entrypoint[@]}" "${healthcheck[@]}" <<'EOF'
set -euo pipefail
run=$1; n=$2; shift 2
entrypoint=("${@:1:$n}"); healthcheck=("${@:$((n + 1))}")
mount -t proc proc "$rootfs/proc"
ip link set lo up 2>/dev/null || true
while IFS= read -r cmd; do
  echo "runtime-smoke: RUN $cmd"
  chroot "$rootfs" /bin/sh -c "$cmd"
done <<< "$run"
# Read-only root, as readOnlyRootFilesystem: true (proc again on top of the new bind mount:
# the loader needs /proc/self/exe to resolve the bundle's $ORIGIN RUNPATH).
umount "$rootfs/proc"
mount --bind "$rootfs" "$rootfs" && mount -o remount,bind,ro "$rootfs"
mount -t proc proc "$rootfs/proc"
as_user=(chroot --userspec="$user" "$rootfs")
echo "runtime-smoke: ENTRYPOINT ${entrypoint[*]} --backend cpu --scene city=builtin:city?gaussians=20000 (as $user, read-only root)"
"${as_user[@]}" "${entrypoint[@]}" --backend cpu --scene 'city=builtin:city?gaussians=20000' > /tmp/runtime-smoke.out 2> /tmp/runtime-smoke.err &
pid=$!
for _ in $(seq 1 100); do "${as_user[@]}" "${healthcheck[@]}" > /dev/null 2>&1 && break; sleep 0.2; done
echo "runtime-smoke: HEALTHCHECK ${healthcheck[*]}"
"${as_user[@]}" "${healthcheck[@]}"
"${as_user[@]}" /opt/catgs/bin/catgs-client --server 127.0.0.1:50051 scenes list
"${as_user[@]}" /opt/catgs/bin/catgs-client --server 127.0.0.1:50051 stream \
  --trajectory 'builtin:survey?frames=20' --width 160 --height 90 --max-frames 20 | tail -1
if touch "$rootfs/probe-write" 2>/dev/null; then echo "runtime-smoke: the root is writable" >&2; exit 1; fi
kill -TERM $pid
status=0; wait $pid || status=$?
cat /tmp/runtime-smoke.out; tail -2 /tmp/runtime-smoke.err
[ $status = 0 ] || { echo "runtime-smoke: server exit status $status after SIGTERM" >&2; exit 1; }
echo "runtime-smoke: OK"
EOF
