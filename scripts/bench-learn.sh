#!/usr/bin/env bash
# Active learning, fixed threshold (reference paper Algorithm 1): `twin learn --mode fixed`
# against a numpy/scipy peer (scripts/bench_learn.py) on the same inputs, in the same run:
#   1. the Python environment (scripts/setup-python.sh), the FMUs and `twin` in release;
#   2. the twin calibrated on dataset1 (`twin calibrate`), its physics predictions on the three
#      records (`twin compare --predictions`): the peer reads these, so both learn from the
#      same inputs;
#   3. each side runs Algorithm 1 over the three records RUNS times (default 3), with the same
#      refit schedule (passed to both); printed: the median time of the initial fit and the
#      learning loop (ours: "initial_fit_seconds" + the mode's "seconds" in the report, which
#      leave out the FMI physics runs; the peer: its loop, initial fit included), the queries
#      per record, the final NMSE per floor per record, and the ratio peer / ours.
#
#   scripts/bench-learn.sh [RUNS] [--lags Q]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
runs=${1:-3}
shift || true
lags=9
if [[ "${1:-}" == "--lags" ]]; then lags=$2; fi

# shellcheck source=scripts/bench-twin.sh
source scripts/bench-twin.sh
for k in 1 2 3; do
  "$twin" compare --twin "$work/cal.ssp" --data "data/dataset$k.csv" --predictions "$work/p$k.csv" >/dev/null
done
data=(data/dataset1.csv data/dataset2.csv data/dataset3.csv)

schedule=(--refit-every 25 --refit-growth 0.3333333333333333 --refit-iterations 100)
for i in $(seq "$runs"); do
  "$twin" learn --twin "$work/cal.ssp" --data "${data[@]}" --mode fixed --lags "$lags" \
    "${schedule[@]}" --report "$work/ours$i.json" >/dev/null
  .venv/bin/python scripts/bench_learn.py --data "${data[@]}" \
    --predictions "$work/p1.csv" "$work/p2.csv" "$work/p3.csv" --lags "$lags" \
    "${schedule[@]}" --json "$work/peer$i.json" >/dev/null
done

.venv/bin/python - "$work" "$runs" <<'PY'
import json, statistics, sys
work, runs = sys.argv[1], int(sys.argv[2])
ours = [json.load(open(f"{work}/ours{i}.json"))["modes"][0] for i in range(1, runs + 1)]
peer = [json.load(open(f"{work}/peer{i}.json")) for i in range(1, runs + 1)]
t_ours = statistics.median(m["seconds"] + m["initial_fit_seconds"] for m in ours)
t_peer = statistics.median(p["seconds"] for p in peer)
fmt = lambda n: "/".join(f"{v:.2f}" for v in n)
print(f"ours (twin learn --mode fixed): median {t_ours:.2f} s over {runs} runs")
print(f"  queries per record {[r['queries'] for r in ours[0]['records']]}")
print(f"  final NMSE %       {[fmt(r['final_nmse']) for r in ours[0]['records']]}")
print(f"peer (numpy/scipy, refactoring): median {t_peer:.2f} s over {runs} runs")
print(f"  queries per record {[r['queries'] for r in peer[0]['records']]}")
print(f"  final NMSE %       {[fmt(r['final_nmse']) for r in peer[0]['records']]}")
print(f"ratio peer / ours: {t_peer / t_ours:.2f}")
PY
