#!/usr/bin/env bash
# The screenshots of docs/web.md (points of interest, a tour stop, a phone screen): publishes
# PACKAGE (default out/demo.grotto, whose manifest has points of interest and a tour), opens it in
# headless Chromium on SwiftShader and writes docs/images/web-*.png.
# Usage: scripts/web-screenshots.sh [PACKAGE]
set -euo pipefail
cd "$(dirname "$0")/.."
package=$(realpath "${1:-out/demo.grotto}")
./scripts/build-web.sh > /dev/null
GROTTO_WEB_BENCH_PACKAGE="$package" GROTTO_WEB_DOCS_OUT="$PWD/docs/images" \
    cargo test --release --locked -p grotto-tests --test browser \
    -- --ignored --nocapture screenshots_for_the_docs
ls -l docs/images/web-*.png
