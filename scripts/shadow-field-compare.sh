#!/usr/bin/env bash
# The shadowing field (seed 003 ch. 5) against exact shadow rays and the path-traced
# reference on builtin:shadow-box (seed 003 Fig. 7.10), at sharpening 1, 2 and 3:
#  - light visibility (`render --ao` against `reference --ao`), HDR-FLIP;
#  - the full image (`render --gi ddgi`, shadow_field true and false, against
#    `reference`), HDR-FLIP; and the render times.
# Usage: scripts/shadow-field-compare.sh [OUT_DIR] (default out/shadow-field); needs a
# release build (cargo build --release). Prints a Markdown table.
set -euo pipefail
out=${1:-out/shadow-field}
bin=${PROBEGI_BIN:-target/release/probegi}
scene=${SCENE:-builtin:shadow-box}
size=(--width 320 --height 240)
mkdir -p "$out"
"$bin" reference --scene "$scene" "${size[@]}" --spp "${SPP:-256}" --out "$out/reference.exr" --ao "$out/ao-exact.exr" 2>/dev/null
flip() { "$bin" compare "$1" "$2" 2>/dev/null | sed -n 's/^mean_flip: //p'; }
secs() { sed -n 's/.*frames, \([0-9.]*\) s.*/\1/p'; }
echo "| shadows | visibility HDR-FLIP vs exact | image HDR-FLIP vs reference | render s (${FRAMES:-32} frames) |"
echo "|---|---|---|---|"
t=$("$bin" render --scene "$scene" --gi ddgi "${size[@]}" --frames "${FRAMES:-32}" --set shadow_field=false \
    --out "$out/exact.exr" 2>&1 | secs)
echo "| exact shadow rays | 0 | $(flip "$out/reference.exr" "$out/exact.exr") | $t |"
for k in 1 2 3; do
    t=$("$bin" render --scene "$scene" --gi ddgi "${size[@]}" --frames "${FRAMES:-32}" --set shadow_field=true \
        --set shadow_field_sharpness=$k --ao "$out/ao-field-k$k.exr" --out "$out/field-k$k.exr" 2>&1 | secs)
    echo "| field, sharpening $k | $(flip "$out/ao-exact.exr" "$out/ao-field-k$k.exr") | $(flip "$out/reference.exr" "$out/field-k$k.exr") | $t |"
done
