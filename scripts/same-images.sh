#!/usr/bin/env bash
# Renders the issue-28 set of CPU images at a fixed seed and prints one sha256
# per image: run it before and after a change that must not change behaviour
# and diff the two listings (`bash scripts/same-images.sh > before.txt`).
# Usage: [PROBEGI_BIN=path] scripts/same-images.sh [OUT_DIR]   (default: out/same-images)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/same-images}"
mkdir -p "$out"
# PROBEGI_BIN: a binary built elsewhere (e.g. a copy of the one from before a change).
bin="${PROBEGI_BIN:-}"
if [ -z "$bin" ]; then
  cargo build --release --locked -q -p probegi-cli
  bin=target/release/probegi
fi
shared=../shared/scenes
run() { # name, then render arguments
  local name=$1; shift
  "$bin" render --seed 7 --out "$out/$name.exr" "$@" >/dev/null 2>&1 ||
    { echo "$name: render failed" >&2; exit 1; }
  sha256sum "$out/$name.exr" | awk -v n="$name" '{print $1, n}'
}
run cornell-box --scene builtin:cornell-box --width 96 --height 96 --gi ddgi --frames 24
run door-room --scene builtin:door-room --width 96 --height 96 --gi ddgi --frames 24
run sponza --scene builtin:sponza-sun --width 96 --height 64 --gi ddgi --frames 6
run cornell-original --scene "$shared/cornell-box/CornellBox-Original.obj" --width 64 --height 64 --gi ddgi --frames 12
run forest --scene builtin:forest --width 96 --height 64 --gi ddgi --frames 6
run cascades --scene builtin:sponza-sun --width 96 --height 64 --gi ddgi --frames 6 --cascades 2
run moving-box --scene scenes/moving-box.toml --width 96 --height 96 --gi ddgi --frames 12
run sh-cornell --scene builtin:cornell-box --width 64 --height 64 --gi sh --frames 8
