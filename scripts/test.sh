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

cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo test --workspace --locked
# The embedding example drives the seam with its own triangles and ray caster.
cargo run -p probegi-cpu --example embed_ddgi --locked
