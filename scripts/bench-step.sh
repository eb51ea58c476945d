#!/usr/bin/env bash
# Cost of one communication step of the shear FMU, ours against fmpy, in the same run:
#   1. our criterion benchmark, `cargo bench -p fmu-shear --bench do_step`, group fmi2DoStep,
#      id record_1024_steps: one full 1024-step record through the C ABI; its median (ns) is
#      read from target/criterion/fmi2DoStep/record_1024_steps/new/estimates.json;
#   2. scripts/bench_fmpy.py: fmpy's simulate_fmu on the same FMU and the same input (dataset1's
#      force, 1024 steps of 1/51.2 s);
# then prints both per-step times, steps per second and the ratio fmpy / ours.
#
#   scripts/bench-step.sh [--repetitions N] [--json FILE]     (options go to bench_fmpy.py)
#   BENCH_STEP_ESTIMATES=path/estimates.json scripts/bench-step.sh
#       skips cargo and compares with that file instead (e.g. one from an earlier run)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh
scripts/build-fmus.sh

if [ -n "${BENCH_STEP_ESTIMATES:-}" ]; then
  estimates=$BENCH_STEP_ESTIMATES
  echo "bench-step: not running cargo bench; comparing with $estimates" >&2
else
  estimates="$target_dir/criterion/fmi2DoStep/record_1024_steps/new/estimates.json"
  # A result older than this run must not be reported as this run's.
  marker=$(mktemp)
  trap 'rm -f "$marker"' EXIT
  if ! cargo bench -p fmu-shear --bench do_step -- 'fmi2DoStep/record_1024_steps'; then
    echo "bench-step: 'cargo bench -p fmu-shear --bench do_step' failed" >&2
    exit 1
  fi
  if [ ! -f "$estimates" ] || [ ! "$estimates" -nt "$marker" ]; then
    echo "bench-step: the bench ran but did not write $estimates: is there a criterion group" \
         "'fmi2DoStep' with the id 'record_1024_steps' in fmu-shear/benches/do_step.rs?" >&2
    exit 1
  fi
fi
[ -f "$estimates" ] || { echo "bench-step: $estimates does not exist" >&2; exit 1; }

.venv/bin/python scripts/bench_fmpy.py --fmu "$target_dir/fmu/fmu_shear.fmu" --criterion-estimates "$estimates" "$@"
