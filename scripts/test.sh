#!/usr/bin/env bash
# The test command: the machine's prerequisites (checked in seconds; as root with apt-get the
# missing Debian packages are installed, otherwise it stops with the command to run), the
# Python venv with fmpy and the third-party tools, the FMUs, the shear_twin package (built from
# python/ with maturin into .venv), both installs used from outside the repository
# (scripts/test-installs.sh), then every Rust test of the workspace and the Python tests.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/prerequisites.sh
scripts/setup-python.sh
scripts/build-fmus.sh
scripts/make-third-party-fmus.sh
scripts/make-c-fmus.sh
scripts/install-python-package.sh
scripts/test-installs.sh
cargo test --workspace --no-fail-fast
.venv/bin/python -m pytest tests/python -q
