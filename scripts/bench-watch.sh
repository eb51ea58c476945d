#!/usr/bin/env bash
# Speed of `twin watch` on a long stream, against real time:
#   1. the FMUs and the release `twin` (scripts/build-fmus.sh, cargo build --release);
#   2. a twin calibrated on a 20 s synthetic record of the default structure (seed 1);
#   3. a long synthetic record (`twin synth --duration`, default 3600 s = 184 320 samples at
#      51.2 Hz, seed 2) streamed through `twin watch --source -` from a pipe;
# then prints, from the watcher's `end` alert: samples per second, the speed against real time
# (51.2 samples/s) and the median and p99 per-sample latency the watcher measured itself (the
# FMU step, the comparison and the alerts of one sample), and whether the product goal of at
# least 100× real time is met. About half a minute on 2 cores. Not run by the tests.
#
#   scripts/bench-watch.sh [DURATION_S]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
duration=${1:-3600}

scripts/build-fmus.sh
cargo build --release --quiet -p orchestrator --bin twin
twin="$target_dir/release/twin"
export TWIN_FMU_DIR="$target_dir/fmu"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$twin" synth --seed 1 --duration 20 --out "$work/calibration.csv" >/dev/null
"$twin" calibrate --data "$work/calibration.csv" --out "$work/twin.ssp" --starts 2 >/dev/null
"$twin" synth --seed 2 --duration "$duration" --out "$work/long.csv" >/dev/null
samples=$(($(wc -l <"$work/long.csv") - 1))
echo "streaming $samples samples (${duration} s at 51.2 Hz) through twin watch --source -"
start=$(date +%s.%N)
cat "$work/long.csv" | "$twin" watch --twin "$work/twin.ssp" --source - \
    --alerts "$work/alerts.jsonl" >/dev/null
end=$(date +%s.%N)
python3 - "$work/alerts.jsonl" "$start" "$end" <<'PY'
import json, sys
alerts = [json.loads(l) for l in open(sys.argv[1])]
end = alerts[-1]
assert end["kind"] == "end", end
wall = float(sys.argv[3]) - float(sys.argv[2])
rate = end["samples_per_second"]
factor = rate / 51.2
print(f"samples: {end['samples']}, alerts: {end['alerts']}, bad lines {end['bad_lines']}, gaps {end['gaps']}")
print(f"speed: {rate:,.0f} samples/s = {factor:,.0f}x real time (51.2 samples/s); "
      f"whole command incl. loading {wall:.2f} s = {end['samples'] / wall / 51.2:,.0f}x")
print(f"per-sample latency: median {end['latency_median_us']:.2f} us, p99 {end['latency_p99_us']:.2f} us")
print(f"goal >= 100x real time: {'met' if factor >= 100 else 'NOT met'}")
PY
