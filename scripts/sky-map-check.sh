#!/usr/bin/env bash
# Issue "Lit by a real sky…", goal 5: DDGI under an environment map against the
# path-traced reference, on the CPU and the wgpu backend, on the shared Sponza
# from the README's camera, under Blender's studio-light maps (Debian's
# blender-data: apt-get install blender-data). For each map: the reference
# (`probegi reference`, the map importance-sampled), `render --gi ddgi` on both
# backends, HDR-FLIP of each against the reference and of the two backends
# against each other, the mean ratio to the reference and the dark fraction.
# Usage: scripts/sky-map-check.sh [OUT_DIR] (default out/sky-map); needs a release
# build. MAPS (default "courtyard sunset"), INTENSITY (default 4), FRAMES (100),
# SPP (256), BACKENDS ("cpu wgpu"; wgpu needs a Vulkan driver, lavapipe is slow).
set -euo pipefail
out=${1:-out/sky-map}
bin=${PROBEGI_BIN:-target/release/probegi}
maps_dir=${MAPS_DIR:-/usr/share/blender/datafiles/studiolights/world}
scene=${SCENE:-../shared/scenes/dabrovic-sponza/sponza.obj}
view=(--camera-pos=-12,2,0 --camera-target 10,4,0 --fov-y 60 --width "${WIDTH:-160}" --height "${HEIGHT:-120}")
[ -d "$maps_dir" ] || { echo "sky-map-check: no $maps_dir (apt-get install blender-data)" >&2; exit 2; }
mkdir -p "$out"
flip() { "$bin" compare "$1" "$2" 2>/dev/null | sed -n 's/^mean_flip: //p'; }
dark() { "$bin" compare "$1" "$2" 2>/dev/null | sed -n 's/^dark_fraction: //p'; }
ratio() { "$bin" compare "$1" "$2" 2>/dev/null | awk '/^mean_ratio:/ { printf "%.3f %.3f %.3f\n", $2, $3, $4 }'; }
echo "| map (× ${INTENSITY:-4}) | backend | HDR-FLIP vs reference | dark fraction | mean ratio to reference (R G B) | render s (${FRAMES:-100} frames) |"
echo "|---|---|---|---|---|---|"
for m in ${MAPS:-courtyard sunset}; do
    map=(--sky-map "$maps_dir/$m.exr" --sky-intensity "${INTENSITY:-4}")
    ref="$out/$m-reference.exr"
    [ -f "$ref" ] || "$bin" reference --scene "$scene" "${view[@]}" "${map[@]}" --spp "${SPP:-256}" --out "$ref" 2>/dev/null
    for b in ${BACKENDS:-cpu wgpu}; do
        img="$out/$m-ddgi-$b.exr"
        t=$("$bin" render --scene "$scene" "${view[@]}" "${map[@]}" --gi ddgi --backend "$b" --frames "${FRAMES:-100}" \
            --out "$img" 2>&1 | sed -n 's/.*frames, \([0-9.]*\) s.*/\1/p')
        echo "| $m | $b | $(flip "$ref" "$img") | $(dark "$ref" "$img") | $(ratio "$ref" "$img") | $t |"
    done
    if [ -f "$out/$m-ddgi-cpu.exr" ] && [ -f "$out/$m-ddgi-wgpu.exr" ]; then
        echo "| $m | CPU vs wgpu | $(flip "$out/$m-ddgi-cpu.exr" "$out/$m-ddgi-wgpu.exr") | | | |"
    fi
done
