#!/usr/bin/env bash
# The main job on the built-in demo scene: build the demo package, describe it, verify it.
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out}
mkdir -p "$out"
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
target/release/grotto-pack demo -o "$out/demo.grotto"
target/release/grotto inspect "$out/demo.grotto"
target/release/grotto verify "$out/demo.grotto"
