#!/usr/bin/env bash
# The test suite. Installs what the tests need on a fresh Debian machine (Mesa's software Vulkan
# driver lavapipe, EGL + llvmpipe for wgpu's GL backend, and Xvfb and xdotool for the window of
# `grotto view`), Chromium with its WebDriver for the browser viewer's test, and Survex (its `cavern`
# compiles the survey tests' .svx files), builds that viewer
# (scripts/build-web.sh, into target/web), then runs every test of the workspace. Tests that read third-party files expect ../shared/data beside the repository (or
# GROTTO_SHARED_DATA) and fail without it; GROTTO_SKIP_SHARED_DATA=1 skips them instead.
set -euo pipefail
cd "$(dirname "$0")/.."
packages=(mesa-vulkan-drivers libvulkan1 libegl1 libegl-mesa0 libgl1-mesa-dri xvfb xauth xdotool chromium chromium-driver survex)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "installing ${missing[*]} (GPU tests run on Mesa's software drivers)"
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# No session bus or display here; wgpu's GL backend only needs a writable runtime dir for EGL.
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
# The browser viewer the browser test publishes (tests/tests/browser/).
./scripts/build-web.sh > /dev/null
# Libraries, binaries and tests: not the examples (measurement tools that no test runs; clippy
# --all-targets checks them in CI), each of which would link the whole dependency tree again.
cargo test --workspace --locked --lib --bins --tests
# The cluster steps on a real scheduler: plan, a build-tile job array and assemble
# on a 3-node Slurm cluster made here in namespaces, one node lost mid-build, against one build
# (the one-node cluster where namespaces cannot be made). Skipped with a message where no scheduler
# can start; a failed job or a different package fails.
GROTTO_PACK=target/debug/grotto-pack GROTTO_SLURM_OPTIONAL=1 ./scripts/test-slurm.sh
