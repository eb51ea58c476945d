#!/usr/bin/env bash
# Build every FMU of the workspace in release mode and package it as target/fmu/<modelIdentifier>.fmu.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

# crate name : modelIdentifier
fmus=("fmu-shear:fmu_shear" "fmu-gp-corrector:fmu_gp_corrector" "fmu-lqr:fmu_lqr" "fmu-substructure:fmu_substructure")

packages=()
features=()
for entry in "${fmus[@]}"; do
  packages+=(-p "${entry%%:*}")
  features+=("${entry%%:*}/exports")
done
# The packer first: it links the FMU crates as ordinary libraries, without `exports`.
cargo build --release --quiet -p orchestrator --bin twin
# `exports` gives the fmi2* functions their C names in the shared libraries (fmi2::export_fmu!);
# built last, so these are the libraries that get packaged.
cargo build --release --quiet "${packages[@]}" --features "$(IFS=,; echo "${features[*]}")"

mkdir -p "$target_dir/fmu"
for entry in "${fmus[@]}"; do
  crate=${entry%%:*}
  id=${entry##*:}
  args=(--model-description "modelDescription/$id.xml"
        --library "$target_dir/release/lib${crate//-/_}.so"
        --out "$target_dir/fmu/$id.fmu")
  [ -d "$crate/documentation" ] && args+=(--documentation "$crate/documentation")
  [ -d "$crate/resources" ] && args+=(--resources "$crate/resources")
  "$target_dir/release/twin" pack-fmu "${args[@]}"
done
