#!/usr/bin/env bash
# `twin run` against fmpy's `simulate_fmu` on the same FMUs and inputs, in the same run: the
# shear FMU on dataset1's force (1024 steps), the C FMUs (BouncingBall: 300 steps with events;
# Discrete: Integer/Boolean/String with input events) and fmu-manipulation-toolbox's container.
# Medians of repeated runs; see scripts/bench_run.py for what is timed.
#
#   scripts/bench-run.sh [--repetitions N]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/setup-python.sh
scripts/build-fmus.sh
scripts/make-c-fmus.sh >/dev/null
[ -f "${CARGO_TARGET_DIR:-target}/third-party/shear_container.fmu" ] || scripts/make-third-party-fmus.sh
cargo build --release --quiet -p orchestrator --bin twin
.venv/bin/python scripts/bench_run.py "$@"
