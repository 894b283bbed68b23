#!/usr/bin/env bash
# The main job on the built-in demo scene: synthesise a cave (LAS, LAZ, PLY and E57 scans plus a
# manifest) into OUT/demo-scans, build OUT/demo.grotto from it, then describe and verify the package.
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
target/release/grotto-pack demo --out "$out"
target/release/grotto inspect "$out/demo.grotto"
target/release/grotto verify "$out/demo.grotto"
