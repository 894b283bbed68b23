#!/usr/bin/env bash
# grotto's normals against Open3D's and CloudCompare's on the same cloud, in one run
# (table in docs/benchmarks.md). Needs `pip install open3d numpy` and Debian's `cloudcompare`.
#   bench/compare-normals.sh [POINTS] [DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
points=${1:-1000000}
dir=${2:-target/compare-normals}
mkdir -p "$dir"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release -q -p grotto-preprocess --bin grotto-pack
echo "== grotto (2 threads)"
target/release/grotto-pack bench-normals --dir "$dir/scans" --points "$points" --k 16 --threads 2 \
    --export "$dir/cloud.ply" --json
echo "== Open3D (2 threads)"
OMP_NUM_THREADS=2 python3 bench/open3d_normals.py "$dir/cloud.ply" --k 16
echo "== CloudCompare"
python3 bench/cloudcompare_normals.py "$dir/cloud.ply" --k 16
