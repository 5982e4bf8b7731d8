#!/usr/bin/env bash
# The viewer's screenshots in docs/images (view-window-*.png): scripted runs of
# `probegi view` in a window under Xvfb (xvfb-run), on the CPU backend, each
# leaving the window's capture beside its --screenshot.
# Usage: scripts/view-screenshots.sh [OUT_DIR]   (default: out/view-screenshots)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/view-screenshots}"
mkdir -p "$out"
command -v xvfb-run >/dev/null || { echo "needs xvfb-run (apt-get install xvfb)" >&2; exit 1; }
cargo build --release --locked -q -p probegi-cli
bin=$PWD/target/release/probegi
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
# The reference: the scene clock paused at frame 1 (the sun moves), then F5.
printf '1 key space down\n2 key f5 down\n' > "$out/reference.script"
shot() { # name, frames, then view arguments
  local name=$1 frames=$2; shift 2
  xvfb-run -a -s "-screen 0 1280x800x24" "$bin" view --backend cpu --width 320 --height 180 \
    --exit-after-frames "$frames" --screenshot "$out/$name.png" "$@"
  cp "$out/$name-window.png" "docs/images/view-window-$name.png"
}
flight=(--scene builtin:sponza-sun --input-script scenes/sponza-flight.script)
shot full 60 "${flight[@]}"
shot indirect 60 "${flight[@]}" --view indirect
shot probes 60 "${flight[@]}" --view probes
shot atlas 40 --scene builtin:sponza-sun --view irradiance-atlas
shot reference 60 --scene builtin:sponza-sun --input-script "$out/reference.script" --reference-spp 64
shot forest 30 --scene builtin:forest
