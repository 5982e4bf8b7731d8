#!/usr/bin/env bash
# Issue "`probegi-bevy`…", GPU timing: the Sponza example
# (crates/probegi-bevy/examples/bevy_sponza.rs) headless at 1920×1080, Bevy's
# frame with the plugin's field (three 16×8×16 cascades on the camera, the sun
# and the sky) and without it (--no-field: Bevy's own lighting), FRAMES frames
# each, from the example's --bench (frame wall times after the first quarter).
# Prints a table and writes $OUT/sponza-{field,no-field}.{json,png}.
#
# Where a GPU is lent (../shared/device/README.md), from the project root:
#   bash ../shared/device/prepare.sh dabrovic-sponza
#   bash scripts/bevy-gpu-timing.sh --prepare   # the example in release into .device/bin
#                                               # (Bevy 0.20's toolchain, as scripts/test.sh picks it;
#                                               # a fresh release build of Bevy takes 20-30 min on 2 cores)
# then one device call: bash .device/on-device.sh 'bash scripts/bevy-gpu-timing.sh'
# Here it runs on lavapipe too (a dry run; its times say nothing of a GPU).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = --prepare ]; then
  # shellcheck source=scripts/bevy-toolchain.sh
  source scripts/bevy-toolchain.sh
  [ -n "$bevy_toolchain" ] || { echo "bevy-gpu-timing: no Rust 1.97.1 or 1.97 nightly for Bevy 0.20" >&2; exit 2; }
  (cd crates/probegi-bevy && cargo "+$bevy_toolchain" build --release --locked "${bevy_flags[@]}" --example bevy_sponza)
  mkdir -p .device/bin
  cp crates/probegi-bevy/target/release/examples/bevy_sponza .device/bin/
  strip .device/bin/bevy_sponza 2>/dev/null || true
  ls -la .device/bin/bevy_sponza
  exit 0
fi
EXAMPLE=${EXAMPLE:-.device/bin/bevy_sponza}
[ -x "$EXAMPLE" ] || EXAMPLE=crates/probegi-bevy/target/release/examples/bevy_sponza
[ -x "$EXAMPLE" ] || { echo "bevy-gpu-timing: no example binary: run it with --prepare first" >&2; exit 2; }
SCENE=${SCENE:-../shared/scenes/dabrovic-sponza/sponza.obj}
[ -f "$SCENE" ] || { echo "bevy-gpu-timing: scene $SCENE not found (../shared beside the repository)" >&2; exit 2; }
FRAMES=${FRAMES:-120}
SIZE=${SIZE:-1920x1080}
OUT=${OUT:-out/bevy-gpu-timing}
mkdir -p "$OUT"
for run in field no-field; do
  flags=()
  [ "$run" = no-field ] && flags=(--no-field)
  "$EXAMPLE" --scene "$SCENE" --size "$SIZE" --frames "$FRAMES" --bench --out "$OUT/sponza-$run.png" \
    "${flags[@]}" >"$OUT/sponza-$run.json"
done
python3 - "$OUT" <<'PY'
import json, sys
out = sys.argv[1]
runs = {r: json.load(open(f"{out}/sponza-{r}.json")) for r in ("field", "no-field")}
print(f"Sponza in Bevy, {runs['field']['size'][0]}x{runs['field']['size'][1]}, "
      f"{runs['field']['frames_timed']} frames timed (ms a frame)")
print("| run | mean | median | p95 |")
print("|---|---|---|---|")
for r, d in runs.items():
    m = d["frame_ms"]
    print(f"| {r} | {m['mean']:.2f} | {m['median']:.2f} | {m['p95']:.2f} |")
f, b = runs["field"]["frame_ms"], runs["no-field"]["frame_ms"]
print(f"the field's cost: {f['median'] - b['median']:.2f} ms a frame (medians), "
      f"{f['median'] / b['median']:.2f}x Bevy's own frame")
PY
