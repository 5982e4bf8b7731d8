#!/usr/bin/env bash
# Issue "Real time on a real GPU…": every check of a GPU machine in one run, for a
# device that has the driver but no toolchain (../shared/device/README.md):
#   1. scripts/gpu-frame-bench.sh (the viewer's frame: Sponza with cascades at
#      720p, 1080p and 4K, still and flying; the 4×4 world at 1080p);
#   2. scripts/gpu-tests.sh run (the packed GPU test binaries), when packed;
#   3. `render --stats --backend wgpu` on builtin:sponza-sun --cascades 3 at the
#      four sizes of the issue's first table (20 frames), camera and field ms;
#   4. scripts/gpu-bench.sh on Sibenik (GRIDS/RAYS trimmed by GPU_BENCH_GRIDS,
#      GPU_BENCH_RAYS).
# Each step has a time limit (FRAME_BENCH_S, TESTS_S, RENDER_S each, GPU_BENCH_S),
# so that the whole fits one device call of 10 minutes (150 + 200 + 4 × 40 + 90 s);
# gpu-bench runs both probe-state schemes: give it STATES=jcgt, or more time.
# Prepare here with: bash ../shared/device/prepare.sh cornell-box dabrovic-sponza
#   sibenik scrub-pine; bash scripts/gpu-tests.sh pack; then on the device:
#   bash .device/on-device.sh 'bash scripts/gpu-device-check.sh'
# Tables go to stdout and OUT (default out/gpu-device-check).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/gpu-device-check}
BIN=${BIN:-./target/release/probegi}
mkdir -p "$OUT"
export PROBEGI_SHARED_DIR=${PROBEGI_SHARED_DIR:-$(cd ../shared && pwd)}

# An H200 container of 2026-12-04 had the NVIDIA driver's GLX library refuse
# Vulkan ("Could not get 'vkCreateInstance' via 'vk_icdGetInstanceProcAddr' for
# ICD libGLX_nvidia.so.0") while its EGL library, the same driver's other
# entry point, worked: without an adapter, try a manifest naming that one.
has_adapter() { "$BIN" bench --gi ddgi --backend wgpu --grids 4,4,4 --rays 32 --frames 1 --repeat 1 2>/dev/null | grep -q '"adapter"'; }
if ! has_adapter; then
  for egl in /usr/local/nvidia/lib64/libEGL_nvidia.so.0 /usr/lib/x86_64-linux-gnu/libEGL_nvidia.so.0; do
    [ -e "$egl" ] || continue
    icd=$(mktemp --suffix=.json)
    printf '{"file_format_version":"1.0.1","ICD":{"library_path":"%s","api_version":"1.3.0"}}\n' "$egl" >"$icd"
    export VK_ICD_FILENAMES=$icd VK_DRIVER_FILES=$icd
    if has_adapter; then echo "Vulkan through $egl ($icd)"; break; fi
  done
fi

echo "## 1. The viewer's frame (gpu-frame-bench)"
OUT="$OUT/frame" BIN="$BIN" FRAMES=${FRAMES:-120} timeout ${FRAME_BENCH_S:-150} bash scripts/gpu-frame-bench.sh || echo "gpu-frame-bench failed or timed out"

echo; echo "## 2. GPU test binaries"
if [ -f .device/tests/probegi-wgpu-tests.tar.xz ]; then
  OUT="$OUT/tests" timeout ${TESTS_S:-200} bash scripts/gpu-tests.sh run || echo "some GPU test binaries failed (logs in $OUT/tests)"
else
  echo "no packed test binaries (.device/tests)"
fi
echo; echo "## 3. render --stats --backend wgpu, builtin:sponza-sun --cascades 3, 20 frames"
echo "| size | camera ms | field update ms | frame means ok |"
echo "|---|---|---|---|"
for size in 480x270 960x540 1920x1080 3840x2160; do
  s="$OUT/render-$size.json"
  if timeout ${RENDER_S:-40} "$BIN" render --scene builtin:sponza-sun --gi ddgi --cascades 3 --backend wgpu --frames 20 \
    --width "${size%x*}" --height "${size#*x}" --out "$OUT/render-$size.exr" --stats "$s" >/dev/null 2>"$OUT/render-$size.log"; then
    python3 - "$s" "$size" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(f"| {sys.argv[2]} | {d['pass_ms'].get('camera', 0):.2f} | {d.get('field_update_ms') or 0:.2f} | {len(d.get('frame_means', []))} |")
PY
  else
    echo "| $size | failed | | |"; tail -3 "$OUT/render-$size.log"
  fi
done

echo; echo "## 4. gpu-bench (Sibenik)"
OUT="$OUT/gpu-bench" BIN="$BIN" GRIDS=${GPU_BENCH_GRIDS:-16,8,16 32,16,32 32,32,32} RAYS=${GPU_BENCH_RAYS:-128 256} \
  timeout ${GPU_BENCH_S:-90} bash scripts/gpu-bench.sh >/dev/null 2>"$OUT/gpu-bench.log" && cat "$OUT/gpu-bench/table.md" ||
  { echo "gpu-bench failed or timed out"; tail -3 "$OUT/gpu-bench.log"; }

# What comes back: the tables above, and a tarball of the JSON and logs.
tar -czf "$OUT/../gpu-device-check.tar.gz" -C "$OUT" . 2>/dev/null || true
