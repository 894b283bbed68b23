#!/usr/bin/env bash
# Bytes a browser fetches before the viewer's first frame: publishes PACKAGE with the
# viewer bundle (built here), serves it on 127.0.0.1 with range requests, opens it in headless
# Chromium (SwiftShader WebGPU, as the test suite does) at 320x240 and prints a row of the table in
# docs/web.md: package bytes, bytes fetched before the first frame, requests, the site's other
# bytes (HTML, JS, wasm) and the time to the first frame on the software adapter.
# Usage: scripts/bench-web.sh PACKAGE
set -euo pipefail
cd "$(dirname "$0")/.."
package=$(realpath "$1")
./scripts/build-web.sh > /dev/null
GROTTO_WEB_BENCH_PACKAGE="$package" cargo test --release --locked -p grotto-tests --test browser \
    -- --ignored --nocapture bytes_before_the_first_frame 2>&1 | grep '^|'
