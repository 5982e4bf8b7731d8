#!/usr/bin/env bash
# Issue "`probegi-bevy`…", "a visible difference": the Sponza example
# (crates/probegi-bevy/examples/bevy_sponza.rs) as exposed radiance (`--out
# *.exr`: an HDR camera, Bevy's tone mapping off, radiance × the camera's
# exposure) with the field and without it (--no-field: Bevy's own lighting),
# each against `probegi reference` of the same view lit × the same exposure
# (scenes/sponza-bevy-example.toml; bump maps off, as the example draws none). Prints `probegi compare`'s
# HDR-FLIP, dark fraction and mean ratio (test / reference) for both, and
# writes the images and contact sheets to $OUT.
#   SIZE=320x240 FRAMES=40 SPP=256 bash scripts/bevy-sponza-flip.sh
# On lavapipe (2 cores) the field run takes about 2 min at 320×240, the
# reference about as long. Needs Bevy 0.20's toolchain (scripts/test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
SIZE=${SIZE:-320x240}
FRAMES=${FRAMES:-40}
SPP=${SPP:-256}
OUT=${OUT:-out/bevy-sponza-flip}
BIN=${BIN:-./target/release/probegi}
[ -x "$BIN" ] || cargo build --release --locked -q
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
# shellcheck source=scripts/bevy-toolchain.sh
source scripts/bevy-toolchain.sh
[ -n "$bevy_toolchain" ] || { echo "bevy-sponza-flip: no Rust 1.97.1 or 1.97 nightly for Bevy 0.20" >&2; exit 2; }
(
  cd crates/probegi-bevy
  for run in field no-field; do
    flags=()
    [ "$run" = no-field ] && flags=(--no-field)
    cargo "+$bevy_toolchain" run -q --locked "${bevy_flags[@]}" --example bevy_sponza -- \
      --size "$SIZE" --frames "$FRAMES" --out "$OUT/bevy-$run.exr" "${flags[@]}" 2>/dev/null
  done
)
w=${SIZE%x*}
h=${SIZE#*x}
"$BIN" reference --scene scenes/sponza-bevy-example.toml --width "$w" --height "$h" --spp "$SPP" \
  --set normal_maps=false --out "$OUT/reference.exr" >/dev/null
echo "Sponza in Bevy against probegi reference ($SPP spp), ${SIZE}, $FRAMES frames"
echo "| Bevy's frame | HDR-FLIP | dark fraction | mean ratio (R G B) |"
echo "|---|---|---|---|"
for run in field no-field; do
  "$BIN" compare "$OUT/reference.exr" "$OUT/bevy-$run.exr" --out "$OUT/sheet-$run.png" |
    awk -v run="$run" '/^mean_flip:/ { f = $2 } /^dark_fraction:/ { d = $2 }
      /^mean_ratio:/ { r = $2 " " $3 " " $4 } END { printf "| %s | %.3f | %.3f | %s |\n", run, f, d, r }'
done
