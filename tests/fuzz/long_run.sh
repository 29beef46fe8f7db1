#!/usr/bin/env bash
# Long fuzz runs (the closing notes' "10 million executions per target"): each target gets K
# parallel libFuzzer jobs, seeded with the checked-in corpus, each job stopping after 10M/K
# executions or SECONDS. Prints the executions per target summed over its jobs, its findings
# (crash inputs in OUT/<target>/art/) and the sanitizer reports in its logs.
#
# Usage: tests/fuzz/long_run.sh SECONDS TARGET:K [TARGET:K ...]
#   e.g. tests/fuzz/long_run.sh 540 fuzz_ply:4 fuzz_splat:4 fuzz_stream_request:1
# Environment: FUZZ_BIN [build-fuzz/tests/fuzz], FUZZ_CORPUS [tests/fuzz/corpus],
#              OUT [fuzz-long], FUZZ_TIMEOUT [10: seconds one input may take]. On a bare host,
#              bundle the targets with deploy/bundle.sh and point FUZZ_BIN at the bundle's bin/.
#              Run under `nice` on a machine doing other work, raise FUZZ_TIMEOUT: a starved
#              job's input is reported as a timeout (here 10 s for inputs that take 0.2 s).
set -uo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=$(realpath "${FUZZ_BIN:-$root/build-fuzz/tests/fuzz}")
corpus=$(realpath "${FUZZ_CORPUS:-$root/tests/fuzz/corpus}")
out=$(realpath -m "${OUT:-fuzz-long}")
[ $# -ge 2 ] || { echo "usage: $0 SECONDS TARGET:K [TARGET:K ...]" >&2; exit 2; }
seconds=$1; shift
export ASAN_OPTIONS="abort_on_error=1:detect_leaks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
for spec in "$@"; do
  t=${spec%%:*}; k=${spec##*:}
  [ -x "$bin/$t" ] || { echo "long_run: no target $bin/$t" >&2; exit 2; }
  d=$out/$t; mkdir -p "$d/new" "$d/art"
  # New inputs go to new/ (the checked-in corpus is only read); -jobs writes fuzz-N.log here.
  ( cd "$d" && "$bin/$t" -jobs="$k" -workers="$k" -runs=$((10000000 / k + 1)) -max_total_time="$seconds" \
      -timeout="${FUZZ_TIMEOUT:-10}" -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$d/art/" "$d/new" "$corpus/$t" \
      > "$d/driver.log" 2>&1 ) &
done
wait
status=0
for spec in "$@"; do
  t=${spec%%:*}; d=$out/$t
  execs=$(cat "$d"/fuzz-*.log 2>/dev/null | grep -ho 'stat::number_of_executed_units: [0-9]*' | awk '{s += $2} END {print s + 0}')
  finds=$(find "$d/art" -type f | wc -l)
  reports=$(cat "$d"/fuzz-*.log 2>/dev/null | grep -c -E "ERROR: (AddressSanitizer|libFuzzer|LeakSanitizer)|runtime error")
  echo "$t jobs=${spec##*:} executions=$execs findings=$finds reports=$reports"
  [ "$finds" = 0 ] && [ "$reports" = 0 ] || status=1
done
exit $status
