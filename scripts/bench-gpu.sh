#!/usr/bin/env bash
# Every GPU figure the project states, in one go, for a machine with a GPU: per-pass
# times of the demo cave per preset at 640x480 and 1920x1080; the cave paper's 1.4 M-point
# configurations (SVO depth 7 and 8) at 800x600 and 1600x900; a 10^7-point package at 1920x1080;
# and a 10^8-point package streamed along its entrance -> chamber path at 1920x1080 under a GPU
# memory budget, with per-frame times (median, p99, worst) and stalls (frames over 50 ms), as it
# is and with --point-budget 1M and 5M, settled before each frame and as a viewer runs it (a
# bounce a frame, shadow faces within 8 ms a frame); and, for the demo cave and the 10^7 package, the splat
# passes' work counts (draws, surfels, vertex and fragment invocations) drawn whole
# (--cull tiles --no-splat-lod) and as the viewers draw them; and the G-buffer with the front-most disc against
# blended splats. Prints one markdown table per part (also written to
# OUT/tables.md, part by part, so a run cut short keeps what it measured) and keeps the raw JSON
# reports in OUT/json/.
#
# Usage: scripts/bench-gpu.sh [OUT_DIR]   (default: out/gpu)
# Environment: GROTTO_BIN   a folder with grotto and grotto-pack already built (else cargo builds
#                           them here);
#              WORK         where the scans and packages go (default OUT/work; about 12 GB at 10^8);
#              PARTS        which parts run (default "demo paper 1e7 1e8");
#              FLY_FRAMES   frames of each fly-through (default 30);
#              FLY_GPU_MEMORY  the fly-throughs' --gpu-memory (default 512M, so tiles stream);
#              REPS         repetitions of each bench (default 5).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/gpu}
work=${WORK:-$out/work}
parts=${PARTS:-demo paper 1e7 1e8}
frames=${FLY_FRAMES:-30}
fly_memory=${FLY_GPU_MEMORY:-512M}
reps=${REPS:-5}
mkdir -p "$out/json" "$work"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
if [ -n "${GROTTO_BIN:-}" ]; then
    bin=$GROTTO_BIN
else
    cargo build --release --locked -p grotto-preprocess -p grotto-runtime
    bin=target/release
fi
tables=$out/tables.md
: > "$tables"
log() { echo "[$(date +%T)] $*" >&2; }

# A markdown table of per-pass medians from `grotto bench --json` reports.
bench_table() {
    python3 - "$@" <<'PY'
import json, sys
passes = ["shadow", "inject", "mip", "propagate", "gbuffer", "shade", "resolve"]
title, files = sys.argv[1], sys.argv[2:]
first = json.load(open(files[0]))
splats = "pulled" if first.get("splats_pulled") else "instanced"
print(f"\n{title} ({first['device']}, timestamps: {first['timestamps']}, splats {splats}, median of {first['repetitions']}, ms)\n")
print("| package | preset | size | leaves | surfels | " + " | ".join(passes) + " | frame (gbuffer + shade) |")
print("|---|---|---|---:|---:|" + "---:|" * (len(passes) + 1))
for f in files:
    r = json.load(open(f))
    m = r["median_ms"]
    name, preset = f.rsplit("/", 1)[-1].split("__")[:2]
    print(f"| {name} | {preset} | {r['width']}x{r['height']} | {r['leaves']:,} | "
          f"{r['surfels']:,} | " + " | ".join(f"{m.get(p, 0):.2f}" for p in passes)
          + f" | {m.get('gbuffer', 0) + m.get('shade', 0):.2f} |")
PY
}

# A markdown table of per-pass work counts and times from `grotto bench --json` reports
# (draws, surfels drawn, vertex and fragment shader invocations from pipeline statistics queries).
work_table() {
    python3 - "$@" <<'PY'
import json, sys
title, files = sys.argv[1], sys.argv[2:]
first = json.load(open(files[0]))
print(f"\n{title} ({first['device']}, median of {first['repetitions']})\n")
print("| package | draws as | size | pass | ms | draws | surfels drawn | vertices | fragments | submits | bytes written |")
print("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
n = lambda v: "-" if v is None else f"{v:,}"
for f in files:
    r = json.load(open(f))
    name, how = f.rsplit("/", 1)[-1].removesuffix(".json").split("__")[:2]
    for p in ("shadow", "gbuffer"):
        w = r["work"].get(p, {})
        print(f"| {name} | {how} | {r['width']}x{r['height']} | {p} | {r['median_ms'].get(p, 0):.2f} | "
              f"{n(w.get('draws'))} | {n(w.get('surfels'))} | {n(w.get('vertex_invocations'))} | "
              f"{n(w.get('fragment_invocations'))} | {r['submits']} | {r['upload_bytes']:,} |")
PY
}

# The same package drawn whole (whole tiles, every surfel) and as the viewers draw it.
work_pair() {
    local name=$1 pkg=$2 size=$3
    "$bin/grotto" bench "$pkg" --camera chamber --size "$size" --reps "$reps" --bounces 0 \
        --cull tiles --no-splat-lod --json > "$out/json/work-$name__tiles__$size.json"
    "$bin/grotto" bench "$pkg" --camera chamber --size "$size" --reps "$reps" --bounces 0 \
        --json > "$out/json/work-$name__chunks+lod__$size.json"
    echo "$out/json/work-$name__tiles__$size.json" "$out/json/work-$name__chunks+lod__$size.json"
}

# One line of per-frame statistics from a `grotto render --path --json` report.
fly_row() {
    python3 - "$@" <<'PY'
import json, sys
label, path = sys.argv[1], sys.argv[2]
r = json.load(open(path))
f = r["frames"]
ms = sorted(x["frame_ms"] for x in f[1:]) or [f[0]["frame_ms"]]
pick = lambda q: ms[min(len(ms) - 1, int(q * len(ms)))]
stalls = sum(1 for x in ms if x > 50.0)
surfels = max(x["surfels"] for x in f)
uploaded = sum((x.get("update") or {}).get("upload_bytes", 0) for x in f) / 2**20
faces = sum(x["shadow_faces"] for x in f)
most = max(x["shadow_faces"] for x in f[1:]) if len(f) > 1 else f[0]["shadow_faces"]
print(f"| {label} | {len(f)} | {f[0]['frame_ms']:.1f} | {pick(0.5):.1f} | {pick(0.99):.1f} | {ms[-1]:.1f} | "
      f"{stalls} | {surfels:,} | {uploaded:.0f} | {faces} | {most} | {r['settle_s']:.2f} |")
PY
}

if [[ " $parts " == *" demo "* ]]; then
    log "demo cave"
    [ -f "$work/demo/demo.grotto" ] || "$bin/grotto-pack" demo --out "$work/demo" > /dev/null
    files=()
    for q in fast balanced high; do
        for size in 640x480 1920x1080; do
            f=$out/json/demo__${q}__$size.json
            "$bin/grotto" bench "$work/demo/demo.grotto" --camera chamber --size "$size" --quality "$q" \
                --reps "$reps" --json > "$f"
            files+=("$f")
        done
    done
    bench_table "The demo cave (grotto-pack demo), chamber camera" "${files[@]}" | tee -a "$tables"
    # shellcheck disable=SC2046
    work_table "The demo cave's splat passes: whole tiles and every surfel against chunks and level of detail" \
        $(work_pair demo "$work/demo/demo.grotto" 1920x1080) | tee -a "$tables"
    # The front-most disc against blended splats (the default), and the resolve
    # pass a still frame's sample adds (anti-aliasing at rest), one run each.
    files=()
    for mode in front blend blend-aa; do
        f=$out/json/demo__splats-$mode__1920x1080.json
        extra=()
        [ "$mode" = front ] && extra=(--no-splat-blend)
        [ "$mode" = blend-aa ] && extra=(--samples 8)
        "$bin/grotto" bench "$work/demo/demo.grotto" --camera chamber --size 1920x1080 --bounces 0 \
            --reps "$reps" "${extra[@]}" --json > "$f"
        files+=("$f")
    done
    bench_table "The demo cave at 1920x1080: front-most disc against blended splats, and a still frame's resolve" "${files[@]}" | tee -a "$tables"
fi

if [[ " $parts " == *" paper "* ]]; then
    log "the cave paper's 1.4 M points"
    [ -f "$work/paper/manifest.toml" ] || "$bin/grotto-pack" synth --out "$work/paper" --points 1400000 \
        --formats las > /dev/null
    files=()
    for depth in 7 8; do
        leaf=$([ "$depth" = 7 ] && echo 0.5 || echo 0.25)
        pkg=$work/cave-d$depth.grotto
        [ -f "$pkg" ] || "$bin/grotto-pack" build "$work/paper/manifest.toml" -o "$pkg" --leaf-m "$leaf" \
            --min-tile-m 64 --max-tile-m 64 --halo-m 1 --clean --json > /dev/null
        for size in 800x600 1600x900; do
            f=$out/json/cave-d$depth-1.4M__balanced__$size.json
            "$bin/grotto" bench "$pkg" --camera chamber --size "$size" --reps "$reps" --json > "$f"
            files+=("$f")
        done
    done
    bench_table "The cave paper's configurations (1.4 M points, 64 m tiles, depth 7 and 8)" "${files[@]}" \
        | tee -a "$tables"
fi

# A synthetic survey of POINTS points built with the defaults (automatic leaf size, 2 GiB budget).
survey() {
    local points=$1
    [ -f "$work/survey-$points/manifest.toml" ] || "$bin/grotto-pack" synth --out "$work/survey-$points" \
        --points "$points" --formats las > /dev/null
    [ -f "$work/survey-$points.grotto" ] || "$bin/grotto-pack" build "$work/survey-$points/manifest.toml" \
        -o "$work/survey-$points.grotto" --work-dir "$work/build-$points" --clean --json \
        > "$out/json/build-$points.json"
}

if [[ " $parts " == *" 1e7 "* ]]; then
    log "10^7 points"
    survey 10000000
    f=$out/json/survey-1e7__balanced__1920x1080.json
    "$bin/grotto" bench "$work/survey-10000000.grotto" --camera chamber --size 1920x1080 --reps "$reps" --json > "$f"
    bench_table "A 10^7-point survey (grotto-pack synth --points 10000000), every tile held" "$f" | tee -a "$tables"
    # shellcheck disable=SC2046
    work_table "The 10^7 survey's splat passes: whole tiles and every surfel against chunks and level of detail" \
        $(work_pair survey-1e7 "$work/survey-10000000.grotto" 1920x1080) | tee -a "$tables"
fi

if [[ " $parts " == *" 1e8 "* ]]; then
    log "10^8 points"
    survey 100000000
    {
        echo
        echo "A 10^8-point survey streamed along entrance -> chamber, $frames frames at 1920x1080, --gpu-memory $fly_memory"
        echo "(frame ms: waiting for tiles, swapping them in, settling light, drawing; frame 0 after the first settle;"
        echo "median, p99 and worst over the frames after it; stalls: frames over 50 ms)"
        echo
        echo "| run | frames | frame 0 ms | median ms | p99 ms | worst ms | stalls | surfels drawn (most) | uploaded MiB | shadow faces drawn | most faces in a frame | first settle s |"
        echo "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    } | tee -a "$tables"
    # Batch rows settle the light before each frame (what `grotto render --path` does for
    # images); viewer rows run as the viewers do: no bounce before a frame whose tiles
    # changed (one a frame after), shadow faces out of date drawn within 8 ms a frame.
    for run in none:batch 5000000:batch 1000000:batch 5000000:viewer 1000000:viewer; do
        budget=${run%%:*}; how=${run##*:}
        label=$([ "$budget" = none ] && echo "no point budget" || echo "--point-budget $budget")
        extra=()
        if [ "$how" = viewer ]; then
            label="$label, viewer-like (--frame-bounces 0 --shadow-ms 8)"
            extra=(--frame-bounces 0 --shadow-ms 8)
        fi
        f=$out/json/fly-1e8__${budget}__$how.json
        log "fly-through, $label"
        "$bin/grotto" render "$work/survey-100000000.grotto" --path entrance,chamber --frames "$frames" \
            --size 1920x1080 --gpu-memory "$fly_memory" \
            $([ "$budget" = none ] || echo --point-budget "$budget") "${extra[@]}" \
            -o "$work/fly-$budget-$how.png" --json > "$f"
        fly_row "$label" "$f" | tee -a "$tables"
    done
fi
log "done: $tables"
