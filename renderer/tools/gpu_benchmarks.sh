#!/usr/bin/env bash
# The GPU benchmark runs quoted in the issue notes, in one place. Runs on the GPU host from a
# bundle (deploy/bundle.sh): time against error for every pipeline configuration on
#   - the built-in city, 6M Gaussians, SH degree 3, 1080p and 4K, survey at 75 m, -45 deg,
#     8 m/s, 30 fps, 300 frames;
#   - hq_garden_lod2.splat replicated 3x3 (~7.4M Gaussians), survey at 120 m, 1080p.
# Usage: gpu_benchmarks.sh BIN_DIR SHARED_DIR OUT_DIR
set -euo pipefail
bin=$1 shared=$2 out=$3
mkdir -p "$out"
log=$(mktemp -d)  # full tables stay here: only JSON and CSV go to OUT_DIR
city='builtin:city?gaussians=6000000&seed=1'
survey='builtin:survey?altitude=75&pitch=-45&speed=8&fps=30&frames=300'
garden="$shared/data/scenes/hq-garden/hq_garden_lod2.splat"
garden_survey='builtin:survey?altitude=120&pitch=-45&speed=8&fps=30&frames=300'

full='bbox3sigma: --culling bbox3sigma; bbox3sigma-nochunks: --culling bbox3sigma --chunks off;
opacity-aware: ; opacity-aware-nochunks: --chunks off; catgs-nochunks: --cache speculative --split auto --chunks off;
split-256: --split 256; split-512: --split 512; split-1024: --split 1024; split-2048: --split 2048; split-auto: --split auto;
cache-W1: --cache speculative --window 1; cache-W2: --cache speculative --window 2; cache-W4: --cache speculative --window 4;
cache-W8: --cache speculative --window 8; cache-W16: --cache speculative --window 16; cache-adaptive: --cache speculative;
cache-W4-reuse-order: --cache speculative --window 4 --resort off;
catgs: --cache speculative --split auto; catgs-W4: --cache speculative --window 4 --split auto;
catgs-reuse-order: --cache speculative --split auto --resort off; catgs-tail-1e-3: --cache speculative --split auto --split-tail 1e-3;
catgs-guard-1: --cache speculative --split auto --guard-px 1; catgs-guard-0.5: --cache speculative --split auto --guard-px 0.5;
catgs-split-2048: --cache speculative --split 2048; catgs-split-2048-guard-1: --cache speculative --split 2048 --guard-px 1'
short='bbox3sigma: --culling bbox3sigma; opacity-aware: ; split-auto: --split auto; split-1024: --split 1024;
cache-W4: --cache speculative --window 4; cache-adaptive: --cache speculative; catgs: --cache speculative --split auto;
catgs-reuse-order: --cache speculative --split auto --resort off; catgs-guard-1: --cache speculative --split auto --guard-px 1'

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
