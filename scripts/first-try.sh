#!/usr/bin/env bash
# A new user's first try on every scan file in ../shared/data: `grotto-pack build FILE` and
# `grotto render PACKAGE` with default options (only the image size is set). Writes OUT/NAME.png
# for every file, a markdown table of what each try gave to OUT/first-try.md, and copies the
# images docs/first-try.md shows to docs/images/first-try/ when run with --docs.
# Usage: scripts/first-try.sh [--docs] [OUT_DIR]   (default out/first-try; needs python3)
set -euo pipefail
cd "$(dirname "$0")/.."
docs=0
if [ "${1:-}" = "--docs" ]; then docs=1; shift; fi
out=${1:-out/first-try}
data=${GROTTO_SHARED_DATA:-../shared/data}
size=${SIZE:-320x240}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
bin=target/release
table="$out/first-try.md"
echo "| file | points | leaf m | tiles | view | covered | black | seconds | warnings |" > "$table"
echo "|---|---:|---:|---:|---|---:|---:|---:|---|" >> "$table"
find "$data/las" "$data/e57" "$data/ply" -type f \( -iname '*.las' -o -iname '*.laz' -o -iname '*.ply' -o -iname '*.e57' \) | sort |
while read -r f; do
    name=$(basename "$f")
    start=$(date +%s.%N)
    rm -rf "$out/$name.grotto" "$out/$name.grotto.work"
    if ! "$bin/grotto-pack" build "$f" -o "$out/$name.grotto" --json >"$out/$name.build.json" 2>"$out/$name.err"; then
        echo "| $name | | | | unreadable: $(tail -1 "$out/$name.err" | sed 's/|/\\|/g') | | | | |" >> "$table"
        continue
    fi
    if ! "$bin/grotto" render "$out/$name.grotto" --size "$size" -o "$out/$name.png" --json >"$out/$name.render.json" 2>"$out/$name.err"; then
        echo "| $name | 0 | | | $(tail -1 "$out/$name.err" | sed 's/|/\\|/g') | | | | |" >> "$table"
        continue
    fi
    seconds=$(echo "$(date +%s.%N) - $start" | bc)
    python3 - "$name" "$seconds" "$out/$name" <<'PY' >> "$table"
import json, sys
name, seconds, base = sys.argv[1], float(sys.argv[2]), sys.argv[3]
b = json.load(open(base + ".build.json"))
r = json.load(open(base + ".render.json"))
px = r["width"] * r["height"]
covered = px - r["uncovered_pixels"]
black = r["black_pixels"] / max(covered, 1)
view = next((n.split(";")[1].split("(")[0].strip() for n in r["notes"] if n.startswith("camera:")), "package camera")
warn = "; ".join(w.split(":")[0] for w in r["warnings"])
print(f"| {name} | {b['points']} | {b.get('leaf_m', '')} | {r['tiles']} | {view} | {100 * covered / px:.0f}% | {100 * black:.0f}% | {seconds:.1f} | {warn} |")
PY
done
echo "wrote $table"
if [ "$docs" = 1 ]; then
    mkdir -p docs/images/first-try
    for name in pdal_autzen_trim.laz e57rs_bunnyDouble.e57 bun_zipper.ply e57rs_tinyCartesianFloatRgb.e57 \
        laspy_simple1_4.las lazrs_point-color.las pdal_A_B.e57 1.2_3.las laspy_simple1_3.las; do
        cp "$out/$name.png" "docs/images/first-try/$name.png"
    done
    echo "copied the docs' images to docs/images/first-try/"
fi
