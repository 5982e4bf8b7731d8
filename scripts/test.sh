#!/usr/bin/env bash
# The whole test suite: formatting, lints with warnings denied, then every test
# of every crate. The README's second command and .ci/run both run exactly this.
# Tests read the real scenes from ../shared/scenes beside the repository.
set -euo pipefail
cd "$(dirname "$0")/.."

for component in rustfmt clippy; do
  if ! cargo "${component/rustfmt/fmt}" --version >/dev/null 2>&1; then
    rustup component add "$component"
  fi
done

if [ ! -d ../shared/scenes ]; then
  echo "error: ../shared/scenes is missing; the tests read the shared scenes from beside the repository" >&2
  exit 1
fi

# GPU tests (crates/probegi-wgpu) run on any Vulkan driver; without one, install
# Mesa's software Vulkan (lavapipe) when apt is usable, and then require them.
# Any ICD manifest in either folder (one of them may exist empty: `ls a/* b/*`
# fails when either glob matches nothing, which skipped the GPU tests' requirement).
have_vulkan() {
  local f
  for f in /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json; do
    [ -e "$f" ] && return 0
  done
  return 1
}
if ! have_vulkan && command -v apt-get >/dev/null 2>&1; then
  echo "no Vulkan driver found: installing mesa-vulkan-drivers (lavapipe) for the GPU tests" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo -n"
  { $SUDO apt-get install -y mesa-vulkan-drivers >/dev/null 2>&1 ||
    { $SUDO apt-get update >/dev/null 2>&1 && $SUDO apt-get install -y mesa-vulkan-drivers >/dev/null 2>&1; }; } ||
    echo "could not install mesa-vulkan-drivers" >&2
fi
if have_vulkan; then
  export PROBEGI_REQUIRE_GPU=1
else
  echo "warning: no Vulkan driver and none could be installed: the GPU tests will SKIP (install mesa-vulkan-drivers)" >&2
fi
# The glTF corpus test (crates/probegi-scene/tests/it/assimp_gltf2.rs) loads every
# glTF 2.0 file of Debian's assimp-testmodels (importer-breaking files and valid
# ones): installed like mesa-vulkan-drivers, else that test skips with a warning.
ASSIMP_GLTF2=/usr/share/assimp/models/glTF2
if [ ! -d "$ASSIMP_GLTF2" ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing assimp-testmodels for the glTF corpus test" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo -n"
  { $SUDO apt-get install -y assimp-testmodels >/dev/null 2>&1 ||
    { $SUDO apt-get update >/dev/null 2>&1 && $SUDO apt-get install -y assimp-testmodels >/dev/null 2>&1; }; } ||
    echo "could not install assimp-testmodels" >&2
fi
if [ ! -d "$ASSIMP_GLTF2" ]; then
  echo "warning: assimp-testmodels is not installed: the glTF corpus test will SKIP" >&2
fi
# The viewer's real-window test (crates/probegi-cli/tests/it/view_window.rs) runs
# `probegi view` under Xvfb: install it (and the X libraries winit opens at run
# time) like mesa-vulkan-drivers, then require the test; without it, it skips.
if ! command -v xvfb-run >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
  echo "installing xvfb for the viewer's window test" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1 && SUDO="sudo -n"
  X_PACKAGES="xvfb xauth libxkbcommon-x11-0 libxcursor1 libxrandr2 libxi6"
  # shellcheck disable=SC2086
  { $SUDO apt-get install -y $X_PACKAGES >/dev/null 2>&1 ||
    { $SUDO apt-get update >/dev/null 2>&1 && $SUDO apt-get install -y $X_PACKAGES >/dev/null 2>&1; }; } ||
    echo "could not install xvfb" >&2
fi
if command -v xvfb-run >/dev/null 2>&1 && have_vulkan; then
  export PROBEGI_REQUIRE_DISPLAY=1
else
  echo "warning: no xvfb-run (or no Vulkan driver): the viewer's window test will SKIP (install xvfb)" >&2
fi
# Khronos glTF samples (WaterBottle, TextureSettingsTest, TextureTransformTest,
# AlphaBlendModeTest) as the scena crate 1.5.0 ships them in its tests, fetched
# once into a cache outside the repository for
# crates/probegi-scene/tests/it/khronos_gltf_samples.rs (which skips without them).
PROBEGI_SCENA_DIR="${XDG_CACHE_HOME:-$HOME/.cache}/probegi/scena-1.5.0"
if [ ! -d "$PROBEGI_SCENA_DIR/tests/assets/gltf/khronos" ]; then
  scena_tmp=$(mktemp -d)
  if command -v curl >/dev/null 2>&1 &&
    curl -fsSL --max-time 300 https://static.crates.io/crates/scena/scena-1.5.0.crate | tar xz -C "$scena_tmp" &&
    [ -d "$scena_tmp/scena-1.5.0/tests/assets/gltf/khronos" ]; then
    mkdir -p "$(dirname "$PROBEGI_SCENA_DIR")"
    rm -rf "$PROBEGI_SCENA_DIR"
    mv "$scena_tmp/scena-1.5.0" "$PROBEGI_SCENA_DIR"
  else
    echo "warning: could not fetch the scena 1.5.0 crate from crates.io: the Khronos glTF sample test will SKIP" >&2
  fi
  rm -rf "$scena_tmp"
fi
export PROBEGI_SCENA_DIR
# wgpu's Vulkan loader wants a runtime dir; give it one instead of a warning per device.
if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -d "${XDG_RUNTIME_DIR}" ]; then
  XDG_RUNTIME_DIR=$(mktemp -d)
  export XDG_RUNTIME_DIR
fi

# A whole-workspace build from scratch: incremental state costs time to write and
# splits crates into 256 codegen units, which keeps hot code from inlining.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"

cargo fmt --all -- --check
# Lints and tests in one build. `cargo clippy` is rustc with clippy's lints
# (clippy-driver as the workspace's rustc wrapper, its arguments in CLIPPY_ARGS).
# Building the tests through it lints what `cargo clippy --all-targets` would
# (library, binaries, examples and tests; the crates have no benches) and
# compiles the workspace once instead of twice. Dependencies are not wrapped.
CLIPPY_DRIVER="$(rustc --print sysroot)/bin/clippy-driver"
[ -x "$CLIPPY_DRIVER" ] || CLIPPY_DRIVER="$(command -v clippy-driver || true)"
if [ ! -x "$CLIPPY_DRIVER" ]; then
  echo "error: clippy-driver not found (rustup component add clippy)" >&2
  exit 1
fi
RUSTC_WORKSPACE_WRAPPER="$CLIPPY_DRIVER" CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" \
  cargo test --workspace --locked

# The Bevy plugin (crates/probegi-bevy): a workspace of its own on Bevy 0.20's
# toolchain (rust-version 1.97.1, crates/probegi-bevy/README.md says why). The
# newest toolchain present builds it: stable once it is 1.97.1 or newer, else
# an installed nightly of 1.97 with --ignore-rust-version. Formatting, lints
# with warnings denied and its tests, as above, with the `window` feature (one
# build: the examples in a window too, which a test runs under Xvfb).
# shellcheck source=scripts/bevy-toolchain.sh
source scripts/bevy-toolchain.sh
if [ -z "$bevy_toolchain" ]; then
  echo "warning: no Rust 1.97.1 (stable) or 1.97 nightly: the Bevy plugin's tests will SKIP (rustup toolchain install nightly)" >&2
else
  echo "probegi-bevy: building with $(rustc "+$bevy_toolchain" --version) ($bevy_toolchain${bevy_flags[*]:+, ${bevy_flags[*]}})" >&2
  (
    cd crates/probegi-bevy
    cargo "+$bevy_toolchain" fmt -- --check
    BEVY_CLIPPY="$(rustc "+$bevy_toolchain" --print sysroot)/bin/clippy-driver"
    RUSTUP_TOOLCHAIN="$bevy_toolchain" RUSTC_WORKSPACE_WRAPPER="$BEVY_CLIPPY" \
      CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" \
      cargo "+$bevy_toolchain" test --locked --features window "${bevy_flags[@]}"
  )
fi
