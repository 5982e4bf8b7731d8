#!/usr/bin/env bash
# Issue "Lit by a real sky…", goal 5: how the field follows a sky map that turns.
# The shared Sponza from the README's camera under a Blender studio-light map
# (apt-get install blender-data), turned by STEP_DEG at frame 60 in one frame (a
# jump: the scene-change detector's large light change) and, in a second run,
# turning steadily by the same angle over frames 60-90 (a moving sun: a small
# light change each frame). For each, with the fast-convergence heuristics on
# and off (`probe_fast_convergence`), the frames the field's term (the indirect
# image's mean) takes after frame 60 to come within 5 % of its mean over the
# last 20 frames. Writes OUT_DIR/sky-lag.csv (frame, one column per run) and
# prints a Markdown table.
# Usage: scripts/sky-lag.sh [OUT_DIR] (default out/sky-lag); needs a release build.
set -euo pipefail
out=${1:-out/sky-lag}
bin=${PROBEGI_BIN:-target/release/probegi}
map=${MAP:-/usr/share/blender/datafiles/studiolights/world/courtyard.exr}
sponza=$(cd "$(dirname "$0")/.." && pwd)/../shared/scenes/dabrovic-sponza/sponza.obj
step=${STEP_DEG:-90}
frames=${FRAMES:-180}
[ -f "$map" ] || { echo "sky-lag: no $map (apt-get install blender-data)" >&2; exit 2; }
[ -f "$sponza" ] || { echo "sky-lag: no $sponza (../shared beside the repository)" >&2; exit 2; }
mkdir -p "$out"
scene() { # $1: name, $2: the keyframes
    cat >"$out/$1.toml" <<TOML
[[meshes]]
path = "$sponza"
[sky_map]
path = "$map"
intensity = ${INTENSITY:-4}
keyframes = $2
[camera]
position = [-12.0, 2.0, 0.0]
target = [10.0, 4.0, 0.0]
fov_y_deg = 60.0
TOML
}
scene jump "[{ frame = 60, rotation_deg = 0.0 }, { frame = 61, rotation_deg = $step.0 }]"
scene turn "[{ frame = 60, rotation_deg = 0.0 }, { frame = 90, rotation_deg = $step.0 }]"
runs=()
for s in jump turn; do
    for fc in true false; do
        "$bin" render --scene "$out/$s.toml" --gi ddgi --frames "$frames" --width 80 --height 60 \
            --set probe_fast_convergence=$fc --stats "$out/$s-$fc.json" --out "$out/$s-$fc.png" 2>/dev/null
        runs+=("$s-$fc")
    done
done
python3 - "$out" "${runs[@]}" <<'PY'
import json, sys
out, runs = sys.argv[1], sys.argv[2:]
series = {r: [sum(m) / 3 for m in json.load(open(f"{out}/{r}.json"))["frame_indirect_means"]] for r in runs}
n = len(next(iter(series.values())))
with open(f"{out}/sky-lag.csv", "w") as f:
    f.write("frame," + ",".join(runs) + "\n")
    for i in range(n):
        f.write(f"{i}," + ",".join(f"{series[r][i]:.6f}" for r in runs) + "\n")
print("| change at frame 60 | fast convergence | indirect mean before → after | frames to within 5 % |")
print("|---|---|---|---|")
for r in runs:
    s = series[r]
    final = sum(s[-20:]) / 20
    before = s[59]
    settle = next((i - 60 for i in range(60, n) if all(abs(x - final) <= 0.05 * final for x in s[i:])), None)
    kind, fc = r.rsplit("-", 1)
    print(f"| {kind} | {fc} | {before:.4f} → {final:.4f} | {settle} |")
PY
