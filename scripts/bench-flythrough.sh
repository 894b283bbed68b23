#!/usr/bin/env bash
# A fly-through under a GPU memory budget: a synthetic cave of POINTS points cut into
# 4 m tiles (TILE_M, default 4), rendered along its entrance -> chamber path with --gpu-memory
# BUDGET. Prints the per-frame table of docs/benchmarks.md (tile bytes, full, coarse and far
# tiles, tiles loaded and evicted, surfels drawn, bounces, leaves whose light was carried over,
# leaves the frame's bounces propagated, bytes uploaded into the tile pools and whether they were
# repacked, shadow faces drawn, time waiting for the loader, pass times) and writes the raw JSON to
# OUT/flythrough.json. UPLOAD (e.g. 16M) passes --upload-per-frame and adds a deferred column.
# The same command takes the figures on a machine with a GPU.
# Usage: scripts/bench-flythrough.sh [OUT_DIR] [POINTS] [BUDGET] [FRAMES]
#        (default: out/fly, 1000000, 64M, 6)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/fly}
points=${2:-1000000}
budget=${3:-64M}
frames=${4:-6}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
[ -f "$out/scans-$points/manifest.toml" ] || target/release/grotto-pack synth --out "$out/scans-$points" \
    --points "$points" --formats las
pkg="$out/cave-$points-t${TILE_M:-4}.grotto"
[ -f "$pkg" ] || target/release/grotto-pack build "$out/scans-$points/manifest.toml" -o "$pkg" \
    --max-tile-m "${TILE_M:-4}" --clean --json >/dev/null
target/release/grotto render "$pkg" --path entrance,chamber --frames "$frames" --size 160x120 --bounces 2 \
    --gpu-memory "$budget" --exposure 8 ${UPLOAD:+--upload-per-frame "$UPLOAD"} -o "$out/fly.png" --json \
    > "$out/flythrough.json"
python3 - "$out/flythrough.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
res = r.get("residency")
print(f"device: {r['device']}, {r['tiles']} tiles, budget "
      f"{res['budget']['gpu_bytes'] / 2**20:.0f} MiB" if res else "the whole package fits the budget")
passes = ["shadow", "inject", "mip", "propagate", "gbuffer", "shade"]
print(f"tile pools: {r['frames'][0]['pool_bytes'] / 2**20:.1f} MiB")
print("| frame | tile MiB | full | coarse | far | loaded | evicted | surfels drawn | bounces | carried leaves | "
      "propagated leaves | uploaded MiB | repacked | shadow faces | deferred | load wait | "
      + " | ".join(passes) + " (ms) |")
print("|" + "---:|" * (16 + len(passes)))
for f in r["frames"]:
    ms = " | ".join(f"{f['pass_ms'].get(p, 0):.0f}" for p in passes)
    u = f.get("update") or {}
    repacked = "yes" if u.get("repacked") else ("new" if f.get("made_anew") else "")
    print(f"| {f['frame']} | {f['tile_bytes'] / 2**20:.1f} | {f['full_tiles']} | {f['coarse_tiles']} | "
          f"{f['far_tiles']} | {f['loaded']} | {f['evicted']} | {f['surfels']:,} | {f['bounces']} | "
          f"{f['carried_leaves']:,} | {f['propagated_leaves']:,} | {u.get('upload_bytes', 0) / 2**20:.1f} | "
          f"{repacked} | {f['shadow_faces']} of {f['shadow_faces_total']} | {f['deferred']} | "
          f"{f['load_wait_ms']:.0f} | {ms} |")
PY
