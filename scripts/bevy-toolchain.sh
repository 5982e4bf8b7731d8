# Sourced by scripts/test.sh, bevy-gpu-timing.sh and bevy-sponza-flip.sh: the
# toolchain that builds the Bevy plugin (crates/probegi-bevy; Bevy 0.20
# declares rust-version 1.97.1, the crate's README says why). Sets
# `bevy_toolchain` (stable once it is 1.97.1 or newer, else an installed
# nightly of 1.97, else empty) and `bevy_flags` (--ignore-rust-version for
# that nightly).
rust_version() { rustc "+$1" --version 2>/dev/null | awk '{ print $2 }' | cut -d- -f1; }
at_least() { [ -n "$1" ] && printf '%s\n%s\n' "$2" "$1" | sort -V -C; }
bevy_flags=()
if at_least "$(rust_version stable)" 1.97.1; then
  bevy_toolchain=stable
elif at_least "$(rust_version nightly)" 1.97.0; then
  bevy_toolchain=nightly
  bevy_flags=(--ignore-rust-version)
else
  bevy_toolchain=""
fi
