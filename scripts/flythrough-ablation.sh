#!/usr/bin/env bash
# Issue "Denser is better…", items 2–3: seeding new probes and edge buffers on a
# flythrough. The shared Dabrovic Sponza under a sun and sky, FRAMES frames of
# camera keyframes: along the atrium, up through the open roof, over it and back
# down. Four cascades of 12×6×12 probes (1 m innermost, as scripts/world-scale.sh),
# 128 rays per probe, each configuration against `probegi reference --frame K` at
# SPP spp at frames FLIP_FRAMES, plus the per-frame change of the indirect term.
# Writes out/fly/*.exr, out/fly/table.md (FLIP per frame, the indirect term's
# change, the mean probe rays per frame). A benchmark, not a test: ~10 min on 2 cores.
# Usage: [W=160 H=90 SPP=256 FRAMES=120] scripts/flythrough-ablation.sh [CONFIG...]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/fly}
W=${W:-160}; H=${H:-90}; SPP=${SPP:-256}; FRAMES=${FRAMES:-120}
last=$((FRAMES - 1))
FLIP_FRAMES=${FLIP_FRAMES:-"$((FRAMES / 3)) $((FRAMES / 2)) $((2 * FRAMES / 3)) $last"}
mkdir -p "$OUT"
cargo build --release --locked -q -p probegi-cli
BIN=./target/release/probegi
scene="$OUT/sponza-fly.toml"
{
  echo '# Dabrovic Sponza (CC BY-NC, © 2002 Marko Dabrovic; ../shared/scenes) with a camera flight.'
  echo 'sky_radiance = [0.15, 0.18, 0.25]'
  printf '[[meshes]]\npath = "shared:scenes/dabrovic-sponza/sponza.obj"\n'
  printf '[[lights]]\nkind = "directional"\ndirection = [0.25, -1.0, 0.15]\ncolor = [1.0, 0.92, 0.8]\nintensity = 12.0\n'
  printf '[camera]\nposition = [-13.0, 3.0, 0.0]\ntarget = [0.0, 4.0, 0.0]\nfov_y_deg = 65.0\n'
  printf 'keyframes = [\n'
  printf '  { frame = 0, position = [-13.0, 3.0, 0.0], target = [0.0, 4.0, 0.0] },\n'
  printf '  { frame = %d, position = [8.0, 3.0, 0.0], target = [20.0, 5.0, 0.0] },\n' $((FRAMES / 3))
  printf '  { frame = %d, position = [0.0, 20.0, 0.0], target = [10.0, 0.0, 0.0] },\n' $((2 * FRAMES / 3))
  printf '  { frame = %d, position = [-8.0, 6.0, 0.0], target = [10.0, 4.0, 0.0] },\n' $last
  printf ']\n'
} > "$scene"
# The reference has no bump maps, so the renders leave them out too.
CASCADES=(--gi ddgi --cascades 4 --probes 12,6,12 --set probe_spacing_m=1.0 --rays-per-probe 128 --set normal_maps=false)
declare -A CONFIGS=(
  [base]=""
  [edge-buffers]="--set volume_edge_buffer_planes=2"
  [edge-buffers-0.5]="--set volume_edge_buffer_planes=2 --set volume_edge_buffer_hysteresis=0.5"
  [base-seed-2]="--seed 2"
  [seeding]="--set probe_seeding=true"
  [seeding-edge-buffers]="--set probe_seeding=true --set volume_edge_buffer_planes=2"
  [all-active]="--set probe_states=all-active"
  [screen]="--set probe_states=screen"
  [screen-seeding]="--set probe_states=screen --set probe_seeding=true"
  [screen-seeding-edge-buffers]="--set probe_states=screen --set probe_seeding=true --set volume_edge_buffer_planes=2"
)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(base edge-buffers seeding seeding-edge-buffers)
for k in $FLIP_FRAMES; do
  [ -f "$OUT/reference-$k.exr" ] ||
    "$BIN" reference --scene "$scene" --frame "$k" --width "$W" --height "$H" --spp "$SPP" \
      --out "$OUT/reference-$k.exr" 2>/dev/null
done
[ -f "$OUT/table.md" ] || {
  printf '| configuration |'; for k in $FLIP_FRAMES; do printf ' FLIP frame %s |' "$k"; done
  printf ' indirect mean change per frame: median, max | probe rays per frame |\n|---|'
  for _ in $FLIP_FRAMES; do printf -- '---|'; done; printf -- '---|---|\n'
} > "$OUT/table.md"
for name in "${names[@]}"; do
  # shellcheck disable=SC2086
  "$BIN" render --scene "$scene" "${CASCADES[@]}" ${CONFIGS[$name]} --frames "$FRAMES" --width "$W" --height "$H" \
    --sequence "$OUT/$name" --sequence-exr --out "$OUT/$name.exr" --stats "$OUT/$name.json" 2>/dev/null
  row="| $name |"
  for k in $FLIP_FRAMES; do
    f=$("$BIN" compare "$OUT/reference-$k.exr" "$(printf '%s/%s/frame-%04d.exr' "$OUT" "$name" "$k")" | awk '/mean_flip/ {printf "%.3f", $2}')
    row="$row $f |"
  done
  change=$(python3 -c "
import json; m = [sum(v) / 3 for v in json.load(open('$OUT/$name.json'))['frame_indirect_means']]
c = sorted(abs(m[i] - m[i - 1]) / max(m[i - 1], 1e-9) for i in range(1, len(m)))
d = json.load(open('$OUT/$name.json')); r = d['probe_rays_traced'] / d['frames']
print(f'{100 * c[len(c) // 2]:.1f} %, {100 * c[-1]:.1f} % | {r:.0f}')")
  echo "$row $change |" | tee -a "$OUT/table.md"
done
