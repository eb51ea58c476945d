#!/usr/bin/env bash
# Create (or bring up to date) the project's Python environment, .venv at the repository root,
# with the pinned packages of scripts/requirements.txt. Idempotent and quick when nothing
# changed: a stamp in .venv records the hash of the requirements and the interpreter version,
# and a run that finds both unchanged returns at once.
#
#   scripts/setup-python.sh            # then: .venv/bin/python -m pytest tests/python -q
#   PYTHON=python3.11 scripts/setup-python.sh
#
# Needs CPython ≥ 3.10 (3.11 on the project's machines) and PyPI; nothing else is downloaded.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
venv="$root/.venv"
requirements="$root/scripts/requirements.txt"
stamp="$venv/.requirements.stamp"
python=${PYTHON:-python3}

version_of() {
  "$1" -c 'import sys; print(".".join(map(str, sys.version_info[:3])))' 2>/dev/null
}

if ! wanted_version=$(version_of "$python"); then
  echo "setup-python: '$python' does not run; install CPython 3.11 or set PYTHON" >&2
  exit 1
fi
wanted_stamp="$(sha256sum "$requirements" | cut -d' ' -f1) python-$wanted_version"
venv_version=$(version_of "$venv/bin/python" || true)

if [ "$venv_version" = "$wanted_version" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$wanted_stamp" ]; then
  exit 0
fi

# A venv of another interpreter, or one whose interpreter no longer runs, is rebuilt.
if [ -e "$venv" ] && [ "$venv_version" != "$wanted_version" ]; then
  echo "setup-python: $venv has Python '${venv_version:-none}', want $wanted_version: recreating it" >&2
  rm -rf "$venv"
fi

if [ ! -e "$venv" ]; then
  echo "setup-python: creating $venv with Python $wanted_version" >&2
  if ! "$python" -m venv "$venv" 2>/dev/null; then
    # Debian's own python3 without the python3-venv package has no ensurepip: make the venv
    # without pip and install pip into it with the interpreter's pip, if it has one.
    rm -rf "$venv"
    "$python" -m venv --without-pip "$venv"
    if ! "$python" -m pip --python "$venv/bin/python" install --quiet --disable-pip-version-check pip; then
      rm -rf "$venv"
      echo "setup-python: '$python -m venv' lacks ensurepip and '$python -m pip' cannot bootstrap pip;" \
           "install Debian's python3-venv package or use another CPython" >&2
      exit 1
    fi
  fi
fi

rm -f "$stamp"
echo "setup-python: installing scripts/requirements.txt into .venv" >&2
# The demo (SHEAR_TWIN_PROGRESS=1) shows pip's own progress, a line a package; the tests keep it quiet.
quiet=(--quiet)
[ -n "${SHEAR_TWIN_PROGRESS:-}" ] && quiet=()
"$venv/bin/python" -m pip install "${quiet[@]}" --disable-pip-version-check --requirement "$requirements"
echo "$wanted_stamp" >"$stamp"
