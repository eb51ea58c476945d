#!/usr/bin/env bash
# Create (or bring up to date) the project's Python environment, .venv at the repository root,
# with the pinned packages of scripts/requirements.txt. Idempotent and quick when nothing
# changed: a stamp in .venv records the hash of the requirements and the interpreter version,
# and a second run with the same ones returns at once.
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

if ! command -v "$python" >/dev/null 2>&1; then
  echo "setup-python: '$python' not found; install CPython 3.11 or set PYTHON" >&2
  exit 1
fi

# What the environment must match: the requirements' content and the interpreter that made it.
wanted_stamp() {
  local digest version
  digest=$(sha256sum "$requirements" | cut -d' ' -f1)
  version=$("$1" -c 'import sys; print(".".join(map(str, sys.version_info[:3])))')
  echo "$digest python-$version"
}

if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] \
   && [ "$(cat "$stamp")" = "$(wanted_stamp "$venv/bin/python")" ] \
   && [ "$("$venv/bin/python" -c 'import sys; print(".".join(map(str, sys.version_info[:2])))')" \
        = "$("$python" -c 'import sys; print(".".join(map(str, sys.version_info[:2])))')" ]; then
  exit 0
fi

# A venv without a working interpreter (moved, or made by a Python that is gone) is rebuilt.
if [ -e "$venv" ] && ! "$venv/bin/python" -c 'import sys' >/dev/null 2>&1; then
  echo "setup-python: $venv is broken; recreating it" >&2
  rm -rf "$venv"
fi

if [ ! -x "$venv/bin/python" ]; then
  echo "setup-python: creating $venv with $("$python" --version 2>&1)" >&2
  if ! "$python" -m venv "$venv" 2>/dev/null; then
    # Debian's python3 without python3-venv has no ensurepip: make the venv without pip and
    # install pip into it with the interpreter's own pip, if there is one.
    rm -rf "$venv"
    "$python" -m venv --without-pip "$venv"
    if ! "$python" -m pip --python "$venv/bin/python" install --quiet --disable-pip-version-check pip; then
      rm -rf "$venv"
      echo "setup-python: '$python -m venv' has no ensurepip and '$python -m pip' cannot bootstrap pip;" \
           "install the python3-venv package (Debian) or use another CPython" >&2
      exit 1
    fi
  fi
fi

rm -f "$stamp"
echo "setup-python: installing scripts/requirements.txt into .venv" >&2
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --requirement "$requirements"
wanted_stamp "$venv/bin/python" >"$stamp"
