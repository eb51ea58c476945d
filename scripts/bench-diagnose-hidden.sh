#!/usr/bin/env bash
# The whole `twin diagnose` of 20 s records with hidden changes — forward selection of several
# changes and the discovery of effects outside the library included — against the goal of 30 s
# a record on this 2-core machine. No other tool does this diagnosis, so there is no peer here
# (scripts/bench-diagnose.sh times the library fits against an fmpy + scipy peer).
#   1. the FMUs and `twin` in release;
#   2. a twin calibrated on a change-free record of `twin synth`'s default structure (seed 1,
#      sensor noise 0.003 m/s²);
#   3. per case, a new record (seed 2, force ×3 in 12–17 s) with the hidden changes, diagnosed
#      RUNS times (default 3); the median wall time, the action, the effects and NMSE before →
#      after; then dataset3 with the twin calibrated on dataset1.
# About 5 minutes. Not run by the tests.
#
#   scripts/bench-diagnose-hidden.sh [RUNS]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
runs=${1:-3}
if ! [[ "$runs" =~ ^[1-9][0-9]*$ ]]; then
  echo "bench-diagnose-hidden: RUNS must be a positive integer, was '$runs'" >&2
  exit 2
fi
[[ -f "$target_dir/fmu/fmu_shear.fmu" ]] || scripts/build-fmus.sh
cargo build --release --quiet -p orchestrator --bin twin
twin="$target_dir/release/twin"
export TWIN_FMU_DIR="$target_dir/fmu"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

"$twin" synth --seed 1 --noise-sd 0.003 --out "$work/base.csv" >/dev/null
"$twin" calibrate --data "$work/base.csv" --out "$work/synth.ssp" >/dev/null
"$twin" calibrate --data data/dataset1.csv --out "$work/dataset1.ssp" >/dev/null

cases=(
  "contact 2-3|--effect contact@2-3:gap=5e-4,stiffness=9000,side=both"
  "k2 -15 % and contact 2-3|--change k2@0:0.85 --effect contact@2-3:gap=5e-4,stiffness=9000,side=both"
  "friction 1 and cubic 3|--effect friction@1:force=0.05,velocity_scale=1e-3 --effect cubic@3:stiffness=8e9"
  "quadratic damping storey 2|--effect quadratic-damping@2:coefficient=2000"
  "quadratic damping floor 3|--effect quadratic-damping@floor3:coefficient=2000"
  "Bouc-Wen storey 2|--effect hysteresis@2:stiffness=1500,yield=3e-4"
  "k2 -15 % at 10 s|--change k2@10:0.85"
)
summaries=()
n=0
for case in "${cases[@]}"; do
  n=$((n + 1))
  name=${case%%|*}
  read -r -a flags <<<"${case#*|}"
  record="$work/record.csv"
  "$twin" synth --seed 2 --noise-sd 0.003 --force-window 12:17:3:0.5 "${flags[@]}" --out "$record" >/dev/null
  files=()
  for i in $(seq "$runs"); do
    "$twin" diagnose --twin "$work/synth.ssp" --data "$record" --report "$work/case${n}_$i.json" >/dev/null
    files+=("$work/case${n}_$i.json")
  done
  summaries+=("$name|${files[*]}")
  echo "done: $name" >&2
done
files=()
for i in $(seq "$runs"); do
  "$twin" diagnose --twin "$work/dataset1.ssp" --data data/dataset3.csv --report "$work/ds3_$i.json" >/dev/null
  files+=("$work/ds3_$i.json")
done
summaries+=("dataset3 (twin of dataset1)|${files[*]}")

python3 - "${summaries[@]}" <<'PY'
import json, statistics, sys
print(f"{'case':<30} {'median s':>9} {'runs':>5}  action / effects / NMSE worst floor before → after")
worst_median = 0.0
for arg in sys.argv[1:]:
    name, files = arg.split("|", 1)
    reports = [json.load(open(f)) for f in files.split()]
    seconds = statistics.median(r["seconds"] for r in reports)
    worst_median = max(worst_median, seconds)
    r = reports[0]
    effects = " + ".join(
        e["label"] + ("(" + " + ".join(t["function"] for t in e.get("terms", [])) + ")" if e.get("terms") else "")
        for e in r.get("effects", [])
    ) or "-"
    moved = ", ".join(f"{p['name']} {100 * p['relative_change']:+.1f} %" for p in r.get("physics_moved", []))
    print(f"{name:<30} {seconds:>9.1f} {len(reports):>5}  {r['action']} / {effects}{' / ' + moved if moved else ''}"
          f" / {max(r['nmse_before']):.2f} → {max(r['nmse_after']):.3f} %")
print(f"slowest median {worst_median:.1f} s against the goal of 30 s: {'met' if worst_median < 30 else 'NOT met'}")
PY
