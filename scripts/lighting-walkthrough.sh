#!/usr/bin/env bash
# The pictures of docs/lighting.md: the demo cave's chamber as its package
# lights it, then with docs/examples/show-lighting.toml (a spot on the column, an IES downlight),
# and that lighting in the lux view. Needs out/demo.grotto (scripts/demo.sh).
# Usage: scripts/lighting-walkthrough.sh [PACKAGE]
set -euo pipefail
cd "$(dirname "$0")/.."
package=${1:-out/demo.grotto}
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-runtime
common=(--camera chamber --size 640x480 --exposure 12)
target/release/grotto render "$package" "${common[@]}" --out docs/images/lighting-before.png
target/release/grotto render "$package" "${common[@]}" --lights docs/examples/show-lighting.toml \
    --out docs/images/lighting-after.png
target/release/grotto render "$package" "${common[@]}" --lights docs/examples/show-lighting.toml \
    --view lux --out docs/images/lighting-lux.png
ls -l docs/images/lighting-*.png
