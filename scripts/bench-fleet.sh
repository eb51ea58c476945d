#!/usr/bin/env bash
# The fleet's throughput with 1 and 2 Dask workers, the per-task overhead and the extrapolation
# to 100 workers (scripts/bench_fleet.py says how). Needs scripts/test.sh's set-up (the venv,
# the FMUs, the shear_twin package).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
exec .venv/bin/python scripts/bench_fleet.py "$@"
