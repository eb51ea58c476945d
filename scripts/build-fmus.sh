#!/usr/bin/env bash
# Build every FMU of the workspace in release mode and write it as target/fmu/<modelIdentifier>.fmu.
# The FMUs are built (and packed) by `twin`'s build script, which embeds them in the binary
# (orchestrator/build.rs: a nested `cargo build --release` of the FMU crates with `exports` in
# target/embedded-fmus); `twin export-fmus` writes them out. One build serves `twin`, the Python
# package (maturin builds in the same target directory) and these files.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

# The demo (SHEAR_TWIN_PROGRESS=1) shows cargo's progress; the tests keep it quiet.
quiet=(--quiet)
[ -n "${SHEAR_TWIN_PROGRESS:-}" ] && quiet=()
cargo build --release "${quiet[@]}" -p orchestrator --bin twin
"$target_dir/release/twin" export-fmus --out "$target_dir/fmu" >/dev/null
