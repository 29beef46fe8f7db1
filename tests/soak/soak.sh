#!/usr/bin/env bash
# Soak test: `catgs-client load` with STREAMS concurrent streams for DURATION seconds against
# one catgs-server process (CPU backend, loopback only), while the server's resident set size
# is sampled from /proc/PID/status into a CSV. Prints the RSS over time, the latency
# percentiles and the errors, and a plateau verdict: the RSS growth over the second half of
# the run (least-squares slope times the half's length) must stay within
# max(SOAK_RSS_BOUND_MB, SOAK_RSS_BOUND_PCT % of the mean RSS of that half).
#
# Usage: tests/soak/soak.sh STREAMS DURATION_S OUT_DIR
#   e.g. tests/soak/soak.sh 32 300 soak-out      (the full soak, outside CI)
#        tests/soak/soak.sh 8 20 soak-short      (the ctest ServerSoak.Short)
#        tests/soak/soak.sh --analyze OUT_DIR    (summary and verdict of a finished run, again)
# Environment (defaults in brackets):
#   CATGS_SERVER, CATGS_CLIENT   binaries [build/server/catgs-server, build/client/catgs-client]
#   SOAK_SCENE        [city=builtin:city?gaussians=50000&seed=1]
#   SOAK_WIDTH/HEIGHT [320/180]   SOAK_RATE poses/s per stream [10]   SOAK_ENCODING [jpeg]
#   SOAK_SAMPLE_S     RSS sampling period [1 for runs up to 60 s, else 5]
#   SOAK_RENDER_WORKERS [2]  SOAK_RENDER_THREADS [0: all cores]
#   SOAK_RSS_BOUND_MB [16]  SOAK_RSS_BOUND_PCT [10]
# Files in OUT_DIR: rss.csv (t_s,rss_kb,hwm_kb,threads: the samples while the client ran),
# rss-after.csv (one sample after every session closed), run.env, report.json (the client's),
# client.txt, client.err, server.log, summary.txt.
# Exit status 0 when the client and the server exited cleanly, every stream ended OK with no
# frame errors and the RSS plateaued; 1 otherwise; 2 on bad arguments.
set -uo pipefail

bound_mb=${SOAK_RSS_BOUND_MB:-16}
bound_pct=${SOAK_RSS_BOUND_PCT:-10}

# analyze OUT_DIR: prints the summary (also into OUT_DIR/summary.txt); returns the verdict.
analyze() {
  local dir=$1
  # shellcheck disable=SC1091
  . "$dir/run.env"
  {
    echo "== catgs soak: $streams streams x ${duration} s, ${width}x${height} $encoding at ${rate} Hz, CPU backend =="
    echo "client exit $client_rc, server exit $server_rc (SIGTERM after the run)"
    sed -n '/^load:/,$p' "$dir/client.txt"
    echo "-- server RSS (MiB) over time, sampled every ${sample} s ($(($(wc -l < "$dir/rss.csv") - 1)) samples in rss.csv)"
    awk -F, -v end="$t_client_end" -v bound_mb="$bound_mb" -v bound_pct="$bound_pct" '
      NR == 1 { next }
      { n++; t[n] = $1; r[n] = $2; h = $3; th = $4 }
      END {
        if (n < 4) { print "too few samples"; print "VERDICT: UNKNOWN"; exit }
        split("0 10 25 50 75 90 100", q, " ")
        line = ""
        for (i = 1; i <= 7; i++) {
          k = int((n - 1) * q[i] / 100) + 1
          line = line sprintf("  t=%4.0fs %6.1f", t[k], r[k] / 1024)
        }
        print line
        # Second half of the run: least-squares slope of RSS against time.
        half = end / 2; m = 0; st = 0; sr = 0; stt = 0; str = 0; rmax1 = 0; rmax2 = 0; first_t = -1
        for (i = 1; i <= n; i++) {
          if (t[i] < half) { if (r[i] > rmax1) rmax1 = r[i]; continue }
          if (first_t < 0) first_t = t[i]
          m++; st += t[i]; sr += r[i]; stt += t[i] * t[i]; str += t[i] * r[i]
          if (r[i] > rmax2) rmax2 = r[i]
          last_t = t[i]
        }
        den = m * stt - st * st
        slope = (m > 1 && den > 0) ? (m * str - st * sr) / den : 0
        mean = m > 0 ? sr / m : 0
        growth = slope * (last_t - first_t)
        bound = bound_mb * 1024
        if (bound_pct * mean / 100 > bound) bound = bound_pct * mean / 100
        printf "  peak RSS: first half %.1f MiB, second half %.1f MiB (VmHWM %.1f MiB); %d threads\n", rmax1 / 1024, rmax2 / 1024, h / 1024, th
        printf "  second half (%.0f-%.0f s, %d samples): mean %.1f MiB, slope %.2f KiB/s, growth %.1f MiB, bound %.1f MiB\n", first_t, last_t, m, mean / 1024, slope, growth / 1024, bound / 1024
        print (growth <= bound ? "VERDICT: PLATEAU" : "VERDICT: GROWING")
      }' "$dir/rss.csv"
    awk -F, 'NR == 2 { printf "  after every session closed: %.1f MiB\n", $2 / 1024 }' "$dir/rss-after.csv" 2>/dev/null
  } | tee "$dir/summary.txt"

  local status=0 codes errors frames
  grep -q "VERDICT: PLATEAU" "$dir/summary.txt" || { echo "soak: FAIL: server RSS did not plateau"; status=1; }
  [ "$client_rc" -eq 0 ] || { echo "soak: FAIL: catgs-client exited $client_rc"; tail -5 "$dir/client.err"; status=1; }
  [ "$server_rc" -eq 0 ] || { echo "soak: FAIL: catgs-server exited $server_rc"; tail -5 "$dir/server.log"; status=1; }
  codes=$(sed -n 's/^  status codes://p' "$dir/client.txt")
  [ "$codes" = " OK=$streams" ] || { echo "soak: FAIL: stream statuses:$codes"; status=1; }
  errors=$(awk '/frame errors/ {print $NF}' "$dir/client.txt")
  [ "${errors:-x}" = "0" ] || { echo "soak: FAIL: ${errors:-?} frame errors"; status=1; }
  frames=$(awk '/frames received/ {print $NF}' "$dir/client.txt")
  [ "${frames:-0}" -gt 0 ] || { echo "soak: FAIL: no frames received"; status=1; }
  [ "$status" -eq 0 ] && echo "soak: PASS ($dir)"
  return "$status"
}

if [ "${1:-}" = "--analyze" ]; then
  [ -f "${2:-}/run.env" ] || { echo "usage: soak.sh --analyze OUT_DIR (the directory of a finished run)" >&2; exit 2; }
  analyze "$2"
  exit
fi

streams=${1:-}
duration=${2:-}
out=${3:-}
if ! [[ "$streams" =~ ^[0-9]+$ && "$duration" =~ ^[0-9]+$ && -n "$out" ]] || [ "$streams" -lt 1 ] || [ "$duration" -lt 4 ]; then
  echo "usage: soak.sh STREAMS DURATION_S OUT_DIR (STREAMS >= 1, DURATION_S >= 4) | soak.sh --analyze OUT_DIR" >&2
  exit 2
fi
repo=$(cd "$(dirname "$0")/../.." && pwd)
server_bin=${CATGS_SERVER:-$repo/build/server/catgs-server}
client_bin=${CATGS_CLIENT:-$repo/build/client/catgs-client}
for b in "$server_bin" "$client_bin"; do
  [ -x "$b" ] || { echo "soak: $b is not an executable (set CATGS_SERVER / CATGS_CLIENT)" >&2; exit 2; }
done
scene=${SOAK_SCENE:-city=builtin:city?gaussians=50000&seed=1}
width=${SOAK_WIDTH:-320}
height=${SOAK_HEIGHT:-180}
rate=${SOAK_RATE:-10}
encoding=${SOAK_ENCODING:-jpeg}
if [ "$duration" -le 60 ]; then sample=${SOAK_SAMPLE_S:-1}; else sample=${SOAK_SAMPLE_S:-5}; fi
mkdir -p "$out"
out=$(cd "$out" && pwd)
rm -f "$out"/{rss.csv,rss-after.csv,run.env,report.json,client.txt,client.err,server.log,server.out,summary.txt}

server_pid=""
sampler_pid=""
cleanup() {
  [ -n "$sampler_pid" ] && kill "$sampler_pid" 2>/dev/null
  [ -n "$server_pid" ] && kill -9 "$server_pid" 2>/dev/null
  return 0
}
trap cleanup EXIT

# Created before the server starts: a background command's redirections are opened in the
# child, after '&' returns, and the first sed below must not find the file missing.
: > "$out/server.out"
"$server_bin" --address 127.0.0.1:0 --backend cpu --scene "$scene" --max-sessions "$streams" \
  --render-workers "${SOAK_RENDER_WORKERS:-2}" --render-threads "${SOAK_RENDER_THREADS:-0}" \
  > "$out/server.out" 2> "$out/server.log" &
server_pid=$!
port=""
for _ in $(seq 1 600); do
  port=$(sed -n 's/^catgs-server: listening on port \([0-9]*\)$/\1/p' "$out/server.out")
  [ -n "$port" ] && break
  kill -0 "$server_pid" 2>/dev/null || { echo "soak: catgs-server exited before listening:" >&2; cat "$out/server.log" >&2; exit 1; }
  sleep 0.1
done
[ -n "$port" ] || { echo "soak: catgs-server did not listen within 60 s" >&2; exit 1; }

now() { date +%s.%N; }
t0=$(now)
sample_once() {
  awk -v t="$(now)" -v t0="$t0" '
    /^VmRSS:/ {rss=$2} /^VmHWM:/ {hwm=$2} /^Threads:/ {th=$2}
    END { if (rss != "") printf "%.1f,%d,%d,%d\n", t - t0, rss, hwm, th }' "/proc/$server_pid/status" 2>/dev/null
}
echo "t_s,rss_kb,hwm_kb,threads" > "$out/rss.csv"
(
  while kill -0 "$server_pid" 2>/dev/null; do
    sample_once >> "$out/rss.csv"
    sleep "$sample"
  done
) &
sampler_pid=$!

echo "soak: $streams streams x ${duration} s at ${rate} Hz, ${width}x${height} $encoding, scene '$scene', server pid $server_pid port $port"
"$client_bin" --server "127.0.0.1:$port" load --scene "${scene%%=*}" --streams "$streams" --duration "$duration" \
  --rate "$rate" --width "$width" --height "$height" --encoding "$encoding" \
  --trajectory 'builtin:flythrough?frames=600&altitude=60' --json-out "$out/report.json" \
  > "$out/client.txt" 2> "$out/client.err"
client_rc=$?
t_client_end=$(awk -v t="$(now)" -v t0="$t0" 'BEGIN { printf "%.1f", t - t0 }')
kill "$sampler_pid" 2>/dev/null
wait "$sampler_pid" 2>/dev/null
sampler_pid=""
# Every session has closed: what the server gives back.
sleep 1
{ echo "t_s,rss_kb,hwm_kb,threads"; sample_once; } > "$out/rss-after.csv"
kill -TERM "$server_pid"
wait "$server_pid"
server_rc=$?
server_pid=""
cat > "$out/run.env" <<ENV
streams=$streams
duration=$duration
width=$width
height=$height
encoding=$encoding
rate=$rate
sample=$sample
t_client_end=$t_client_end
client_rc=$client_rc
server_rc=$server_rc
ENV
analyze "$out"
