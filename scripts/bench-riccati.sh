#!/usr/bin/env bash
# Our CARE solver (numerics::control::solve_care) against scipy and python-control on the same
# problem, in the same run (see scripts/bench_riccati.py for the problem and what is timed):
#   1. the Python environment (scripts/setup-python.sh);
#   2. the criterion bench `riccati/shear_n6_q1e3_light` (numerics/benches/riccati.rs), release;
#   3. scripts/bench_riccati.py: reads criterion's median, times scipy's solve_continuous_are and
#      control.lqr on the same problem (median of many batches), prints the times and the ratios.
#      About a minute on 2 cores. Not run by the tests.
#
#   scripts/bench-riccati.sh [--repeats R] [--number N]      (options go to bench_riccati.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh
cargo bench --quiet -p numerics --bench riccati -- shear_n6_q1e3_light
.venv/bin/python scripts/bench_riccati.py --criterion "$target_dir/criterion" "$@"
