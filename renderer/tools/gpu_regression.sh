#!/usr/bin/env bash
# Before/after check of a change that must not change what the GPU draws (a refactor), in one
# device call, on the bench kit's scenes (shared/bench-kit, prepared with its bench.py):
#   1. the after bundle's GPU test suite;
#   2. catgs-bench of both bundles on every path, the default pipeline and the plain one,
#      alternating per path so drift hits both alike: median, mean and p90 of total_ms, the
#      after/before ratios, and every frame's image digest compared (--image-digests). Frames
#      through catgs-server are no substitute: the client's wall-clock timestamps feed the
#      planner's pose prediction, so two runs of one binary choose different key frames.
# Usage: gpu_regression.sh BEFORE_BIN AFTER_BIN KIT_DIR SCENE_DIR OUT_DIR
#   Both bundles must digest alike: catgs-bench's digest changed on 2026-12-06 (docs/tools.md).
#   BEFORE_BIN, AFTER_BIN: bin/ folders of deploy/bundle.sh bundles (catgs-bench; AFTER_BIN also
#   catgs_gpu_tests). SCENE_DIR: bench.py --prep-catgs output, made here when missing.
# Env: TAGS (trajectory tags), WARMUP (default 30, as the kit), GPU_TESTS=0 skips step 1,
#   BACKEND=cpu makes a dry run on a machine without a GPU.
set -uo pipefail
before=$1 after=$2 kit=$3 scenes=$4 out=$5
mkdir -p "$out" "$scenes"
tags=${TAGS:-city_ring_1920x1080 city_ring_3840x2160 garden_tiled_survey_1920x1080 garden_tiled_survey_3840x2160 garden_tiled_low_1920x1080 garden_tiled_low_3840x2160}
backend=${BACKEND:-cuda}  # cpu: a dry run of this script on a machine without a GPU
prep_extra=${PREP_EXTRA:-}  # e.g. '--n 20000 --frames 3' for a dry run
t0=$(date +%s)
el() { echo "[$(( $(date +%s) - t0 )) s]"; }

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
fi

echo "$(el) bench"
sweep='default: ; plain: --cache off --split off'
for tag in $tags; do
  res=${tag##*_}
  for side in before after; do
    bin=$before; [ $side = after ] && bin=$after
    "$bin/catgs-bench" --scene "$scenes/$(variant_of "$tag").ply" --trajectory "$scenes/$tag.txt" --width "${res%x*}" \
      --height "${res#*x}" --backend "$backend" --warmup "${WARMUP:-30}" --quiet --image-digests --sweep "$sweep" \
      --json-out "$out/bench_${side}_$tag.json" \
      > "$out/bench_${side}_$tag.txt" 2>&1 || { echo "bench $side $tag failed"; tail -3 "$out/bench_${side}_$tag.txt"; }
  done
done
python3 - "$out" $tags <<'EOF'
import json, sys, os
import statistics as st
out, tags = sys.argv[1], sys.argv[2:]
def load(side, tag, name):
    doc = json.load(open(os.path.join(out, "bench_%s_%s.json" % (side, tag))))
    return next(r for r in doc["results"] if r["name"] == name)["frames"]
def times(frames):
    t = sorted(f["total_ms"] for f in frames)
    return st.median(t), sum(t) / len(t), t[int(0.9 * (len(t) - 1))]
print("%-32s %-8s %26s %26s %19s %s" % ("path", "config", "before med/mean/p90", "after med/mean/p90",
                                         "ratio med/mean", "images"))
differ = 0
for tag in tags:
    for name in ("default", "plain"):
        try:
            b, a = load("before", tag, name), load("after", tag, name)
        except Exception as e:
            print(tag, name, "missing:", e); differ += 1; continue
        tb, ta = times(b), times(a)
        same = sum(x.get("image_digest") is not None and x.get("image_digest") == y.get("image_digest")
                   for x, y in zip(b, a))
        differ += max(len(b), len(a)) - same
        print("%-32s %-8s %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %9.3f %9.3f %d/%d identical" %
              (tag, name, *tb, *ta, ta[0] / tb[0], ta[1] / tb[1], same, len(b)))
print("images: bit-identical" if differ == 0 else "images: %d frames DIFFER" % differ)
EOF
echo "$(el) done"
