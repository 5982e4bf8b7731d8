#!/usr/bin/env bash
# Seed 000 Table 1 on the forest: DDGI image quality (HDR-FLIP against
# `probegi reference`) over probe density × irradiance probe resolution, with a
# contact sheet (reference | DDGI | FLIP) per configuration, and the same pair
# with alpha cutouts off to show where the leaves leak. Not part of CI.
#   bash scripts/forest-table.sh [OUT_DIR]     (default out/forest-table)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/forest-table}
W=${W:-320} H=${H:-240} SPP=${SPP:-512} FRAMES=${FRAMES:-64}
GRIDS=${GRIDS:-"4,2,4 8,4,8 16,8,16"} TEXELS=${TEXELS:-"8 16 32"}
mkdir -p "$out"
cargo build --release -q
bin=target/release/probegi
scene=builtin:forest
common=(--scene "$scene" --width "$W" --height "$H")
for cut in true false; do
  "$bin" reference "${common[@]}" --spp "$SPP" --set alpha_cutouts=$cut --out "$out/reference-cutouts-$cut.exr"
done
table="$out/table.md"
{
  echo "| grid \\ irradiance texels | ${TEXELS// / | } |"
  echo "|---|$(for _ in $TEXELS; do printf -- '---|'; done)"
} >"$table"
for g in $GRIDS; do
  row="| ${g//,/×} |"
  for t in $TEXELS; do
    name="ddgi-${g//,/x}-t$t"
    "$bin" render --gi ddgi "${common[@]}" --frames "$FRAMES" --probes "$g" \
      --set probe_irradiance_texels="$t" --out "$out/$name.exr" --stats "$out/$name.json"
    flip=$("$bin" compare "$out/reference-cutouts-true.exr" "$out/$name.exr" --out "$out/$name-sheet.png" | awk '/mean_flip/ {print $2}')
    row="$row $flip |"
  done
  echo "$row" >>"$table"
done
# Leaks before and after cutouts: the densest configuration, each against its own reference.
g=${GRIDS##* }
for cut in true false; do
  name="leak-cutouts-$cut"
  "$bin" render --gi ddgi "${common[@]}" --frames "$FRAMES" --probes "$g" --set alpha_cutouts=$cut \
    --out "$out/$name.exr"
  flip=$("$bin" compare "$out/reference-cutouts-$cut.exr" "$out/$name.exr" --out "$out/$name-sheet.png" | awk '/mean_flip/ {print $2}')
  echo "alpha_cutouts=$cut, grid ${g//,/×}: FLIP $flip (sheet $out/$name-sheet.png)" >>"$table"
done
cat "$table"
