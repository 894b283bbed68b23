#!/usr/bin/env bash
# Time to first frame under a GPU memory budget: a synthetic cave of POINTS points
# (LAS scans), built into one package (tiles of at most TILE_M metres when TILE_M is set, else the
# build's default), rendered once from its `entrance` camera with --gpu-memory BUDGET (and
# --point-budget POINT_BUDGET when given), 160x120, fast preset. Prints one row of the table in
# docs/benchmarks.md "Opening a package and time to first frame": tiles full / coarse / far,
# leaves, surfels, load_s (open, choose and read the tiles), settle_s and the command's wall time.
# Scans and package (and the build's --json summary beside it) are kept in OUT and reused.
# Usage: scripts/bench-first-frame.sh [OUT_DIR] [POINTS] [BUDGET] [POINT_BUDGET]
#        (default: out/first-frame, 1000000, 64M, no point budget)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/first-frame}
points=${2:-1000000}
budget=${3:-64M}
point_budget=${4:-}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
[ -f "$out/scans-$points/manifest.toml" ] || target/release/grotto-pack synth --out "$out/scans-$points" \
    --points "$points" --formats las
tiles=()
[ -n "${TILE_M:-}" ] && tiles=(--max-tile-m "$TILE_M")
pkg="$out/cave-$points-t${TILE_M:-default}.grotto"
[ -f "$pkg" ] || target/release/grotto-pack build "$out/scans-$points/manifest.toml" -o "$pkg" \
    "${tiles[@]}" --memory-budget 1G --clean --json > "${pkg%.grotto}-build.json"
limits=(--gpu-memory "$budget")
[ -n "$point_budget" ] && limits+=(--point-budget "$point_budget")
start=$(date +%s.%N)
target/release/grotto render "$pkg" --camera entrance --size 160x120 --quality fast "${limits[@]}" \
    -o "$out/first.png" --json > "$out/first-frame.json"
end=$(date +%s.%N)
python3 - "$out/first-frame.json" "$pkg" "$start" "$end" <<'PY'
import json, os, sys
r = json.load(open(sys.argv[1]))
f = r["frames"][0]
wall = float(sys.argv[4]) - float(sys.argv[3])
print(f"| {os.path.basename(sys.argv[2])} | {r['tiles']} tiles | {f['full_tiles']} / {f['coarse_tiles']} / "
      f"{f['far_tiles']} | {r['leaves']:,} | {r['surfels']:,} | {r['load_s']:.3f} | {r['settle_s']:.1f} | {wall:.1f} s |")
PY
