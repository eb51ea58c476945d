#!/usr/bin/env bash
# Build every FMU of the workspace in release mode and write it as target/fmu/<modelIdentifier>.fmu.
# The FMU crates' shared libraries (with `exports`, the fmi2* C names) are built first, in the
# target directory with the dependency features `twin` uses, and copied
# with their dep-info to target/fmu-libs; `twin`'s build script packs them and embeds them in
# the binary (orchestrator/build.rs; without fresh libraries there, as in `cargo install`, it
# builds them itself in a target directory of its own, compiling the dependencies again).
# `twin export-fmus` writes them out. One build serves `twin`, the Python package (maturin
# builds in the same target directory) and these files.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

# The demo (SHEAR_TWIN_PROGRESS=1) shows cargo's progress; the tests keep it quiet.
quiet=(--quiet)
[ -n "${SHEAR_TWIN_PROGRESS:-}" ] && quiet=()
# One `cargo rustc` per FMU: the crates are rlibs (what `twin` links), built here as the
# cdylib of the FMU with `exports`; each depends on workspace-hack, so the dependencies they
# share with `twin` are compiled once, with `twin`'s features.
fmus=(fmu-shear fmu-gp-corrector fmu-lqr fmu-substructure)
for krate in "${fmus[@]}"; do
  cargo rustc --release "${quiet[@]}" -p "$krate" --lib --crate-type cdylib --features exports
done
mkdir -p "$target_dir/fmu-libs"
for krate in "${fmus[@]}"; do
  stem=lib${krate//-/_}
  for file in "$stem.so" "$stem.d"; do
    # Copied when newer, with its time: twin's build script compares it with the sources.
    cp -p -u "$target_dir/release/$file" "$target_dir/fmu-libs/$file"
  done
done
cargo build --release "${quiet[@]}" -p orchestrator --bin twin
"$target_dir/release/twin" export-fmus --out "$target_dir/fmu" >/dev/null
