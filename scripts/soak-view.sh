#!/usr/bin/env bash
# Memory soak of the viewer: `grotto view PACKAGE` under Xvfb, flown by a script for
# MINUTES (default 30) in a loop (camera switch, forward, turn, forward, turn back, backward,
# rest), with its resident set (VmRSS) and its data segment (VmData: heap and anonymous maps,
# where a software adapter's GPU memory lives too) sampled every 10 s into OUT/memory.csv.
# Prints a summary: the largest figures during the first third of the run (the first passes over
# the cave: a loop alternates between the package's first two cameras) and during the last
# third, and the growth between them; a viewer that keeps nothing it does not need shows none. A benchmark, not a CI test (it runs for half an hour).
# Extra arguments go to grotto view (e.g. --gpu-memory 256M, so that tiles stream).
# Usage: scripts/soak-view.sh PACKAGE [OUT_DIR] [MINUTES] [SIZE] [view args...]
#        (default: out/soak, 30, 640x480)
set -euo pipefail
cd "$(dirname "$0")/.."
pkg=$1
out=${2:-out/soak}
minutes=${3:-30}
size=${4:-640x480}
shift $(($# < 4 ? $# : 4))
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
for tool in xvfb-run xdotool; do
    command -v $tool >/dev/null || { echo "needs $tool (apt-get install xvfb xdotool)"; exit 1; }
done
[ -n "${GROTTO_BIN:-}" ] || cargo build --release --locked -p grotto-runtime
bin=${GROTTO_BIN:-target/release/grotto}
w=${size%x*}
h=${size#*x}
xvfb-run -a -s "-screen 0 $((w + 16))x$((h + 16))x24" bash -c '
    bin=$0 pkg=$1 size=$2 out=$3 minutes=$4; shift 4
    "$bin" view "$pkg" --size "$size" --json "$@" > "$out/view.json" 2> "$out/view.err" & pid=$!
    wid=$(timeout 300 xdotool search --sync --name "grotto view")
    for i in $(seq 100); do
        xdotool windowfocus "$wid" 2>/dev/null
        [ "$(xdotool getwindowfocus 2>/dev/null)" = "$wid" ] && break
        sleep 0.2
    done
    start=$(date +%s)
    echo "t_s,loop,rss_mib,data_mib" > "$out/memory.csv"
    (   # The sampler: every 10 s while the viewer lives.
        while kill -0 $pid 2>/dev/null; do
            t=$(( $(date +%s) - start ))
            rss=$(awk "/^VmRSS/ {print \$2}" /proc/$pid/status 2>/dev/null || echo 0)
            data=$(awk "/^VmData/ {print \$2}" /proc/$pid/status 2>/dev/null || echo 0)
            echo "$t,$(cat "$out/loop" 2>/dev/null || echo 0),$((rss / 1024)),$((data / 1024))" >> "$out/memory.csv"
            sleep 10
        done
    ) &
    drag() {  # turn by dragging $1 pixels sideways
        xdotool mousemove $((${size%x*} / 2)) $((${size#*x} / 2)) mousedown 1
        for s in $(seq 10); do xdotool mousemove_relative -- $(($1 / 10)) 0; sleep 0.05; done
        xdotool mouseup 1
    }
    loop=0
    while [ $(( $(date +%s) - start )) -lt $((minutes * 60)) ]; do
        loop=$((loop + 1)); echo $loop > "$out/loop"
        xdotool windowfocus "$wid" 2>/dev/null || true
        xdotool key Tab
        xdotool keydown w sleep 15 keyup w
        drag 300
        xdotool keydown w sleep 10 keyup w
        drag -600
        xdotool keydown s sleep 10 keyup s
        sleep 10
    done
    # Esc until the viewer has gone (a frame at rest can be long on a software adapter, and
    # without a window manager the focus has to be given back by hand).
    while kill -0 $pid 2>/dev/null; do
        xdotool windowfocus "$wid" 2>/dev/null || true
        xdotool key Escape 2>/dev/null || true
        sleep 5
    done
    wait $pid || true
' "$bin" "$pkg" "$size" "$out" "$minutes" "$@"
python3 - "$out/memory.csv" <<'EOF'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1])) if int(r["rss_mib"]) > 0]
if not rows:
    sys.exit("no samples")
end = int(rows[-1]["t_s"])
first = [r for r in rows if int(r["t_s"]) <= end // 3]
last = [r for r in rows if int(r["t_s"]) >= end * 2 // 3]
for key in ("rss_mib", "data_mib"):
    a = max(int(r[key]) for r in first)
    b = max(int(r[key]) for r in last)
    print(f"{key}: first third max {a} MiB, last third max {b} MiB, growth {b - a:+d} MiB "
          f"({len(rows)} samples over {end} s, {rows[-1]['loop']} loops)")
EOF
