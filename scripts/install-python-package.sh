#!/usr/bin/env bash
# Build the shear_twin Python package (python/: PyO3 over the orchestrator library, maturin as
# the build backend, in release mode in the workspace's target directory, so it reuses the
# orchestrator already built) and install it into .venv. Plain pip does the same from PyPI's
# maturin: `pip install ./python`.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
# maturin from the venv (scripts/requirements.txt pins it), found by pip's build hooks on PATH.
# The demo (SHEAR_TWIN_PROGRESS=1) shows maturin's cargo build as it goes (pip -v); the tests keep
# it quiet.
quiet=(--quiet)
[ -n "${SHEAR_TWIN_PROGRESS:-}" ] && quiet=(-v)
PATH="$root/.venv/bin:$PATH" .venv/bin/python -m pip install "${quiet[@]}" --disable-pip-version-check \
  --no-build-isolation --no-deps --force-reinstall ./python
