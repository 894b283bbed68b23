#!/usr/bin/env bash
# The test suite. Installs what the tests need on a fresh Debian machine, then runs every test of
# the workspace. Tests that read third-party files expect ../shared/data beside the repository
# (or GROTTO_SHARED_DATA).
set -euo pipefail
cd "$(dirname "$0")/.."
# System packages the tests need are installed here as they are added (the runtime's GPU tests will
# need Mesa's software Vulkan driver). Nothing beyond the Rust toolchain is needed yet.
cargo test --workspace --locked
