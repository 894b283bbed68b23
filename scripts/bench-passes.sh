#!/usr/bin/env bash
# Per-pass GPU times for the cave paper's configurations: a 1.4M-point synthetic cave built with
# 64 m tiles at SVO depth 7 (0.5 m leaves) and 8 (0.25 m leaves), rendered at 800x600 and
# 1600x900 with its 14 shadowed lamps, 6 cones. Prints a markdown table (docs/runtime.md) and
# writes the raw JSON reports to OUT/bench-*.json.
# Usage: scripts/bench-passes.sh [OUT_DIR] [REPS]   (default: out/bench, 3)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/bench}
reps=${2:-3}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
if [ ! -f "$out/scans/manifest.toml" ]; then
    target/release/grotto-pack synth --out "$out/scans" --points 1400000 --formats las
fi
for depth in 7 8; do
    leaf=$([ "$depth" = 7 ] && echo 0.5 || echo 0.25)
    [ -f "$out/cave-d$depth.grotto" ] || target/release/grotto-pack build "$out/scans/manifest.toml" \
        -o "$out/cave-d$depth.grotto" --leaf-m "$leaf" --min-tile-m 64 --max-tile-m 64 --halo-m 1 --clean --json >/dev/null
    for size in 800x600 1600x900; do
        target/release/grotto bench "$out/cave-d$depth.grotto" --camera chamber --size "$size" --reps "$reps" --json \
            > "$out/bench-d$depth-$size.json"
    done
done
python3 - "$out" <<'PY'
import json, glob, sys
rows = []
for f in sorted(glob.glob(sys.argv[1] + "/bench-d*.json")):
    r = json.load(open(f))
    m = r["median_ms"]
    total = sum(m.get(p, 0) for p in ["shadow", "inject", "mip", "propagate", "gbuffer", "shade"])
    rows.append(f"| {r['max_depth']} | {r['width']}x{r['height']} | {r['leaves']:,} | {r['surfels']:,} | "
                + " | ".join(f"{m.get(p, 0):.1f}" for p in ["shadow", "inject", "mip", "propagate", "gbuffer", "shade"])
                + f" | {total:.1f} |")
print(f"device: {r['device']}, timestamps: {r['timestamps']}, lights: {r['lights']}, cones: {r['settings']['cones']}, "
      f"shadow map {r['settings']['shadow_map_size']}, median of {r['repetitions']}")
print("| depth | size | leaves | surfels | shadow | inject | mip | propagate | gbuffer | shade | all (ms) |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
print("\n".join(rows))
PY
