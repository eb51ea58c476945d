#!/usr/bin/env bash
# `twin compare` of a twin with the bumper between floors 2 and 3 against the same twin without
# it, on a long record, in the same run (see scripts/bench_contact.py for what is timed):
#   1. the FMUs and the release `twin` (scripts/build-fmus.sh, cargo build --release);
#   2. a twin calibrated on a 20 s synthetic record of the default structure (seed 1), as
#      scripts/bench-watch.sh makes it; a synthetic record of DURATION_S seconds (default 3600 s
#      = 184 320 samples at 51.2 Hz, seed 2, force 2 N RMS) of that structure with the bumper (0.5 mm,
#      9000 N/m, both sides);
#   3. scripts/bench_contact.py: five twins made from the calibrated one by their parameter sets —
#      linear; contact (integrator 0: the exact flows of the contact regions); contact with
#      integrator 1 (64 RK4 sub-steps split at the gap, the former path); cubic stiffness on
#      storey 3 (error-controlled) and with integrator 1 — each compared with the record in
#      turn, --repetitions rounds; medians of the wall and CPU time, the ratios to the linear
#      twin and new against old. About a minute on 2 cores. Not run by the tests.
#
#   scripts/bench-contact.sh [DURATION_S] [--repetitions N] [--json FILE]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
duration=3600
if [ $# -gt 0 ] && [[ $1 != --* ]]; then
  duration=$1
  shift
fi

scripts/build-fmus.sh
cargo build --release --quiet -p orchestrator --bin twin
twin="$target_dir/release/twin"
export TWIN_FMU_DIR="$target_dir/fmu"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$twin" synth --seed 1 --duration 20 --out "$work/calibration.csv" >/dev/null
"$twin" calibrate --data "$work/calibration.csv" --out "$work/linear.ssp" --starts 2 >/dev/null
"$twin" synth --seed 2 --duration "$duration" --force-rms 2 --effect contact@2-3:gap=5e-4,stiffness=9000,side=both \
  --out "$work/long.csv" --truth "$work/truth.json" >/dev/null
python3 scripts/bench_contact.py --twin-bin "$twin" --work "$work" --record "$work/long.csv" "$@"
