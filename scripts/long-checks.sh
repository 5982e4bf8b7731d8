#!/usr/bin/env bash
# Long checks: what the test suite (scripts/test.sh) runs briefly, run for
# minutes in release. Every fuzzer with a long budget and a fresh seed (printed,
# so a failure can be replayed with PROBEGI_FUZZ_SEED=N), and the drift soak five times as
# long as the suite's. Each test prints its figures (--nocapture).
# Usage: scripts/long-checks.sh [MINUTES_PER_FUZZER]   (default 5; the loaders get twice that)
# Needs what scripts/test.sh needs: ../shared/scenes, and a Vulkan driver
# (lavapipe) for the seam fuzzer.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes="${1:-5}"
secs=$((minutes * 60))
seed="${PROBEGI_FUZZ_SEED:-$(date +%s)}"
echo "long checks: ${minutes} min per fuzzer, seed ${seed} (PROBEGI_FUZZ_SEED=${seed} replays it)" >&2
if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -d "${XDG_RUNTIME_DIR}" ]; then
  XDG_RUNTIME_DIR=$(mktemp -d)
  export XDG_RUNTIME_DIR
fi
export PROBEGI_FUZZ_SEED="$seed"
long() { # crate, test target, test-name filter, then VAR=value settings
  local crate=$1 target=$2 filter=$3; shift 3
  echo "== $crate --test $target $filter ($*)" >&2
  env "$@" cargo test --release --locked -p "$crate" --test "$target" -- --nocapture "$filter"
}
# Most crates' integration tests are one binary, `it`, a module per former file.
long probegi-scene it fuzz_loaders:: PROBEGI_FUZZ_SECONDS=$((2 * secs))
long probegi-scene it fuzz_cameras_and_rays:: PROBEGI_FUZZ_CAMERA_SECONDS="$secs"
long probegi-image fuzz_images "" PROBEGI_FUZZ_IMAGE_SECONDS="$secs"
long probegi-cli it fuzz_args:: PROBEGI_FUZZ_ARGS_SECONDS="$secs"
long probegi-wgpu it fuzz_seam_rays:: PROBEGI_FUZZ_SEAM_SECONDS="$secs"
long probegi-cpu it soak:: PROBEGI_SOAK_FRAMES=50000
echo "long checks passed (seed ${seed})" >&2
