#!/usr/bin/env bash
# Issue "Denser is better…": the 4×4 world against one Sponza at a still camera
# (scripts/world-scale.sh's worlds and camera, inside copy (0, 0)). Four
# cascades of 12×6×12 probes 1 m apart innermost, 128 rays, 48 frames, normal
# maps off (the reference has none), each world against its own 256-spp
# reference; per configuration HDR-FLIP, dark pixels, the two worlds' images
# against each other, the field update and the probe rays per frame.
# Writes OUT/table.md and OUT/<config>-<n>.png contact sheets. A benchmark, not
# a test (~2 min per configuration on 2 cores).
# Usage: [OUT=out/world W=160 H=120 SPP=256 FRAMES=48] scripts/world-static.sh NAME="ARGS" ...
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/world}
W=${W:-160}; H=${H:-120}; SPP=${SPP:-256}; FRAMES=${FRAMES:-48}
mkdir -p "$OUT"
cargo build --release --locked -q -p probegi-cli
BIN=./target/release/probegi
# shellcheck source=scripts/sponza-world.sh
. scripts/sponza-world.sh
world() { # N: the camera in copy (0, 0)
  sponza_world "$1"
  printf '[camera]\nposition = [-12.0, 2.5, -1.0]\ntarget = [4.0, 4.5, 0.5]\nfov_y_deg = 65.0\n'
}
CASCADES=(--gi ddgi --cascades 4 --probes 12,6,12 --set probe_spacing_m=1.0 --rays-per-probe 128 --set normal_maps=false)
for n in 1 4; do
  world $n > "$OUT/sponza-$n.toml"
  [ -f "$OUT/reference-$n.exr" ] ||
    $BIN reference --scene "$OUT/sponza-$n.toml" --width $W --height $H --spp $SPP --set normal_maps=false \
      --out "$OUT/reference-$n.exr" 2>/dev/null
done
for spec in "$@"; do
  name=${spec%%=*}; args=${spec#*=}
  for n in 1 4; do
    # shellcheck disable=SC2086
    $BIN render --scene "$OUT/sponza-$n.toml" "${CASCADES[@]}" $args --frames $FRAMES --width $W --height $H \
      --out "$OUT/$name-$n.exr" --stats "$OUT/$name-$n.json" 2>/dev/null
    $BIN compare "$OUT/reference-$n.exr" "$OUT/$name-$n.exr" --out "$OUT/$name-$n.png" > "$OUT/$name-$n.flip"
  done
  between=$($BIN compare "$OUT/$name-1.exr" "$OUT/$name-4.exr" | awk '/mean_flip/ {print $2}')
  for n in 1 4; do
    printf '| %s | %s×%s | %.3f | %.2f %% | %s | %.0f | %.0f |\n' "$name" $n $n \
      "$(awk '/mean_flip/ {print $2}' "$OUT/$name-$n.flip")" \
      "$(awk '/dark_fraction/ {print $2 * 100}' "$OUT/$name-$n.flip")" \
      "$([ $n = 4 ] && printf '%.3f' "$between" || echo —)" \
      "$(jq .field_update_ms "$OUT/$name-$n.json")" "$(jq '.probe_rays_traced / .frames' "$OUT/$name-$n.json")"
  done | tee -a "$OUT/table.md"
done
