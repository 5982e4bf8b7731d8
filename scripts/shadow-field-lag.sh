#!/usr/bin/env bash
# Does the shadowing field (seed 003 ch. 5) follow a moving occluder? On
# scenes/sponza-moving-occluder.toml (Sponza under the sun, 16³ probes, 64 rays, a
# block sliding through the sunlit atrium over frames 0–60 and back by 120, then
# still), every frame of `render --gi ddgi` with shadow_field=true against the same
# frames with exact shadow rays (shadow_field=false): HDR-FLIP per frame. A field
# that follows within its hysteresis lag stays near its error while the block is
# still (frames 130–149). Writes OUT/lag.csv; prints a Markdown summary.
# Usage: [FIELD_SET="shadow_field_surfel_reach_rel=1 …"] scripts/shadow-field-lag.sh [OUT_DIR]
# (default out/shadow-field-lag); FIELD_SET adds --set keys to the field's run. Needs a release build.
set -euo pipefail
out=${1:-out/shadow-field-lag}
bin=${PROBEGI_BIN:-target/release/probegi}
scene=${SCENE:-scenes/sponza-moving-occluder.toml}
frames=${FRAMES:-150}
size=(--width "${WIDTH:-320}" --height "${HEIGHT:-180}")
mkdir -p "$out"
extra=()
for kv in ${FIELD_SET:-}; do extra+=(--set "$kv"); done
for f in true false; do
    rm -rf "${out:?}/field-$f"
    args=(--set shadow_field=$f)
    [[ $f == true ]] && args+=("${extra[@]}")
    "$bin" render --scene "$scene" --gi ddgi "${size[@]}" --frames "$frames" "${args[@]}" \
        --sequence "$out/field-$f" --sequence-exr --out "$out/field-$f.exr" 2>/dev/null
done
echo "frame,hdr_flip_field_vs_exact" > "$out/lag.csv"
for ((k = 0; k < frames; k++)); do
    name=$(printf 'frame-%04d.exr' "$k")
    v=$("$bin" compare "$out/field-false/$name" "$out/field-true/$name" 2>/dev/null | sed -n 's/^mean_flip: //p')
    echo "$k,$v" >> "$out/lag.csv"
done
mean() { awk -F, -v a="$1" -v b="$2" 'NR > 1 && $1 >= a && $1 <= b { s += $2; n++ } END { printf "%.4f", s / n }' "$out/lag.csv"; }
echo "| frames | block | mean HDR-FLIP, field vs exact shadow rays |"
echo "|---|---|---|"
echo "| 10–55 | sliding out | $(mean 10 55) |"
echo "| 65–115 | sliding back | $(mean 65 115) |"
echo "| 130–$((frames - 1)) | still | $(mean 130 $((frames - 1))) |"
# The curve, where matplotlib is installed (pip install matplotlib).
python3 - "$out" <<'PY' 2>/dev/null || echo "(no matplotlib: $out/lag.csv holds the curve)"
import csv, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
out = sys.argv[1]
rows = list(csv.DictReader(open(f"{out}/lag.csv")))
x = [int(r["frame"]) for r in rows]
y = [float(r["hdr_flip_field_vs_exact"]) for r in rows]
plt.figure(figsize=(7, 3))
plt.plot(x, y)
for f, label in [(60, "block turns"), (120, "block stops")]:
    plt.axvline(f, color="grey", ls="--")
    plt.text(f + 1, max(y), label, va="top", fontsize=8)
plt.xlabel("frame")
plt.ylabel("HDR-FLIP, field vs exact shadows")
plt.title("The shadowing field under a moving occluder (Sponza, 16³ probes, 64 rays)")
plt.tight_layout()
plt.savefig(f"{out}/lag.png", dpi=100)
print(f"wrote {out}/lag.png")
PY
