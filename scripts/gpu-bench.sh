#!/usr/bin/env bash
# Issue "The whole frame on the GPU…", device check: `probegi bench --gi ddgi
# --backend wgpu` on the shared Sibenik at seed 000 Table 2's probe grids
# (16×8×16, 32×8×32, 32×16×32, 32×32×32) and rays per probe (32–256), 8×8
# irradiance tiles as in the paper (6 interior texels + border, the default). Writes out/gpu-bench/sibenik.json and
# out/gpu-bench/table.md (GPU trace Mrays/s beside the paper's RTX 3080 figures).
# Meant for a machine with an NVIDIA GPU and its Vulkan driver; runs in a few
# minutes. Uses a prebuilt binary when BIN points at one (the device machines
# reach no crate registry), else builds it.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/gpu-bench}
BIN=${BIN:-./target/release/probegi}
SCENE=${SCENE:-../shared/scenes/sibenik/sibenik.obj}
FRAMES=${FRAMES:-1}
GRIDS=${GRIDS:-16,8,16 32,8,32 32,16,32 32,32,32}
RAYS=${RAYS:-32 64 128 256}
# ANY_ADAPTER=1 runs on whatever Vulkan driver is there (lavapipe: a dry run).
ANY_ADAPTER=${ANY_ADAPTER:-0}
mkdir -p "$OUT"

# The Vulkan loader and a driver manifest (ICD): say exactly what is missing.
if ! { ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1'; } && ! ls /usr/lib/x86_64-linux-gnu/libvulkan.so.1 >/dev/null 2>&1; then
  echo "gpu-bench: no Vulkan loader (libvulkan.so.1); install it (Debian/Ubuntu: apt-get install libvulkan1)" >&2
  exit 2
fi
icd=""
for d in ${VK_ICD_FILENAMES:-} /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/share/vulkan/icd.d; do
  for f in "$d"/nvidia_icd*.json "$d"; do
    [ -f "$f" ] && grep -qi nvidia "$f" 2>/dev/null && icd=$f && break 2
  done
done
if [ -z "$icd" ] && [ "$ANY_ADAPTER" = 1 ]; then
  echo "gpu-bench: no NVIDIA ICD; ANY_ADAPTER=1, so running on the default adapter" >&2
elif [ -z "$icd" ]; then
  echo "gpu-bench: no NVIDIA Vulkan ICD (nvidia_icd.json in /usr/share/vulkan/icd.d or /etc/vulkan/icd.d);" >&2
  echo "  the NVIDIA driver's Vulkan part is missing (Debian: nvidia-vulkan-icd; or the driver's .run installer)." >&2
  echo "  Found instead: $(ls /usr/share/vulkan/icd.d /etc/vulkan/icd.d 2>/dev/null | tr '\n' ' ')" >&2
  exit 2
fi
if [ -n "$icd" ]; then export VK_ICD_FILENAMES=$icd; echo "Vulkan ICD: $icd" >&2; fi
[ -x "$BIN" ] || cargo build --release --locked -q
[ -f "$SCENE" ] || { echo "gpu-bench: scene $SCENE not found (../shared beside the repository)" >&2; exit 2; }

args=()
for g in $GRIDS; do args+=(--grids "$g"); done
for r in $RAYS; do args+=(--rays "$r"); done
# Default texels: 6 interior + border = the paper's 8×8 probe resolution.
"$BIN" bench --gi ddgi --backend wgpu --scene "$SCENE" "${args[@]}" --frames "$FRAMES" --repeat 3 >"$OUT/sibenik.json"

python3 - "$OUT/sibenik.json" >"$OUT/table.md" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
# Seed 000 Table 2: Sibenik, RTX 3080, hardware ray tracing, Mrays/s.
paper = {32: [15.1, 57.4, 101.1, 155.2], 64: [29.5, 103.8, 160.2, 216.8],
         128: [56.8, 161.7, 225.1, 277.3], 256: [100.7, 224.1, 283.8, 316.1]}
grids = [[16, 8, 16], [32, 8, 32], [32, 16, 32], [32, 32, 32]]
rows = {(tuple(r["probes"]), r["rays_per_probe"]): r for r in d["sweep"]}
print(f"GPU trace of the field update on {d['adapter']}, Sibenik ({d['triangles']} triangles), "
      "WGSL CWBVH traversal, Mrays/s (seed 000 Table 2's RTX 3080 with hardware ray tracing in brackets)\n")
print("| rays | " + " | ".join("×".join(map(str, g)) for g in grids) + " |")
print("|---|" + "---|" * len(grids))
for rays in [32, 64, 128, 256]:
    cells = []
    for k, g in enumerate(grids):
        r = rows.get((tuple(g), rays))
        gpu = r and r.get("gpu")
        cells.append(f"{gpu['trace_mrays_per_s']:.1f} ({paper[rays][k]})" if gpu else f"– ({paper[rays][k]})")
    print(f"| {rays} | " + " | ".join(cells) + " |")
print("\nAll GPU passes (trace, shade, blend, border; relocation and classification stay on the CPU), Mrays/s:\n")
print("| rays | " + " | ".join("×".join(map(str, g)) for g in grids) + " |")
print("|---|" + "---|" * len(grids))
for rays in [32, 64, 128, 256]:
    cells = []
    for g in grids:
        r = rows.get((tuple(g), rays))
        cells.append(f"{r['gpu']['gpu_passes_mrays_per_s']:.1f}" if r and r.get("gpu") else "–")
    print(f"| {rays} | " + " | ".join(cells) + " |")
PY
cat "$OUT/table.md"
