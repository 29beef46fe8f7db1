#!/usr/bin/env bash
# Before/after check of a change, in one device call, on the bench kit's scenes
# (shared/bench-kit, prepared with its bench.py):
#   1. the after bundle's GPU test suite;
#   2. catgs-bench of every bundle on every path, alternating per path so drift hits all alike:
#      median, mean and p90 of total_ms, the ratios to the before bundle, and every frame's image
#      digest compared with the after bundle's (--image-digests). Frames through catgs-server are
#      no substitute: the client's wall-clock timestamps feed the planner's pose prediction, so
#      two runs of one binary choose different key frames. For the same reason the default
#      pipeline's digests are shown but not counted: its window is chosen from measured frame
#      times; `work` (--window-cost work) is the same cache with reproducible choices.
# Usage: gpu_regression.sh BEFORE_BIN AFTER_BIN KIT_DIR SCENE_DIR OUT_DIR
#   Both bundles must digest alike: catgs-bench's digest changed on 2026-12-06 (docs/tools.md).
#   BEFORE_BIN, AFTER_BIN: bin/ folders of deploy/bundle.sh bundles (catgs-bench; AFTER_BIN also
#   catgs_gpu_tests). SCENE_DIR: bench.py --prep-catgs output, made here when missing.
# Env: TAGS (trajectory tags), WARMUP (default 30, as the kit), GPU_TESTS=0 skips step 1,
#   EXTRA_BINS (more bin/ folders, benchmarked beside the two: an A/B/C of candidate changes),
#   BACKEND=cpu makes a dry run on a machine without a GPU, PACK=FILE.tgz packs OUT_DIR into one
#   file after every step (a device call returns a few files, and one cut off at its time limit
#   keeps only what was packed).
set -uo pipefail
before=$1 after=$2 kit=$3 scenes=$4 out=$5
mkdir -p "$out" "$scenes"
tags=${TAGS:-city_ring_1920x1080 city_ring_3840x2160 garden_tiled_survey_1920x1080 garden_tiled_survey_3840x2160 garden_tiled_low_1920x1080 garden_tiled_low_3840x2160}
backend=${BACKEND:-cuda}  # cpu: a dry run of this script on a machine without a GPU
prep_extra=${PREP_EXTRA:-}  # e.g. '--n 20000 --frames 3' for a dry run
t0=$(date +%s)
el() { echo "[$(( $(date +%s) - t0 )) s]"; }
pack() { [ -z "${PACK:-}" ] || { tar czf "$PACK.tmp" -C "$out" . && mv "$PACK.tmp" "$PACK"; }; }

if [ ! -f "$scenes/manifest.json" ]; then
  echo "$(el) prep"
  python3 "$kit/bench.py" --prep-catgs "$scenes" --variants city_ring,garden_tiled --scene-cache /tmp/scache \
    --res 1920x1080,3840x2160 $prep_extra > "$out/prep.log" 2>&1 || { tail -5 "$out/prep.log"; exit 1; }
fi
variant_of() { case $1 in city_ring*) echo city_ring ;; *) echo garden_tiled ;; esac; }

if [ "${GPU_TESTS:-1}" != 0 ]; then
  echo "$(el) GPU suite (after)"
  "$after/catgs_gpu_tests" --gtest_brief=1 > "$out/gpu_tests.log" 2>&1
  echo "gpu tests rc=$?"; grep -E '^\[  (PASSED|FAILED|SKIPPED)|FAILED' "$out/gpu_tests.log" | head -20
  pack
fi

echo "$(el) bench"
sweep='default: ; plain: --cache off --split off; work: --window-cost work'
bins=("$before" "$after")
for extra in ${EXTRA_BINS:-}; do bins+=("$extra"); done
for tag in $tags; do
  res=${tag##*_}
  for side in "${!bins[@]}"; do
    "${bins[$side]}/catgs-bench" --scene "$scenes/$(variant_of "$tag").ply" --trajectory "$scenes/$tag.txt" \
      --width "${res%x*}" --height "${res#*x}" --backend "$backend" --warmup "${WARMUP:-30}" --quiet --image-digests \
      --sweep "$sweep" --json-out "$out/bench_${side}_$tag.json" \
      > "$out/bench_${side}_$tag.txt" 2>&1 || { echo "bench ${bins[$side]} $tag failed"; tail -3 "$out/bench_${side}_$tag.txt"; }
  done
  echo "$(el) $tag"
  pack
done
{ python3 - "$out" "${#bins[@]}" $tags <<'EOF'
import json, sys, os
import statistics as st
out, sides, tags = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
COUNTED = ("plain", "work")  # reproducible pipelines: their images must not move
def load(side, tag, name):
    doc = json.load(open(os.path.join(out, "bench_%d_%s.json" % (side, tag))))
    return next(r for r in doc["results"] if r["name"] == name)["frames"]
def times(frames):
    t = sorted(f["total_ms"] for f in frames)
    return st.median(t), sum(t) / len(t), t[int(0.9 * (len(t) - 1))]
def identical(x, y):
    return sum(a.get("image_digest") is not None and a.get("image_digest") == b.get("image_digest") for a, b in zip(x, y))
print("side 0 is BEFORE, 1 AFTER, 2.. EXTRA_BINS; ratios to side 0; images: frames identical to side 1")
differ = 0
for tag in tags:
    for name in ("default", "plain", "work"):
        try:
            runs = [load(side, tag, name) for side in range(sides)]
        except Exception as e:
            print(tag, name, "missing:", e); differ += 1; continue
        base = times(runs[0])
        row = "%-30s %-7s 0: %.3f %.3f %.3f" % (tag, name, *base)
        for side in range(1, sides):
            t = times(runs[side])
            row += " | %d: %.3f %.3f %.3f (%.3f %.3f %.3f)" % (side, *t, *(a / b for a, b in zip(t, base)))
        for side in (0,) + tuple(range(2, sides)):
            same = identical(runs[1], runs[side])
            row += " | %d=1 %d/%d" % (side, same, len(runs[1]))
            if name in COUNTED and side == 0:
                differ += max(len(runs[0]), len(runs[1])) - same
        print(row)
print("images (plain, work; before against after): bit-identical" if differ == 0 else
      "images (plain, work; before against after): %d frames DIFFER" % differ)
EOF
} | tee "$out/summary.txt"
pack
echo "$(el) done"
