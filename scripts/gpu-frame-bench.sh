#!/usr/bin/env bash
# Issue "Real time on a real GPU…", goal 6: the whole frame on a GPU, as a user of
# `probegi view` gets it. `view --headless --bench --backend wgpu` on the built-in
# Sponza under the sun with 3 camera-centred cascades (the screen scheme, as
# `--cascades` defaults) at 1280×720, 1920×1080 and 3840×2160, with a still camera
# and with scenes/sponza-flight.script; and the 4×4 world of Sponza copies
# (scripts/sponza-world.sh) at 1920×1080 with the same cascades. Prints a Markdown
# table (mean, median and p95 frame, the host's share of a frame, camera and
# field update ms a frame, and the device's own time of each camera-frame pass
# from timestamp queries where the adapter has them) and writes OUT/table.md and
# one JSON per run. The field update's per-pass device times are
# `probegi bench --backend wgpu`'s (scripts/gpu-bench.sh).
#
# Needs only the release binary (BIN, default target/release/probegi, built here
# when missing and cargo exists) and ../shared/scenes (or PROBEGI_SHARED_DIR).
# A missing Vulkan loader or driver is named, and the script stops. About a
# minute on an H200; FRAMES (default 150) frames a run, the first 10 left out of
# the percentiles (the probes' initialisation rounds).
# Usage: [OUT=out/gpu-frame-bench FRAMES=150 SIZES="1280x720 1920x1080 3840x2160"] scripts/gpu-frame-bench.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/gpu-frame-bench}
BIN=${BIN:-./target/release/probegi}
FRAMES=${FRAMES:-150}
SIZES=${SIZES:-1280x720 1920x1080 3840x2160}
WORLD_SIZE=${WORLD_SIZE:-1920x1080}
mkdir -p "$OUT"

if ! { ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1'; } && ! ls /usr/lib/x86_64-linux-gnu/libvulkan.so.1 >/dev/null 2>&1; then
  echo "gpu-frame-bench: no Vulkan loader (libvulkan.so.1): install it (Debian/Ubuntu: apt-get install libvulkan1)" >&2
  exit 2
fi
if [ ! -x "$BIN" ]; then
  command -v cargo >/dev/null 2>&1 || { echo "gpu-frame-bench: no binary at $BIN and no cargo to build it" >&2; exit 2; }
  cargo build --release --locked -q -p probegi-cli
fi
shared=${PROBEGI_SHARED_DIR:-../shared}
[ -f "$shared/scenes/dabrovic-sponza/sponza.obj" ] ||
  { echo "gpu-frame-bench: $shared/scenes/dabrovic-sponza/sponza.obj not found (../shared beside the repository, or PROBEGI_SHARED_DIR)" >&2; exit 2; }
export PROBEGI_SHARED_DIR=$(cd "$shared" && pwd)

# shellcheck source=scripts/sponza-world.sh
. scripts/sponza-world.sh
world="$OUT/sponza-4x4.toml"
{ sponza_world 4; printf '[camera]\nposition = [-12.0, 2.5, -1.0]\ntarget = [4.0, 4.5, 0.5]\nfov_y_deg = 65.0\n'; } > "$world"

CASCADES=(--gi ddgi --cascades 3 --backend wgpu)
run() { # name scene WxH [script]
  local name=$1 scene=$2 size=$3 script=${4:-}
  local args=(view --headless --bench --scene "$scene" "${CASCADES[@]}" --width "${size%x*}" --height "${size#*x}"
    --exit-after-frames "$FRAMES")
  [ -n "$script" ] && args+=(--input-script "$script")
  if ! "$BIN" "${args[@]}" >"$OUT/$name.json" 2>"$OUT/$name.log"; then
    echo "gpu-frame-bench: $name failed:" >&2; tail -5 "$OUT/$name.log" >&2; return 1
  fi
}
runs=()
for size in $SIZES; do
  run "sponza-still-$size" builtin:sponza-sun "$size" && runs+=("sponza-still-$size")
  run "sponza-flight-$size" builtin:sponza-sun "$size" scenes/sponza-flight.script && runs+=("sponza-flight-$size")
done
run "world-4x4-still-$WORLD_SIZE" "$world" "$WORLD_SIZE" && runs+=("world-4x4-still-$WORLD_SIZE")

python3 - "$OUT" "${runs[@]}" >"$OUT/table.md" <<'PY'
import json, sys
out, names = sys.argv[1], sys.argv[2:]
rows = [(n, json.load(open(f"{out}/{n}.json"))) for n in names]
adapter = rows[0][1].get("adapter") if rows else "?"
print(f"`view --headless --bench` on {adapter}, 3 cascades (screen scheme), frames after the warm-up\n")
print("| run | frames | mean ms (period) | median ms | p95 ms | max ms | host ms (mean) | camera ms | field update ms "
      "| GPU: camera / resolve / compose / stats ms |")
print("|---|---|---|---|---|---|---|---|---|---|")
f = lambda v: "—" if v is None else f"{v:.2f}"
for n, d in rows:
    fm, hm = d["frame_ms"], d.get("host_ms", {})
    print(f"| {n} | {d['frames'] - d.get('warmup_frames', 0)} | {f(fm.get('mean'))} | {f(fm['median'])} | {f(fm['p95'])} "
          f"| {f(fm['max'])} | {f(hm.get('mean'))} | {f(d.get('camera_ms'))} | {f(d.get('field_update_ms'))} "
          f"| {' / '.join(f(g.get(k)) for k in ('gpu_camera', 'gpu_frame_resolve', 'gpu_frame_compose', 'gpu_frame_stats')) if (g := d.get('gpu_pass_ms')) else '—'} |")
PY
cat "$OUT/table.md"
