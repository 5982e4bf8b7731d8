#!/usr/bin/env bash
# Issue "Denser is better…": a 300-frame flythrough of the 4×4 world of Sponza
# copies (scripts/world-scale.sh's world and path: along copy (0, 0)'s atrium,
# up through its roof, over the roofs, down into copy (1, 0)), four cascades of
# 12×6×12 probes 1 m apart innermost, 128 rays, normal maps off (the reference
# has none). Per configuration: HDR-FLIP against `probegi reference --frame K`
# at 10 frames spread over the path, the indirect term's mean change per frame,
# the mean probe rays per frame; and the last frame against a static camera
# converged at the same spot (300 frames). Plots both curves (matplotlib).
# Writes OUT/table.md, OUT/flythrough.png. A benchmark, not a test (~40 min on
# 2 cores). Usage: [W=160 H=90 SPP=256 REUSE=0] scripts/world-flythrough.sh [CONFIG...]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/world-fly}
W=${W:-160}; H=${H:-90}; SPP=${SPP:-256}; FRAMES=300
KS=(0 33 66 99 132 165 198 231 264 299)
mkdir -p "$OUT"
cargo build --release --locked -q -p probegi-cli
BIN=./target/release/probegi
fly="$OUT/sponza-4x4-fly.toml"
still="$OUT/sponza-4x4-last-frame.toml"
# shellcheck source=scripts/sponza-world.sh
. scripts/sponza-world.sh
world() { sponza_world "$1"; }
{
  world 4
  printf '[camera]\nposition = [-13.0, 3.0, 0.0]\ntarget = [0.0, 4.0, 0.0]\nfov_y_deg = 65.0\n'
  printf 'keyframes = [\n'
  printf '  { frame = 0, position = [-13.0, 3.0, 0.0], target = [0.0, 4.0, 0.0] },\n'
  printf '  { frame = 100, position = [9.0, 3.0, 0.0], target = [20.0, 5.0, 0.0] },\n'
  printf '  { frame = 160, position = [0.0, 22.0, 0.0], target = [10.0, 0.0, 0.0] },\n'
  printf '  { frame = 230, position = [35.0, 22.0, 0.0], target = [45.0, 0.0, 0.0] },\n'
  printf '  { frame = 299, position = [35.0, 6.0, 0.0], target = [45.0, 5.0, 0.0] },\n'
  printf ']\n'
} > "$fly"
{ world 4; printf '[camera]\nposition = [35.0, 6.0, 0.0]\ntarget = [45.0, 5.0, 0.0]\nfov_y_deg = 65.0\n'; } > "$still"
# The same pose drifting by 1 mm over the run: a camera that moves, so its
# direct light and albedo go through the temporal filter as on the flythrough
# (a still camera accumulates them over every frame).
{
  world 4; printf '[camera]\nposition = [35.0, 6.0, 0.0]\ntarget = [45.0, 5.0, 0.0]\nfov_y_deg = 65.0\n'
  printf 'keyframes = [\n  { frame = 0, position = [35.0, 6.0, 0.0], target = [45.0, 5.0, 0.0] },\n'
  printf '  { frame = 299, position = [35.0, 6.0, 0.0], target = [45.0, 5.0, 0.001] },\n]\n'
} > "$OUT/sponza-4x4-last-frame-moving.toml"
CASCADES=(--gi ddgi --cascades 4 --probes 12,6,12 --set probe_spacing_m=1.0 --rays-per-probe 128 --set normal_maps=false)
declare -A CONFIGS=(
  [default]=""
  [screen]="--set probe_states=screen"
  [screen-edge-buffers]="--set probe_states=screen --set volume_edge_buffer_planes=2"
  [items-2-4]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true"
  [items-2-4-temporal-off]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --temporal-frames 0"
  [items-2-4-unclamped]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --temporal-clip-sigma 0"
  [items-2-4-t2]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --temporal-frames 2"
  [items-2-4-t8]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --temporal-frames 8"
  [items-2-4-t8-unclamped]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --temporal-frames 8 --temporal-clip-sigma 0"
  [ramp]="--set probe_hysteresis_ramp=true"
  [screen-edge-buffers-ramp]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_hysteresis_ramp=true"
  [items-2-4-ramp]="--set probe_states=screen --set volume_edge_buffer_planes=2 --set probe_seeding=true --set probe_hysteresis_ramp=true"
)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(default items-2-4 screen-edge-buffers)
for k in "${KS[@]}"; do
  [ -f "$OUT/reference-$k.exr" ] ||
    "$BIN" reference --scene "$fly" --frame "$k" --width "$W" --height "$H" --spp "$SPP" \
      --out "$OUT/reference-$k.exr" 2>/dev/null
done
[ -f "$OUT/static.exr" ] ||
  "$BIN" render --scene "$still" "${CASCADES[@]}" --frames "$FRAMES" --width "$W" --height "$H" \
    --out "$OUT/static.exr" --stats "$OUT/static.json" 2>/dev/null
static=$("$BIN" compare "$OUT/reference-299.exr" "$OUT/static.exr" | awk '/mean_flip/ {printf "%.3f", $2}')
[ -f "$OUT/static-moving.exr" ] ||
  "$BIN" render --scene "$OUT/sponza-4x4-last-frame-moving.toml" "${CASCADES[@]}" --frames "$FRAMES" --width "$W" \
    --height "$H" --out "$OUT/static-moving.exr" 2>/dev/null
moving=$("$BIN" compare "$OUT/reference-299.exr" "$OUT/static-moving.exr" | awk '/mean_flip/ {printf "%.3f", $2}')
for name in "${names[@]}"; do
  # REUSE=1 keeps a configuration's earlier run.
  [ "${REUSE:-0}" = 1 ] && [ -f "$OUT/$name-flip.txt" ] && continue
  # shellcheck disable=SC2086
  "$BIN" render --scene "$fly" "${CASCADES[@]}" ${CONFIGS[$name]} --frames "$FRAMES" --width "$W" --height "$H" \
    --sequence "$OUT/$name" --sequence-exr --out "$OUT/$name.exr" --stats "$OUT/$name.json" 2>/dev/null
  for k in "${KS[@]}"; do
    "$BIN" compare "$OUT/reference-$k.exr" "$(printf '%s/%s/frame-%04d.exr' "$OUT" "$name" "$k")" |
      awk -v k="$k" '/mean_flip/ {f = $2} /dark_fraction/ {d = $2} END {print k, f, d}'
  done > "$OUT/$name-flip.txt"
done
python3 - "$OUT" "$static" "$moving" "${names[@]}" <<'EOF'
import json, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
out, static, moving, names = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4:]
fig, (a, b) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
rows = []
for n in names:
    d = json.load(open(f"{out}/{n}.json"))
    kfd = [tuple(map(float, l.split())) for l in open(f"{out}/{n}-flip.txt")]
    flip, dark = [(k, f) for k, f, *_ in kfd], kfd[-1][2] if len(kfd[-1]) > 2 else float("nan")
    m = [sum(v) / 3 for v in d["frame_indirect_means"]]
    change = [100 * abs(m[i] - m[i - 1]) / max(m[i - 1], 1e-9) for i in range(1, len(m))]
    a.plot([k for k, _ in flip], [f for _, f in flip], marker="o", label=n)
    b.plot(range(1, len(m)), change, label=n, linewidth=0.8)
    c = sorted(change)
    rows.append((n, flip, c[len(c) // 2], c[-1], d["probe_rays_traced"] / d["frames"], dark))
a.axhline(static, color="grey", linestyle="--", label=f"still camera at frame 299 ({static:.3f})")
a.axhline(moving, color="black", linestyle=":", label=f"same pose, moving camera ({moving:.3f})")
a.set_ylabel("HDR-FLIP vs reference"); a.legend(fontsize=8)
b.set_ylabel("indirect mean change, %"); b.set_xlabel("frame"); b.set_yscale("log")
fig.tight_layout(); fig.savefig(f"{out}/flythrough.png", dpi=100)
with open(f"{out}/table.md", "w") as t:
    ks = [k for k, _ in rows[0][1]]
    t.write("| configuration | " + " | ".join(f"frame {int(k)}" for k in ks) + " | last − still | last − same pose moving | last frame's dark pixels | indirect change: median, max | probe rays per frame |\n")
    t.write("|---|" + "---|" * (len(ks) + 5) + "\n")
    for n, flip, med, mx, rays, dark in rows:
        t.write(f"| {n} | " + " | ".join(f"{f:.3f}" for _, f in flip) + f" | {flip[-1][1] - static:+.3f} | {flip[-1][1] - moving:+.3f} | {100 * dark:.1f} % | {med:.1f} %, {mx:.1f} % | {rays:.0f} |\n")
    t.write(f"\nStill camera at frame 299's pose, 300 frames: {static:.3f}; the same pose drifting 1 mm (a moving camera, its direct light and albedo through the temporal filter): {moving:.3f}\n")
print(open(f"{out}/table.md").read())
EOF
