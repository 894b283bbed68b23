#!/usr/bin/env bash
# The browser viewer's memory over a long visit: publishes PACKAGE with a tour through
# its named cameras, opens it in headless Chromium (SwiftShader WebGPU) and plays the tour round
# and round for MINUTES (default 30), sampling the JS heap, the viewer's wasm memory and the GPU
# bytes every 10 s; prints the samples and the row of docs/web.md ("A long visit").
# Usage: scripts/bench-web-memory.sh PACKAGE [MINUTES]
set -euo pipefail
cd "$(dirname "$0")/.."
package=$(realpath "$1")
./scripts/build-web.sh > /dev/null
GROTTO_WEB_BENCH_PACKAGE="$package" GROTTO_WEB_BENCH_MINUTES="${2:-30}" \
    cargo test --release --locked -p grotto-tests --test browser \
    -- --ignored --nocapture memory_over_a_tour_loop 2>&1 | grep '^|'
