#!/usr/bin/env bash
# Cost with N: `twin compare`, `twin calibrate` and `twin diagnose` on 3-, 10- and 20-storey
# shear buildings (20 s records at 51.2 Hz, a force at floor 1, an accelerometer on every floor),
# each against a numpy/scipy peer running the same linear model in the same run (see
# scripts/bench_storeys.py for the buildings, the records and what each peer does):
#   1. the Python environment, the FMUs and `twin` in release (scripts/setup-python.sh,
#      scripts/build-fmus.sh);
#   2. scripts/bench_storeys.py: per N, the twin made by `twin init --nominal`, records by
#      `twin synth` (calibration; diagnosis with a hidden cubic spring in storey 1); medians of
#      --repetitions (default 3) interleaved runs of both sides; the table of seconds against N
#      and the ratios peer / ours, the 10-storey diagnosis over the 3-storey one (goal: ≤ 5×).
# The peers run single-threaded BLAS (OPENBLAS_NUM_THREADS=1 and the like) and get their
# parallelism, where ours has it, from processes. About 12–15 minutes on 2 shared cores; the
# N = 20 diagnosis is most of it (--diagnose-max-storeys 10 leaves it out). Not run by the tests.
#
#   scripts/bench-storeys.sh [--storeys N...] [--repetitions N] [--starts S]
#                            [--diagnose-max-storeys N] [--json FILE]   (options go to bench_storeys.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh >/dev/null
scripts/build-fmus.sh
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
.venv/bin/python scripts/bench_storeys.py --twin "$target_dir/release/twin" "$@"
