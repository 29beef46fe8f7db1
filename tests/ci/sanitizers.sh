#!/usr/bin/env bash
# Sanitizer and fuzzing jobs of CI (issue 7). Configures, builds and runs, with clang 14:
#
#   asan  the whole CPU test suite (ctest label "cpu", catgs_tests) under AddressSanitizer +
#         UndefinedBehaviorSanitizer                                  (build-asan/)
#   tsan  the server's session/worker tests (label "server", catgs_server_tests, which also
#         start the catgs-server binary) under ThreadSanitizer        (build-tsan/)
#   fuzz  every libFuzzer target of tests/fuzz (ASan + UBSan) for a smoke run seeded with the
#         checked-in corpus, then the corpus replay tests (label "fuzz") (build-fuzz/)
#
# Usage: tests/ci/sanitizers.sh [asan] [tsan] [fuzz]     (no argument: all three, in this order)
# Environment:
#   CATGS_SAN_JOBS       parallel compile jobs, test processes and fuzzers (default 2)
#   CATGS_FUZZ_SECONDS   seconds per fuzz target (default 60: 13 targets, 2 at a time, 6.5 min)
#   CATGS_ASAN_CTEST_ARGS extra ctest arguments for the asan job, e.g. "-E AccuracyBar" to
#                        leave out the longest test (it takes most of the job's time)
#   CATGS_SAN_BUILD_ROOT where build-asan/, build-tsan/, build-fuzz/ go (default: the checkout)
#   CATGS_SAN_CC, CATGS_SAN_CXX  compilers (default clang-14, clang++-14)
# Debian packages beyond deploy/install-deps.sh: clang-14 libclang-rt-14-dev llvm-14
# (llvm-14 for llvm-symbolizer: stack traces with file and line). Ninja is used when present.
#
# Every sanitizer report aborts the process that hit it (-fno-sanitize-recover, halt_on_error),
# so it fails that test or fuzz run. The script runs every selected job even after a failure,
# prints a summary with the time of each step, and exits 1 if anything failed.
# Fuzz findings are saved to build-fuzz/fuzz-artifacts/<target>/ (reproduce with
# build-fuzz/tests/fuzz/<target> FILE); copy them into tests/fuzz/corpus/<target>/crash_<what>
# once fixed, so that the corpus replay keeps them fixed.
set -uo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
JOBS=${CATGS_SAN_JOBS:-2}
FUZZ_SECONDS=${CATGS_FUZZ_SECONDS:-60}
BUILD_ROOT=${CATGS_SAN_BUILD_ROOT:-$ROOT}
CC_BIN=${CATGS_SAN_CC:-clang-14}
CXX_BIN=${CATGS_SAN_CXX:-clang++-14}

jobs_selected=("$@")
[ ${#jobs_selected[@]} -eq 0 ] && jobs_selected=(asan tsan fuzz)
for j in "${jobs_selected[@]}"; do
  case $j in asan | tsan | fuzz) ;; *) echo "sanitizers.sh: unknown job '$j' (expected asan, tsan, fuzz)" >&2; exit 2 ;; esac
done

for tool in "$CC_BIN" "$CXX_BIN" cmake; do
  command -v "$tool" >/dev/null || { echo "sanitizers.sh: '$tool' not found (Debian: clang-14 libclang-rt-14-dev llvm-14)" >&2; exit 2; }
done
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)

# Symbolized reports. llvm-14's symbolizer when installed; the runtimes fall back to
# addresses without it.
symbolizer=""
for s in /usr/lib/llvm-14/bin/llvm-symbolizer "$(command -v llvm-symbolizer-14 || true)"; do
  [ -n "$s" ] && [ -x "$s" ] && { symbolizer=$s; break; }
done
sym_opt=${symbolizer:+:external_symbolizer_path=$symbolizer}
export ASAN_OPTIONS="abort_on_error=1:detect_leaks=1:detect_stack_use_after_return=1:check_initialization_order=1:strict_init_order=1$sym_opt"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1$sym_opt"
# ignore_noninstrumented_modules: interceptors called from Debian's uninstrumented gRPC and
# abseil record no memory accesses (see tests/ci/tsan.supp for the rest).
export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:history_size=4:ignore_noninstrumented_modules=1:suppressions=$ROOT/tests/ci/tsan.supp$sym_opt"

summary=()
failed=0
log() { printf '\n=== sanitizers.sh [%s] %s\n' "$(date +%H:%M:%S)" "$*"; }
record() {  # name status seconds detail
  summary+=("$(printf '%-34s %-5s %6ss  %s' "$1" "$2" "$3" "$4")")
  [ "$2" = ok ] || failed=1
}
# step NAME DETAIL CMD...: runs CMD, times it, records ok/FAIL.
step() {
  local name=$1 detail=$2
  shift 2
  log "$name: $*"
  local start=$SECONDS
  if "$@"; then record "$name" ok $((SECONDS - start)) "$detail"; return 0; fi
  record "$name" FAIL $((SECONDS - start)) "$detail"
  return 1
}

configure() {  # build-dir sanitizers extra-cmake-args...
  local dir=$1 sanitize=$2
  shift 2
  cmake -S "$ROOT" -B "$dir" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_C_COMPILER="$CC_BIN" -DCMAKE_CXX_COMPILER="$CXX_BIN" -DCATGS_CUDA=OFF \
    -DCATGS_SANITIZE="$sanitize" "$@"
}

# --- ASan + UBSan: the CPU suite ---------------------------------------------------------
job_asan() {
  local dir=$BUILD_ROOT/build-asan
  build() { configure "$dir" address,undefined -DCATGS_FUZZ=OFF && cmake --build "$dir" -j"$JOBS" --target catgs_tests; }
  step "asan: configure+build catgs_tests" "$dir" build || return
  # The sanitizers slow the suite down ~3-5x; the longest test, CatgsCache.AccuracyBarOverUavPaths,
  # took 3 to 11 minutes here (2 shared cores), the rest of the suite about 1 minute.
  local extra=()
  read -r -a extra <<<"${CATGS_ASAN_CTEST_ARGS:-}"
  step "asan: ctest -L cpu" "catgs_tests, ASan+UBSan" \
    ctest --test-dir "$dir" -L cpu -j"$JOBS" --output-on-failure --timeout 1800 "${extra[@]}"
}

# --- TSan: the server's session and worker tests ------------------------------------------
job_tsan() {
  local dir=$BUILD_ROOT/build-tsan
  build() {
    configure "$dir" thread -DCATGS_FUZZ=OFF && cmake --build "$dir" -j"$JOBS" --target catgs_server_tests catgs_encoder_tests catgs-server
  }
  step "tsan: configure+build server tests" "$dir" build || return
  step "tsan: ctest -L server" "catgs_server_tests, catgs_encoder_tests + catgs-server, TSan" tsan_tests "$dir"
}

# The server suite under TSan, which slows it ~5-10x (the tests' timing bounds grow by
# CATGS_TIMING_SLACK under sanitizers). A failure fails the job, with or without a TSan report:
# a test that passes only on a second try is a bug to fix, not to retry.
tsan_tests() {
  local dir=$1 log=$1/tsan-ctest.log
  ctest --test-dir "$dir" -L server -j"$JOBS" --output-on-failure --timeout 600 2>&1 | tee "$log"
  [ "${PIPESTATUS[0]}" = 0 ] || return 1
  ! grep -q "WARNING: ThreadSanitizer" "$log"
}

# --- libFuzzer smoke runs -------------------------------------------------------------------
fuzz_one() {  # target: runs it, leaves out/<target>.{log,rc}
  local t=$1 dir=$BUILD_ROOT/build-fuzz
  local work=$dir/fuzz-work/$t art=$dir/fuzz-artifacts/$t
  rm -rf "$work" && mkdir -p "$work" "$art"
  # New inputs go to the work folder; the checked-in corpus is only read.
  "$dir/tests/fuzz/$t" -max_total_time="$FUZZ_SECONDS" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$art/" "$work" "$ROOT/tests/fuzz/corpus/$t" >"$dir/fuzz-logs/$t.log" 2>&1
  echo $? >"$dir/fuzz-logs/$t.rc"
}

job_fuzz() {
  local dir=$BUILD_ROOT/build-fuzz
  build() {
    configure "$dir" address,undefined -DCATGS_FUZZ=ON -DCATGS_BUILD_TESTS=OFF &&
      cmake --build "$dir" -j"$JOBS" --target catgs_fuzz
  }
  step "fuzz: configure+build targets" "$dir" build || return
  local targets=()
  for path in "$ROOT"/tests/fuzz/corpus/*/; do
    local t
    t=$(basename "$path")
    [ -x "$dir/tests/fuzz/$t" ] && targets+=("$t")
  done
  rm -rf "$dir/fuzz-logs" "$dir/fuzz-artifacts" && mkdir -p "$dir/fuzz-logs"
  log "fuzz: ${#targets[@]} targets x ${FUZZ_SECONDS}s, $JOBS at a time: ${targets[*]}"
  local start=$SECONDS running=0
  for t in "${targets[@]}"; do
    if [ "$running" -ge "$JOBS" ]; then wait -n; running=$((running - 1)); fi
    fuzz_one "$t" &
    running=$((running + 1))
  done
  wait
  local total=$((SECONDS - start))
  for t in "${targets[@]}"; do
    local rc execs findings
    rc=$(cat "$dir/fuzz-logs/$t.rc" 2>/dev/null || echo 255)
    execs=$(grep -ho 'stat::number_of_executed_units: [0-9]*' "$dir/fuzz-logs/$t.log" | awk '{print $2}')
    findings=$(find "$dir/fuzz-artifacts/$t" -type f | wc -l)
    if [ "$rc" = 0 ] && [ "$findings" = 0 ]; then
      record "fuzz: $t" ok "$FUZZ_SECONDS" "${execs:-?} executions"
    else
      record "fuzz: $t" FAIL "$FUZZ_SECONDS" "rc $rc, $findings finding(s) in $dir/fuzz-artifacts/$t"
      echo "--- $t: last lines of $dir/fuzz-logs/$t.log"
      tail -n 40 "$dir/fuzz-logs/$t.log"
    fi
  done
  summary+=("$(printf '%-34s %-5s %6ss  %s' "fuzz: smoke runs (wall)" "" "$total" "")")
  step "fuzz: corpus replay (ctest -L fuzz)" "every checked-in input once" \
    ctest --test-dir "$dir" -L fuzz -j"$JOBS" --output-on-failure
}

overall=$SECONDS
for j in "${jobs_selected[@]}"; do "job_$j"; done

log "summary (clang: $("$CXX_BIN" --version | head -n1); symbolizer: ${symbolizer:-none})"
printf '%s\n' "${summary[@]}"
printf 'total %ss\n' $((SECONDS - overall))
if [ "$failed" -ne 0 ]; then
  echo "sanitizers.sh: FAILED"
  exit 1
fi
echo "sanitizers.sh: all passed"
