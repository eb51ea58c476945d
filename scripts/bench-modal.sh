#!/usr/bin/env bash
# Modal identification of a one-hour, five-channel record (a five-storey building at 100 Hz,
# tests/python/modal_records.py) by `twin modal --data` and by strid's SSI-COV, in the same run:
# medians of a few runs each, and the ratio strid / ours. See scripts/bench_modal.py for what is
# timed. A few minutes on 2 cores. Not run by the tests.
#
#   scripts/bench-modal.sh [--repeats R]      (options go to bench_modal.py)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}

scripts/setup-python.sh
cargo build --release --quiet -p orchestrator --bin twin
.venv/bin/python scripts/bench_modal.py --twin "$target_dir/release/twin" "$@"
