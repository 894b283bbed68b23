#!/usr/bin/env bash
# Every GPU figure the project states, in one go, for a machine with a GPU: the demo cave per
# preset, the cave paper's configurations, a 10^7-point survey with every tile held and a
# 10^8-point survey streamed under a GPU memory budget (`cargo xtask bench gpu`; what each part
# measures: `cargo xtask bench list`, xtask/src/suites/gpu.rs). Tables go to OUT/gpu-*/tables.md
# as each part ends, raw reports to OUT/gpu-*/json/, and the rows of docs/figures.md are replaced.
# Usage: scripts/bench-gpu.sh [OUT_DIR]   (default: out/gpu)
# Environment: GROTTO_BIN  a folder with grotto and grotto-pack already built (else cargo builds them);
#              REPS        repetitions of each bench (default 5).
set -euo pipefail
cd "$(dirname "$0")/.."
exec cargo xtask bench gpu --out "${1:-out/gpu}" --reps "${REPS:-5}"
