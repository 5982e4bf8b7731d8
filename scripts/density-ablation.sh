#!/usr/bin/env bash
# Issue "Denser is better…", item 1: why a denser field scores worse on Sponza.
# The shared Dabrovic Sponza, the README camera (-12,2,0 -> 10,4,0), sky 3,
# normal maps off (the reference has none), FRAMES frames; each configuration
# against `probegi reference` at SPP spp: HDR-FLIP and the dark fraction (lit
# reference pixels rendered under a quarter; `probegi compare`).
# Writes out/density/*.exr, out/density/table.md. A benchmark, not a test.
# Usage: [W=160 H=90 SPP=1024 FRAMES=100 BIN=] scripts/density-ablation.sh [CONFIG...]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/density}
W=${W:-160}; H=${H:-90}; SPP=${SPP:-1024}; FRAMES=${FRAMES:-100}
mkdir -p "$OUT"
# BIN=path: run that binary as is (no build).
[ -n "${BIN:-}" ] || { cargo build --release --locked -q -p probegi-cli; BIN=./target/release/probegi; }
common=(--scene ../shared/scenes/dabrovic-sponza/sponza.obj --camera-pos=-12,2,0 --camera-target 10,4,0
  --sky 3,3,3 --set normal_maps=false --width "$W" --height "$H")
[ -f "$OUT/reference-$W-$SPP.exr" ] ||
  "$BIN" reference "${common[@]}" --spp "$SPP" --out "$OUT/reference-$W-$SPP.exr" 2>/dev/null
declare -A CONFIGS=(
  [fitted-16x8x16]="--probes 16,8,16"
  [fitted-32x16x12]="--probes 32,16,12"
  [cascades-3]="--cascades 3 --probes 16,8,16"
  [cascades-3-seed2]="--cascades 3 --probes 16,8,16 --seed 2"
  [cascades-3-free-2x]="--cascades 3 --probes 16,8,16 --set volume_tracking_bounds_m=[[-1e6,-1e6,-1e6],[1e6,1e6,1e6]] --set probe_spacing_m=[1.1607,1.1829,0.52]"
  [cascades-4]="--cascades 4 --probes 16,8,16"
  [cascades-3-ratio-1.5]="--cascades 3 --probes 16,8,16 --cascade-ratio 1.5"
  [cascades-3-ratio-1.5-seed2]="--cascades 3 --probes 16,8,16 --cascade-ratio 1.5 --seed 2"
  [cascades-3-screen]="--cascades 3 --probes 16,8,16 --set probe_states=screen"
  [cascades-3-jcgt]="--cascades 3 --probes 16,8,16 --set probe_states=jcgt"
  [cascades-3-ratio-2]="--cascades 3 --probes 16,8,16 --cascade-ratio 2"
  [cascades-3-fit-cells]="--cascades 3 --probes 16,8,16 --set probe_spacing_m=[0.96722,0.92,0.43333]"
  [fitted-16x8x16-all-active]="--probes 16,8,16 --set probe_states=all-active"
  [fitted-32x16x12-all-active]="--probes 32,16,12 --set probe_states=all-active"
  [fitted-32x16x12-no-relocation]="--probes 32,16,12 --set probe_relocation=false"
  [fitted-32x16x12-bias-x2]="--probes 32,16,12 --set probe_self_shadow_bias=0.6"
  [fitted-32x16x12-usage]="--probes 32,16,12 --set probe_states=usage"
  [cascades-3-all-active]="--cascades 3 --probes 16,8,16 --set probe_states=all-active"
  [fitted-16x8x16-no-chebyshev]="--probes 16,8,16 --set probe_chebyshev_weight=false"
  [fitted-32x16x12-no-chebyshev]="--probes 32,16,12 --set probe_chebyshev_weight=false"
  [fitted-32x16x12-no-backface]="--probes 32,16,12 --set probe_backface_weight=false"
  [fitted-32x16x12-no-crush]="--probes 32,16,12 --set probe_crush_weight=false"
  [fitted-32x16x12-distance-32]="--probes 32,16,12 --set probe_distance_texels=32"
  [cascades-3-cover-2x]="--cascades 3 --probes 16,8,16 --set probe_spacing_m=[1.1607,1.1829,0.52]"
  [cascades-3-20x10x10]="--cascades 3 --probes 20,10,10"
  [fitted-16x8x12]="--probes 16,8,12"
  [fitted-16x8x12-no-chebyshev]="--probes 16,8,12 --set probe_chebyshev_weight=false"
  [fitted-16x8x12-no-backface]="--probes 16,8,12 --set probe_backface_weight=false"
  [fitted-16x8x12-no-relocation]="--probes 16,8,12 --set probe_relocation=false"
  [fitted-16x8x12-no-frontface-step]="--probes 16,8,12 --set probe_relocation_min_frontface_rel=0"
  [fitted-16x8x12-all-active]="--probes 16,8,12 --set probe_states=all-active"
  [fitted-16x8x12-frontface-1]="--probes 16,8,12 --set probe_relocation_min_frontface_rel=1"
  [fitted-16x8x12-offset-049]="--probes 16,8,12 --set probe_relocation_offset_limit_rel=0.49"
  [fitted-16x8x12-iterations-x4]="--probes 16,8,12 --set probe_relocation_iterations=20"
  [fitted-16x8x12-normal-bias]="--probes 16,8,12 --set probe_bias_mode=normal"
  [fitted-32x16x16]="--probes 32,16,16"
  [cascades-3-clamped]="--cascades 3 --probes 16,8,16 --set volume_tracking_bounds_m=[[-17.41,-0.91,-7.8],[17.42,15.66,7.81]]"
  [cascades-3-clamped-1x]="--cascades 3 --probes 16,8,16 --set volume_tracking_bounds_m=[[-17.41,-0.91,-7.8],[17.42,15.66,7.81]] --set probe_spacing_m=[0.5803,0.5914,0.26]"
  [fitted-32x16x32]="--probes 32,16,32"
  [fitted-16x8x16-no-fast-convergence]="--probes 16,8,16 --set probe_fast_convergence=false"
  [fitted-32x16x12-no-fast-convergence]="--probes 32,16,12 --set probe_fast_convergence=false"
)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(fitted-16x8x16 fitted-32x16x12 cascades-3 fitted-16x8x16-all-active
  fitted-32x16x12-all-active fitted-32x16x12-no-relocation fitted-32x16x12-bias-x2 fitted-32x16x12-usage
  cascades-3-all-active)
[ -f "$OUT/table.md" ] || {
  echo "| configuration | probes | HDR-FLIP | dark pixels | field update ms |"
  echo "|---|---|---|---|---|"
} > "$OUT/table.md"
for name in "${names[@]}"; do
  config=${CONFIGS[$name]:-}
  # fitted-AxBxC[-more] without an entry: a fitted A×B×C volume.
  if [ -z "$config" ] && [[ $name =~ ^fitted-([0-9]+)x([0-9]+)x([0-9]+)$ ]]; then
    config="--probes ${BASH_REMATCH[1]},${BASH_REMATCH[2]},${BASH_REMATCH[3]}"
  fi
  # shellcheck disable=SC2086
  "$BIN" render --gi ddgi --frames "$FRAMES" "${common[@]}" $config \
    --out "$OUT/$name.exr" --stats "$OUT/$name.json" 2>/dev/null
  cmp=$("$BIN" compare "$OUT/reference-$W-$SPP.exr" "$OUT/$name.exr" --out "$OUT/$name-sheet.png")
  flip=$(echo "$cmp" | awk '/mean_flip/ {print $2}')
  dark=$(echo "$cmp" | awk '/dark_fraction/ {printf "%.1f %%", 100 * $2}')
  probes=$(python3 -c "import json; d=json.load(open('$OUT/$name.json')); print(d['probes'])")
  upd=$(python3 -c "import json; d=json.load(open('$OUT/$name.json')); print(round(d['field_update_ms'], 1))")
  echo "| $name | $probes | $flip | $dark | $upd |" | tee -a "$OUT/table.md"
done
