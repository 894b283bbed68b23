#!/usr/bin/env bash
# Builds the browser viewer (the web crate, wasm32 on WebGPU) into target/web, where
# `grotto publish` finds it: index.html, grotto_web.js (wasm-bindgen's glue) and
# grotto_web_bg.wasm. Installs the wasm32 target and the wasm-bindgen CLI of the version
# Cargo.lock pins where missing (the CLI must match the crate; built unoptimised, about 2 minutes
# once).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/web}
rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown \
    || rustup target add wasm32-unknown-unknown
want=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/"/, "", $3); print $3; exit }' Cargo.lock)
have=$(wasm-bindgen --version 2>/dev/null | awk '{ print $2 }' || true)
if [ "$have" != "$want" ]; then
    echo "installing wasm-bindgen-cli $want (have: ${have:-none})"
    # --locked first; the crate's own lock file can name versions a registry mirror lacks.
    # --debug: built in 2 min 18 s instead of 4 min 48 s here, and it writes the same files to the
    # byte (cmp'd) in 3.4 s; it runs once a build.
    cargo install wasm-bindgen-cli --version "$want" --locked --debug \
        || cargo install wasm-bindgen-cli --version "$want" --debug
fi
cargo build --profile web-release -p grotto-web --target wasm32-unknown-unknown --locked
mkdir -p "$out"
wasm-bindgen --target web --no-typescript --out-dir "$out" target/wasm32-unknown-unknown/web-release/grotto_web.wasm
cp web/static/index.html "$out/"
ls -l "$out"
