#!/usr/bin/env bash
# Frame times of the browser viewer while moving: publishes PACKAGE with the viewer
# bundle (built here; GROTTO_WEB_BUNDLE names another, e.g. an older build), serves it, opens it
# in headless Chromium on SwiftShader at SIZE (default 800x600), holds W for MOVE_S seconds
# (default 60: on SwiftShader the first moving frame and a bounce slice before it take 10-40 s) after the first frames and prints a row: frames, median, p95 and worst
# milliseconds between frames, and what the frame-time target traded. QUERY adds to the page's
# query string (e.g. "&target_fps=0": no frame-time target).
# Usage: scripts/bench-web-frames.sh PACKAGE [SIZE] [MOVE_S] [QUERY]
set -euo pipefail
cd "$(dirname "$0")/.."
package=$(realpath "$1")
[ -n "${GROTTO_WEB_BUNDLE:-}" ] || ./scripts/build-web.sh > /dev/null
GROTTO_WEB_BENCH_PACKAGE="$package" GROTTO_WEB_BENCH_SIZE="${2:-800x600}" GROTTO_WEB_BENCH_MOVE_S="${3:-60}" \
    GROTTO_WEB_BENCH_QUERY="${4:-}" cargo test --release --locked -p grotto-tests --test browser \
    -- --ignored --nocapture frame_times_while_moving 2>&1 | grep '^|'
