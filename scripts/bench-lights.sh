#!/usr/bin/env bash
# Cost against the number of lights (docs/runtime.md, "Many lights"): the small synthetic cave
# (80k points, 6 passage segments, 0.25 m leaves) relit by a lamp string of N 8 W lamps
# (`grotto bench --lamps N`), N = 1, 16, 64, 256, 1024, with the default shadow-map budget (16
# brightest lamps) and both fallbacks for the rest (SVO shadow cones, unshadowed). Light work only
# (`--bounces 0`): propagation does not depend on the lights. Then 1024 lamps with a higher light
# cutoff (2e-3, 2e-2 W/m^2: shorter ranges, fewer lights per cell). Prints a markdown table and
# writes the raw JSON reports to OUT/lights-*.json.
# Usage: scripts/bench-lights.sh [OUT_DIR] [SIZE]   (default: out/bench-lights, 320x240)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/bench-lights}
size=${2:-320x240}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
if [ ! -f "$out/scans/manifest.toml" ]; then
    target/release/grotto-pack synth --out "$out/scans" --points 80000 --segments 6 --formats las >/dev/null
fi
[ -f "$out/cave.grotto" ] || target/release/grotto-pack build "$out/scans/manifest.toml" -o "$out/cave.grotto" \
    --leaf-m 0.25 --clean --json >/dev/null
for n in 1 16 64 256 1024; do
    for fallback in cone none; do
        target/release/grotto bench "$out/cave.grotto" --camera chamber --size "$size" --reps 3 --bounces 0 \
            --lamps "$n" --shadow-fallback "$fallback" --exposure 8 --json > "$out/lights-$n-$fallback.json"
    done
done
for cutoff in 2e-3 2e-2; do
    target/release/grotto bench "$out/cave.grotto" --camera chamber --size "$size" --reps 3 --bounces 0 \
        --lamps 1024 --light-cutoff "$cutoff" --exposure 8 --json > "$out/lights-1024-cone-cutoff$cutoff.json"
done
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
rows = []
runs = [(n, fb, f"{out}/lights-{n}-{fb}.json") for n in [1, 16, 64, 256, 1024] for fb in ["cone", "none"]]
runs += [(1024, "cone", f"{out}/lights-1024-cone-cutoff{c}.json") for c in ["2e-3", "2e-2"]]
for n, fb, path in runs:
    r = json.load(open(path))
    m = r["median_ms"]
    mean, mx = r["lights_in_range"]
    frame = m.get("gbuffer", 0) + m.get("shade", 0)
    rows.append(f"| {r['lights']} | {r['shadowed_lights']} | {fb} | {r['settings']['light_cutoff_w_m2']:g} | {mean:.1f} / {mx} | "
                f"{m.get('shadow', 0):.1f} | {m.get('inject', 0):.1f} | {m.get('shade', 0):.1f} | {frame:.1f} |")
print(f"device: {r['device']}, timestamps: {r['timestamps']}, {r['leaves']:,} leaves, {r['surfels']:,} surfels, "
      f"{r['width']}x{r['height']}, shadow map {r['settings']['shadow_map_size']}, budget {r['settings']['shadowed_lights']}")
print("| lights | with shadow maps | rest | cutoff (W/m^2) | in range per cell (mean / max) | shadow (ms) | inject (ms) | shade (ms) | frame: gbuffer + shade (ms) |")
print("|---|---|---|---|---|---|---|---|---|")
print("\n".join(rows))
PY
