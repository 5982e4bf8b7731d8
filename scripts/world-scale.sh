#!/usr/bin/env bash
# Issue "World-scale DDGI" measurements: worlds of N×N side-by-side copies of the
# shared Dabrovic Sponza (1×1, 2×2, 4×4; 66 450 triangles each, merged into one
# BVH), the camera inside copy (0, 0).
#   - field-update cost with the same three cascades on every world, against one
#     fitted volume of a similar probe count;
#   - the image inside the copy against the single Sponza's (HDR-FLIP), and both
#     methods against the path-traced reference;
#   - a 300-frame flythrough of the 4×4 world (camera keyframes) with per-frame
#     mean changes and FLIP against `probegi reference --frame K` at three frames.
# Writes out/world/*.json, out/world/table.md. A benchmark, not a test: ~10 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/world}
FRAMES=${FRAMES:-48}
FLY_FRAMES=${FLY_FRAMES:-300}
W=${W:-160}; H=${H:-120}; SPP=${SPP:-256}
mkdir -p "$OUT"
cargo build --release --locked -q
BIN=./target/release/probegi

# shellcheck source=scripts/sponza-world.sh
. scripts/sponza-world.sh
world() { # N [flythrough]
  local n=$1 f="$OUT/sponza-$1x$1${2:+-fly}.toml"
  {
    sponza_world "$n"
    printf '[camera]\nposition = [-12.0, 2.5, -1.0]\ntarget = [4.0, 4.5, 0.5]\nfov_y_deg = 65.0\n'
    if [ -n "${2:-}" ]; then
      # Along copy (0, 0)'s atrium, up through its open roof, over the roofs to
      # copy (1, 0) and down into its atrium.
      printf 'keyframes = [\n'
      printf '  { frame = 0, position = [-13.0, 3.0, 0.0], target = [0.0, 4.0, 0.0] },\n'
      printf '  { frame = 100, position = [9.0, 3.0, 0.0], target = [20.0, 5.0, 0.0] },\n'
      printf '  { frame = 160, position = [0.0, 22.0, 0.0], target = [10.0, 0.0, 0.0] },\n'
      printf '  { frame = 230, position = [35.0, 22.0, 0.0], target = [45.0, 0.0, 0.0] },\n'
      printf '  { frame = 299, position = [35.0, 6.0, 0.0], target = [45.0, 5.0, 0.0] },\n'
      printf ']\n'
    fi
  } > "$f"
  echo "$f"
}

# Four cascades of 12×6×12 probes, 1, 2, 4 and 8 m apart (the coarsest spans ±44 m around
# the camera, so a whole copy seen from inside it); a fitted volume of about as many probes.
CASCADES=(--gi ddgi --cascades 4 --probes 12,6,12 --set probe_spacing_m=1.0 --rays-per-probe 128)
FITTED=(--gi ddgi --probes 20,8,20 --rays-per-probe 128)
for n in 1 2 4; do
  s=$(world $n)
  $BIN render --scene "$s" "${CASCADES[@]}" --frames "$FRAMES" --width $W --height $H \
    --out "$OUT/cascades-$n.exr" --stats "$OUT/cascades-$n.json" 2>/dev/null
  $BIN render --scene "$s" "${FITTED[@]}" --frames "$FRAMES" --width $W --height $H \
    --out "$OUT/fitted-$n.exr" --stats "$OUT/fitted-$n.json" 2>/dev/null
  if [ "$n" != 2 ]; then
    $BIN reference --scene "$s" --width $W --height $H --spp "$SPP" --out "$OUT/reference-$n.exr" 2>/dev/null
  fi
done

fly=$(world 4 fly)
$BIN render --scene "$fly" "${CASCADES[@]}" --frames "$FLY_FRAMES" --width $W --height $H \
  --sequence "$OUT/fly" --sequence-exr --out "$OUT/fly.exr" --stats "$OUT/fly.json" --gif "$OUT/fly.gif" 2>/dev/null
for k in 0 150 $((FLY_FRAMES - 1)); do
  $BIN reference --scene "$fly" --frame $k --width $W --height $H --spp "$SPP" --out "$OUT/fly-reference-$k.exr" 2>/dev/null
done

flip() { $BIN compare "$1" "$2" | awk '{print $2}'; }
{
  echo "| world | triangles | cascades field update ms | ratio to 1×1 | fitted 20×8×20 ms | cascades FLIP vs 1×1 image | cascades FLIP vs reference | fitted FLIP vs reference |"
  echo "|---|---|---|---|---|---|---|---|"
  base=$(jq .field_update_ms "$OUT/cascades-1.json")
  for n in 1 2 4; do
    c=$(jq .field_update_ms "$OUT/cascades-$n.json"); fi_=$(jq .field_update_ms "$OUT/fitted-$n.json")
    tri=$(jq .triangles "$OUT/cascades-$n.json")
    ref="$OUT/reference-$n.exr"; [ -f "$ref" ] || ref=""
    printf '| %s×%s | %s | %.0f | %.2f | %.0f | %s | %s | %s |\n' $n $n "$tri" "$c" "$(echo "$c / $base" | bc -l)" "$fi_" \
      "$(flip "$OUT/cascades-1.exr" "$OUT/cascades-$n.exr")" \
      "${ref:+$(flip "$ref" "$OUT/cascades-$n.exr")}" "${ref:+$(flip "$ref" "$OUT/fitted-$n.exr")}"
  done
  echo
  echo "Cascade costs (4×4 world): rays per cascade in the batch $(jq -c .batch_rays_per_volume "$OUT/cascades-4.json"), probes $(jq .probes "$OUT/cascades-4.json"), states $(jq -c .probe_states "$OUT/cascades-4.json")"
  echo
  echo "Flythrough, 4×4 world, $FLY_FRAMES frames ($(jq .probes_scrolled_in "$OUT/fly.json") probes scrolled in):"
  echo "- per-frame change of the image mean (luminance-free, mean of RGB): $(jq -r '[.frame_means | map(add/3) | . as $m | range(1; length) | (($m[.] - $m[.-1]) / $m[.-1] | fabs)] | "median \(sort | .[length/2|floor] * 1000 | round / 10) %, max \(max * 1000 | round / 10) %"' "$OUT/fly.json")"
  echo "- per-frame change of the indirect (field) term's mean: $(jq -r '[.frame_indirect_means | map(add/3) | . as $m | range(1; length) | (($m[.] - $m[.-1]) / $m[.-1] | fabs)] | "median \(sort | .[length/2|floor] * 1000 | round / 10) %, max \(max * 1000 | round / 10) %"' "$OUT/fly.json")"
  echo "- surface pixels without indirect light per frame: max $(jq '.frame_unlit_fraction | max' "$OUT/fly.json")"
  echo "- FLIP against the reference at frames:"
  for k in 0 150 $((FLY_FRAMES - 1)); do
    printf -- '- %s: %s\n' $k "$(flip "$OUT/fly-reference-$k.exr" "$(printf '%s/fly/frame-%04d.exr' "$OUT" $k)")"
  done
} | tee "$OUT/table.md"
