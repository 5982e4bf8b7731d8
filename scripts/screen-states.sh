#!/usr/bin/env bash
# Issue "Denser is better…", item 4: screen-driven probe updates
# (`probe_states=screen`) against all-active probes and the default jcgt
# states. Per run: HDR-FLIP against `probegi reference` and against the
# all-active render of the same configuration, the dark fraction, the mean
# probe rays per frame (initialisation included) and the field update time.
# Runs (NAME=scene/grid): sponza-fitted (README camera, sky 3, 16×8×16),
# sponza-cascades (3 cascades, 16,8,16), forest (builtin, 16×8×16).
# Writes OUT/*.exr, OUT/table.md. A benchmark, not a test (~40 min on 2 cores).
# Usage: [W=160 H=90 SPP=1024 FRAMES=300 FOREST_FRAMES=100] scripts/screen-states.sh [RUN...]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/screen-states}
W=${W:-160}; H=${H:-90}; SPP=${SPP:-1024}; FRAMES=${FRAMES:-300}; FOREST_FRAMES=${FOREST_FRAMES:-100}
mkdir -p "$OUT"
cargo build --release --locked -q -p probegi-cli
BIN=./target/release/probegi
sponza=(--scene ../shared/scenes/dabrovic-sponza/sponza.obj --camera-pos=-12,2,0 --camera-target 10,4,0
  --sky 3,3,3 --set normal_maps=false --width "$W" --height "$H")
forest=(--scene builtin:forest --width "$W" --height "$H")
declare -A SCENE=([sponza-fitted]=sponza [sponza-cascades]=sponza [forest]=forest)
declare -A GRID=([sponza-fitted]="--probes 16,8,16" [sponza-cascades]="--cascades 3 --probes 16,8,16"
  [forest]="--probes 16,8,16")
runs=("$@")
[ ${#runs[@]} -gt 0 ] || runs=(sponza-fitted forest sponza-cascades)
[ -f "$OUT/table.md" ] || {
  echo "| run | states | HDR-FLIP vs reference | vs all-active | dark pixels | probe rays per frame | field update ms |"
  echo "|---|---|---|---|---|---|---|"
} > "$OUT/table.md"
for run in "${runs[@]}"; do
  scene=${SCENE[$run]}
  if [ "$scene" = sponza ]; then args=("${sponza[@]}"); frames=$FRAMES; else args=("${forest[@]}"); frames=$FOREST_FRAMES; fi
  ref="$OUT/reference-$scene-$W-$SPP.exr"
  [ -f "$ref" ] || "$BIN" reference "${args[@]}" --spp "$SPP" --out "$ref" 2>/dev/null
  for states in all-active jcgt screen; do
    name="$run-$states"
    # shellcheck disable=SC2086
    "$BIN" render --gi ddgi --frames "$frames" "${args[@]}" ${GRID[$run]} --set probe_states=$states \
      --out "$OUT/$name.exr" --stats "$OUT/$name.json" 2>/dev/null
    cmp=$("$BIN" compare "$ref" "$OUT/$name.exr" --out "$OUT/$name-sheet.png")
    flip=$(echo "$cmp" | awk '/mean_flip/ {printf "%.3f", $2}')
    dark=$(echo "$cmp" | awk '/dark_fraction/ {printf "%.1f %%", 100 * $2}')
    vs_all=$("$BIN" compare "$OUT/$run-all-active.exr" "$OUT/$name.exr" | awk '/mean_flip/ {printf "%.3f", $2}')
    stats=$(python3 -c "
import json; d = json.load(open('$OUT/$name.json'))
print(f\"{d['probe_rays_traced'] / d['frames']:.0f} | {d['field_update_ms']:.0f}\")")
    echo "| $run | $states | $flip | $vs_all | $dark | $stats |" | tee -a "$OUT/table.md"
  done
done
