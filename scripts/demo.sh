#!/usr/bin/env bash
# The main job on the built-in demo scene: synthesise a cave (LAS, LAZ, PLY and E57 scans plus a
# manifest) into OUT/demo-scans, build OUT/demo.grotto from it, verify it, then render its two
# cameras with global illumination to OUT/chamber.png and OUT/entrance.png.
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/)
# Rendering runs on the GPU when there is one; otherwise on Mesa's software Vulkan driver (installed
# here if missing), where the demo takes about five minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out}
if ! dpkg-query -W -f='${Status}' mesa-vulkan-drivers 2>/dev/null | grep -q "install ok installed"; then
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends mesa-vulkan-drivers libvulkan1
fi
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
cargo build --release --locked -p grotto-preprocess -p grotto-runtime
target/release/grotto-pack demo --out "$out"
target/release/grotto inspect "$out/demo.grotto"
target/release/grotto verify "$out/demo.grotto"
for camera in chamber entrance; do
    target/release/grotto render "$out/demo.grotto" --camera "$camera" --size 640x480 \
        --out "$out/$camera.png" --explain
done
