#!/usr/bin/env bash
# `twin calibrate` against a numpy/scipy peer (L-BFGS-B, finite-difference gradients) on the same
# MAP problem, in the same run (see scripts/bench_calibrate.py for the problem, the peer's model
# and what is timed):
#   1. the Python environment and the FMUs and twin binary (scripts/setup-python.sh,
#      scripts/build-fmus.sh);
#   2. scripts/bench_calibrate.py: medians of repeated runs of both on data/dataset1.csv, the best
#      negative log posterior of each scored with one formula, the MAP estimates, NMSE per floor
#      and the ratio peer / ours. About a minute on 2 cores (the peer's runs are capped to keep
#      the whole under ~3 minutes). Not run by the tests.
#
#   scripts/bench-calibrate.sh [--repetitions N] [--peer-repetitions N] [--peer-maxiter N]
#                              [--data FILE] [--json FILE]     (options go to bench_calibrate.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh
scripts/build-fmus.sh
.venv/bin/python scripts/bench_calibrate.py --twin "$target_dir/release/twin" "$@"
