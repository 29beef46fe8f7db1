#!/usr/bin/env bash
# The main job: start catgs-server on the built-in city (CUDA when a device is usable, else the
# CPU backend) on an ephemeral loopback port, stream a UAV survey through catgs-client, save
# the received frames and print latency and fps, then stop the server with SIGTERM. Poses go
# in lock step (--rate 0: the next pose when a frame arrives) so that every frame of the flight
# is rendered even on the CPU backend; CATGS_DEMO_RATE=30 streams in real time instead (a slow
# backend then coalesces poses: latest pose wins). It ends by printing the browser viewer's URL
# (the server's --web-address, docs/viewer.md); from a terminal the server then keeps serving
# until Ctrl-C so the viewer can be opened, otherwise for CATGS_DEMO_SERVE_S seconds (default 0).
# CATGS_DEMO_WEB (default 127.0.0.1:0, a free port) is the viewer's address.
# Usage: deploy/demo.sh [BUILD_DIR] [OUT_DIR] [further catgs-client stream flags...]
set -euo pipefail
build=${1:-build}
out=${2:-frames}
shift $(( $# > 2 ? 2 : $# ))
server_log=$(mktemp)
cleanup() {
  if [ -n "${server_pid:-}" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -TERM "$server_pid"
    wait "$server_pid" || true
  fi
  rm -f "$server_log"
}
trap cleanup EXIT

"$build/server/catgs-server" --address 127.0.0.1:0 --scene 'city=builtin:city?gaussians=200000&seed=1' \
  --web-address "${CATGS_DEMO_WEB:-127.0.0.1:0}" > "$server_log" 2> >(sed 's/^/[server] /' >&2) &
server_pid=$!
port=""
for _ in $(seq 1 600); do  # generating the city and starting take a few seconds
  port=$(sed -n 's/^catgs-server: listening on port \([0-9]*\)$/\1/p' "$server_log")
  [ -n "$port" ] && break
  kill -0 "$server_pid" 2>/dev/null || { echo "demo: catgs-server exited before listening" >&2; exit 1; }
  sleep 0.2
done
[ -n "$port" ] || { echo "demo: catgs-server did not start listening within 120 s" >&2; exit 1; }
echo "demo: catgs-server listening on 127.0.0.1:$port"
"$build/client/catgs-client" --server "127.0.0.1:$port" stream --scene city \
  --trajectory 'builtin:survey?frames=90&altitude=80&pitch=-45&speed=8&fps=30' \
  --width 640 --height 360 --rate "${CATGS_DEMO_RATE:-0}" --flight-plan 4 --out "$out" "$@"
echo "demo: frames in $out/"
web=$(sed -n 's/^catgs-server: web viewer on \(.*\)$/\1/p' "$server_log")
if [ -z "$web" ]; then
  echo "demo: catgs-server printed no web viewer address" >&2
elif [ -t 0 ]; then
  echo "demo: open the viewer at $web (the server keeps running; Ctrl-C stops it)"
  wait "$server_pid" || true
else
  echo "demo: the viewer is at $web while the server runs (${CATGS_DEMO_SERVE_S:-0} s more; CATGS_DEMO_SERVE_S sets it)"
  sleep "${CATGS_DEMO_SERVE_S:-0}"
fi
