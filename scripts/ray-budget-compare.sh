#!/usr/bin/env bash
# The per-frame ray budget (issue 30; seed 003 §8.2, seed 000 §5.2) at equal rays,
# on a moving scene: HDR-FLIP against the path-traced reference at several frames of
#  - every tracing probe at R rays each (the full cost);
#  - a budget of half of that, at R rays per probe (`--set ray_budget=N`);
#  - every tracing probe at R/2 rays (fixed rays at the same budget);
#  - the full run again with another seed (how far apart noise alone puts two runs).
# Usage: [SCENE=…] [FRAMES="20 45 75"] [R=128] [SPP=256] scripts/ray-budget-compare.sh [OUT_DIR]
# (default out/ray-budget); needs a release build. Prints a Markdown table.
set -euo pipefail
out=${1:-out/ray-budget}
bin=${PROBEGI_BIN:-target/release/probegi}
scene=${SCENE:-scenes/cornell-moving-light.toml}
read -r -a frames <<< "${FRAMES:-20 45 75}"
r=${R:-128}
size=(--width "${WIDTH:-320}" --height "${HEIGHT:-240}")
last=0
for f in "${frames[@]}"; do ((f > last)) && last=$f; done
mkdir -p "$out"
for f in "${frames[@]}"; do
    [[ -f "$out/ref-$f.exr" ]] || "$bin" reference --scene "$scene" "${size[@]}" --spp "${SPP:-256}" --frame "$f" \
        --out "$out/ref-$f.exr" 2>/dev/null
done
json() { sed -n "s/.*\"$2\": *\([0-9.]*\).*/\1/p" "$1" | head -1; }
"$bin" render --scene "$scene" --gi ddgi --frames 1 --width 8 --height 8 --rays-per-probe "$r" \
    --stats "$out/probes.json" --out "$out/probes.png" 2>/dev/null
probes=$(json "$out/probes.json" probes)
run() {
    local name=$1
    shift
    rm -rf "${out:?}/$name"
    "$bin" render --scene "$scene" --gi ddgi "${size[@]}" --frames $((last + 1)) --sequence "$out/$name" \
        --sequence-exr --stats "$out/$name.json" --out "$out/$name.exr" "$@" 2>/dev/null
}
run full --rays-per-probe "$r"
# Half of what every tracing probe costs (jcgt's sleeping probes trace nothing).
full_rays=$(json "$out/full.json" rays_per_frame)
budget=$((${full_rays%.*} / 2))
run budget --rays-per-probe "$r" --set ray_budget="$budget"
run fixed-half --rays-per-probe $((r / 2))
# The noise scale: the full run with another seed.
run full-seed-1 --rays-per-probe "$r" --seed 1
flip() { "$bin" compare "$1" "$2" 2>/dev/null | sed -n 's/^mean_flip: //p'; }
header="| $scene ($probes probes) | field rays, last frame |"
rule="|---|---|"
for f in "${frames[@]}"; do header+=" HDR-FLIP frame $f |"; rule+="---|"; done
echo "$header"
echo "$rule"
for name in full full-seed-1 budget fixed-half; do
    row="| $name | $(json "$out/$name.json" rays_per_frame) |"
    for f in "${frames[@]}"; do
        row+=" $(flip "$out/ref-$f.exr" "$(printf '%s/%s/frame-%04d.exr' "$out" "$name" "$f")") |"
    done
    echo "$row"
done
echo "(budget: ray_budget=$budget, half the full run's last frame; $probes probes × $r rays)"
