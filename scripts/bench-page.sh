#!/usr/bin/env bash
# The live page's cost (see scripts/bench_page.py for what is measured and how): the latency
# from a sample read to its point drawn in a headless chromium (median, p99), and `twin watch`'s
# speed with no page open and with ten open, one of them stalled. About two minutes on 2 cores
# once built. Needs chromium and chromium-driver (scripts/prerequisites.sh) and .venv's
# selenium (scripts/setup-python.sh). Not run by the tests.
#
#   scripts/bench-page.sh [--runs N] [--json FILE]   (options go to bench_page.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/build-fmus.sh >/dev/null
cargo build --release --quiet -p orchestrator --bin twin
export TWIN_FMU_DIR="$target_dir/fmu"
.venv/bin/python scripts/bench_page.py --twin-bin "$target_dir/release/twin" "$@"
