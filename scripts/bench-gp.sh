#!/usr/bin/env bash
# Our GP fit (numerics::gp) against a numpy/scipy peer on the same problem, in the same run
# (see scripts/bench_gp.py for the problem, the peer and what is timed):
#   1. the Python environment (scripts/setup-python.sh) and the example that fits three GPs
#      (numerics/examples/fit_three.rs), built in release;
#   2. scripts/bench_gp.py: ours fits the three GPs of the synthetic problem (N = 1000, d = 40,
#      3 starts each, one thread) and writes the problem; the peer fits the same three from the
#      same starts, on one thread; printed: both times, the ratio peer / ours, each GP's final
#      NLML on both sides, iterations and evaluations. About two minutes on 2 cores. Not run
#      by the tests.
#
#   scripts/bench-gp.sh [--n N] [--dim D] [--seed S] [--starts K] [--max-iterations M]
#                       [--json FILE]                      (options go to bench_gp.py)
#
# The criterion benches of the same code (fit, Cholesky faer vs nalgebra, append, ...):
#   cargo bench -p numerics --bench gp
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh
cargo build --release --quiet -p numerics --example fit_three
.venv/bin/python scripts/bench_gp.py --ours "$target_dir/release/examples/fit_three" "$@"
