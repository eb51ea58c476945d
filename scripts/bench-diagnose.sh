#!/usr/bin/env bash
# `twin diagnose` (the goal: a full diagnosis of one 20 s record under 30 s on 2 cores, the
# alternatives fitted in parallel) against an fmpy + scipy peer doing the same computation
# (scripts/bench_diagnose.py: FMU2Slave on target/fmu/fmu_shear.fmu, least_squares per fit), in
# the same run:
#   1. the Python environment (scripts/setup-python.sh), the FMUs and `twin` in release;
#   2. the twin calibrated on dataset1 (`twin calibrate`);
#   3. `twin diagnose` of dataset3 RUNS times (default 3) with its default threads and RUNS times
#      with --threads 1, interleaved; the median of each (the report's "seconds"), the parallel
#      speed-up, the action, effect and NMSE after;
#   4. the peer on the same twin and record, one run of the whole library by default (1–3
#      minutes on 2 cores, by the machine's load; the whole bench 3–5 minutes); per job
#      (recalibration and each candidate) the median time of both sides and the ratio
#      peer / ours, the cores each side got, whether both reach the same decision and how close
#      their fits are.
# Not run by the tests. Options after RUNS go to bench_diagnose.py, e.g. --peer-runs 2, or
# --candidates contact@2-3:negative cubic@3 (the peer then runs the recalibration and those
# candidates, and the rest of the library is extrapolated from ours' times).
#
#   scripts/bench-diagnose.sh [RUNS] [--peer-runs N] [--candidates LABEL...] [--plain-api] [--json FILE]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
runs=3
if [[ $# -gt 0 && "$1" != -* ]]; then
  runs=$1
  shift
fi
if ! [[ "$runs" =~ ^[1-9][0-9]*$ ]]; then
  echo "bench-diagnose: RUNS must be a positive integer, was '$runs'" >&2
  exit 2
fi

# shellcheck source=scripts/bench-twin.sh
source scripts/bench-twin.sh
ours=()
ours1=()
cpu=()
# The cores ours' parallel runs actually got (CPU time / wall): on a shared machine, fewer than
# the threads it runs means other work took the rest.
timer=()
if [[ -x /usr/bin/time ]]; then timer=(/usr/bin/time -f "%e %U %S"); fi
for i in $(seq "$runs"); do
  if ((${#timer[@]})); then
    "${timer[@]}" -o "$work/ours$i.cpu" "$twin" diagnose --twin "$work/cal.ssp" --data data/dataset3.csv \
      --report "$work/ours$i.json" >/dev/null
    cpu+=("$work/ours$i.cpu")
  else
    "$twin" diagnose --twin "$work/cal.ssp" --data data/dataset3.csv --report "$work/ours$i.json" >/dev/null
  fi
  "$twin" diagnose --twin "$work/cal.ssp" --data data/dataset3.csv --threads 1 \
    --report "$work/ours1_$i.json" >/dev/null
  ours+=("$work/ours$i.json")
  ours1+=("$work/ours1_$i.json")
  echo "ours run $i/$runs done" >&2
done

.venv/bin/python scripts/bench_diagnose.py --ssp "$work/cal.ssp" --data data/dataset3.csv \
  --fmu "$target_dir/fmu/fmu_shear.fmu" --ours "${ours[@]}" --ours-1 "${ours1[@]}" \
  --ours-cpu ${cpu[@]+"${cpu[@]}"} "$@"
