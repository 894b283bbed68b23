#!/usr/bin/env bash
# The viewer's frame loop at work: opens PACKAGE in `grotto view` under Xvfb in a SIZE
# window (drawn at --render-scale, default 0.5), lets the camera rest for WAIT_S seconds (default
# 20: the light converges meanwhile), flies forward (W held through XTEST, as a person's key would
# be) for MOVE_S seconds, then lets it rest until the light has converged; the viewer then writes
# OUT/view.png (P) and exits (Esc). Prints the viewer's summary (frame times while moving and at
# rest, frames and seconds the light took to converge at rest) and grabs the X screen (panel
# included) to OUT/screen.png; `--json` among the view args gives the whole frame log instead.
# Extra arguments go to grotto view (e.g. --quality high, --frame-budget-ms 16, --render-scale 0.5).
# Usage: scripts/bench-view.sh PACKAGE [OUT_DIR] [SIZE] [MOVE_S] [view args...]
#        (default: out/view, 640x480, 5)
set -euo pipefail
cd "$(dirname "$0")/.."
pkg=$1
out=${2:-out/view}
size=${3:-640x480}
move_s=${4:-5}
shift $(($# < 4 ? $# : 4))
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
for tool in xvfb-run xdotool import; do
    command -v $tool >/dev/null || { echo "needs $tool (apt-get install xvfb xdotool imagemagick)"; exit 1; }
done
cargo build --release --locked -p grotto-runtime
w=${size%x*}
h=${size#*x}
xvfb-run -a -s "-screen 0 $((w + 16))x$((h + 16))x24" bash -c '
    target/release/grotto view "$0" --size "$1" --screenshot "$2/view.png" \
        "${@:4}" > "$2/view.txt" 2> "$2/view.err" & pid=$!
    wid=$(timeout 300 xdotool search --sync --name "grotto view")
    # No window manager: focus by hand, retried until the server reports it.
    for i in $(seq 100); do
        xdotool windowfocus "$wid" 2>/dev/null
        [ "$(xdotool getwindowfocus 2>/dev/null)" = "$wid" ] && break
        sleep 0.2
    done
    sleep "${WAIT_S:-20}"
    import -window root "$2/screen.png" || true
    # P: a screenshot once the light has converged at rest; Esc: quit after it.
    xdotool mousemove 600 400 keydown w sleep "$3" keyup w key p key Escape
    wait $pid
' "$pkg" "$size" "$out" "$move_s" "$@"
cat "$out/view.txt"
