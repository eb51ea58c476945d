#!/usr/bin/env bash
# `twin compare` against fmpy's simulate_fmu on the same FMU and input, in the same run (see
# scripts/bench_compare.py for what is timed and how):
#   1. the Python environment and the FMUs (scripts/setup-python.sh, scripts/build-fmus.sh);
#   2. the in-process timings of the master, orchestrator/examples/bench_master.rs, built in release;
#   3. scripts/bench_compare.py: medians of repeated runs, the ratio fmpy / twin.
#
#   scripts/bench-compare.sh [--repetitions N] [--json FILE]      (options go to bench_compare.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/setup-python.sh
scripts/build-fmus.sh
cargo build --release --quiet -p orchestrator --example bench_master
.venv/bin/python scripts/bench_compare.py "$@"
