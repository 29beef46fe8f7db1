#!/usr/bin/env bash
# The GPU benchmark runs quoted in the issue notes, in one place. Runs on the GPU host from a
# bundle (deploy/bundle.sh): time against error for every pipeline configuration on
#   - the built-in city, 6M Gaussians, SH degree 3, 1080p and 4K, survey at 75 m, -45 deg,
#     8 m/s, 30 fps, 300 frames;
#   - hq_garden_lod2.splat replicated 3x3 (~7.4M Gaussians), survey at 120 m, 1080p;
#   - the city on an orbit at 75 m, 1080p: a camera that always turns.
# Usage: gpu_benchmarks.sh BIN_DIR SHARED_DIR OUT_DIR
set -euo pipefail
bin=$1 shared=$2 out=$3
mkdir -p "$out"
log=$(mktemp -d)  # full tables stay here: only JSON and CSV go to OUT_DIR
city='builtin:city?gaussians=6000000&seed=1'
survey='builtin:survey?altitude=75&pitch=-45&speed=8&fps=30&frames=300'
garden="$shared/data/scenes/hq-garden/hq_garden_lod2.splat"
garden_survey='builtin:survey?altitude=120&pitch=-45&speed=8&fps=30&frames=300'
orbit='builtin:orbit?altitude=75&speed=8&fps=30&frames=300'

# Each entry's flags apply over the defaults (default_pipeline_options: cache, order reused
# while translating, split 8192, guard 1 px), so the plain pipeline says --cache off --split off,
# and the exact-order cache of session 3 says --resort on --split off --guard-px 2.
plain='--cache off --split off'
exact_cache='--resort on --split off --guard-px 2'
full="default: ; default-paper: --reuse-order-max-deg any; default-resort: --resort on; default-nosplit: --split off;
default-split-2048: --split 2048; default-split-auto: --split auto; default-guard-2: --guard-px 2; default-W4: --window 4;
bbox3sigma: --culling bbox3sigma $plain; opacity-aware: $plain; opacity-aware-nochunks: $plain --chunks off;
split-1024: --cache off --split 1024; split-2048: --cache off --split 2048; split-4096: --cache off --split 4096;
split-auto: --cache off --split auto;
cache-W1: $exact_cache --window 1; cache-W2: $exact_cache --window 2; cache-W4: $exact_cache --window 4;
cache-W8: $exact_cache --window 8; cache-W16: $exact_cache --window 16; cache-adaptive: $exact_cache;
cache-W4-paper: --split off --guard-px 2 --window 4 --reuse-order-max-deg any"
short="default: ; default-paper: --reuse-order-max-deg any; default-resort: --resort on; opacity-aware: $plain;
bbox3sigma: --culling bbox3sigma $plain; split-2048: --cache off --split 2048; cache-adaptive: $exact_cache"
turning="default: ; default-paper: --reuse-order-max-deg any; default-resort: --resort on; opacity-aware: $plain"

run() {
  local name=$1; shift
  echo "=== $name"
  "$bin/catgs-bench" "$@" --reference opacity-aware --error-every 10 --quiet \
    --json-out "$out/$name.json" --csv-out "$out/$name.csv" > "$log/$name.txt" 2>&1 || { tail -5 "$log/$name.txt"; return 1; }
  sed -n '/^configuration/,$p' "$log/$name.txt"
}
run city1080 --scene "$city" --trajectory "$survey" --width 1920 --height 1080 --sweep "$full"
run city2160 --scene "$city" --trajectory "$survey" --width 3840 --height 2160 --sweep "$short"
run garden1080 --scene "$garden" --grid 3x3 --up z --trajectory "$garden_survey" --width 1920 --height 1080 --sweep "$full"
run cityorbit1080 --scene "$city" --trajectory "$orbit" --width 1920 --height 1080 --sweep "$turning"
