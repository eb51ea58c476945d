#!/usr/bin/env bash
# `twin watch` on long streams, against real time (see scripts/bench_watch.py for what is
# measured and how):
#   1. the FMUs and the release `twin` (scripts/build-fmus.sh, cargo build --release);
#   2. scripts/bench_watch.py: the physics twin on 1 h and 24 h streams (speed against real
#      time, per-sample latency, peak memory of each: constant memory means equal peaks), the
#      twin with a GP corrector learning online (budget 256) on 1 h and 3 h, and the delay from
#      a stiffness change to the `failing` alert. About ten minutes on 2 cores. Not run by the
#      tests.
#
#   scripts/bench-watch.sh [--corrector-hours H] [--budget N] [--json FILE]   (options go to bench_watch.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/build-fmus.sh >/dev/null
cargo build --release --quiet -p orchestrator --bin twin
export TWIN_FMU_DIR="$target_dir/fmu"
python3 scripts/bench_watch.py --twin-bin "$target_dir/release/twin" "$@"
