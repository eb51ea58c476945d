#!/usr/bin/env bash
# The test command: Python venv with fmpy and the third-party tools, the FMUs, then every
# Rust test of the workspace and the Python cross-checks.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/setup-python.sh
scripts/build-fmus.sh
scripts/make-third-party-fmus.sh
cargo test --workspace --no-fail-fast
.venv/bin/python -m pytest tests/python -q
