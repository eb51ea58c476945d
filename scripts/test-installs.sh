#!/usr/bin/env bash
# Both installs as a user makes them, used from directories outside the repository with no
# TWIN_FMU_DIR and a fresh home (so a fresh FMU cache): the FMUs must come from the installed
# binary or package itself.
#
#   1. `cargo install --locked --path orchestrator --root TMP` (in the workspace's target
#      directory, so it reuses the release build of scripts/build-fmus.sh), then `twin init` and
#      `twin compare --data <dataset1>` from another temporary directory;
#   2. `pip install ./python` into a new venv of the system's python3 (its dependencies at the
#      versions of scripts/requirements.txt, from pip's cache after scripts/setup-python.sh),
#      then Twin.default(), compare, calibrate and diagnose from Python in a temporary directory.
#
# Run by scripts/test.sh after the FMUs and the package are built; prints each part's time.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
target_dir=${CARGO_TARGET_DIR:-$root/target}
python=${PYTHON:-python3}
work=$(mktemp -d "${TMPDIR:-/tmp}/shear-twin-installs.XXXXXX")
trap 'rm -rf "$work"' EXIT
case "$work" in "$root"/*) echo "test-installs: $work is inside the repository" >&2; exit 1 ;; esac

# What the installed programs run with: no TWIN_FMU_DIR, no cache override, a new home.
mkdir -p "$work/home"
as_user=(env -u TWIN_FMU_DIR -u TWIN_FMU_CACHE -u XDG_CACHE_HOME -u PYTHONPATH -u VIRTUAL_ENV
         HOME="$work/home")
fail() { echo "test-installs: $*" >&2; exit 1; }

# 1. cargo install
start=$SECONDS
cargo install --locked --quiet --path "$root/orchestrator" --root "$work/cargo" \
  --target-dir "$target_dir"
twin="$work/cargo/bin/twin"
mkdir "$work/init" "$work/compare"
(cd "$work/init" && "${as_user[@]}" "$twin" init --out twin.ssp >/dev/null)
(cd "$work/compare" && "${as_user[@]}" "$twin" compare --twin "$work/init/twin.ssp" \
   --data "$root/data/dataset1.csv" --report report.json >/dev/null)
# The default twin on dataset1: worst-floor NMSE 5293 % (measured; uncalibrated parameters).
"$python" - "$work/compare/report.json" <<'EOF'
import json, sys
nmse = json.load(open(sys.argv[1]))["nmse"]
assert len(nmse) == 3 and all(1000 < n < 10000 for n in nmse), nmse
EOF
ls "$work/home/.cache/shear-twin/fmu/embedded/"fmu_shear-*.fmu >/dev/null 2>&1 \
  || fail "the installed twin did not write its shear FMU into the fresh cache"
# All four FMUs travel with it: written out, each a non-empty archive.
(cd "$work/compare" && "${as_user[@]}" "$twin" export-fmus --out fmus >/dev/null)
for id in fmu_shear fmu_gp_corrector fmu_lqr fmu_substructure; do
  [ -s "$work/compare/fmus/$id.fmu" ] || fail "twin export-fmus wrote no $id.fmu"
done
echo "test-installs: cargo install --path orchestrator, twin init, compare, export-fmus: $((SECONDS - start)) s"

# 2. pip install
start=$SECONDS
"$python" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install --quiet --disable-pip-version-check \
  -c "$root/scripts/requirements.txt" "$root/python"
mkdir "$work/python"
(cd "$work/python" && "${as_user[@]}" "$work/venv/bin/python" - "$root" <<'EOF'
import os, pathlib, sys
root = pathlib.Path(sys.argv[1])
import shear_twin as st
package = pathlib.Path(st.__file__).resolve()
assert not package.is_relative_to(root), f"shear_twin imported from the repository: {package}"
assert "TWIN_FMU_DIR" not in os.environ

record = st.Record.read(str(root / "data" / "dataset1.csv"))
twin = st.Twin.default()
before = twin.compare(record)
calibrated, report = twin.calibrate(record, starts=2)
after = calibrated.compare(record)
# Measured: worst floor 5293 % before, 0.18 % after the calibration.
assert max(before.nmse) > 1000, before.nmse
assert max(after.nmse) < 1.0, after.nmse
diagnosis = calibrated.diagnose(st.Record.read(str(root / "data" / "dataset3.csv")))
assert diagnosis.action == "add_physics", diagnosis.action
cache = pathlib.Path(os.environ["HOME"]) / ".cache/shear-twin/fmu/embedded"
assert list(cache.glob("fmu_shear-*.fmu")), f"no shear FMU written into {cache}"
print(f"  python: nmse {max(before.nmse):.0f} % -> {max(after.nmse):.3f} %, "
      f"dataset3: {diagnosis.action}")
EOF
)
echo "test-installs: pip install ./python into a new venv, compare, calibrate, diagnose: $((SECONDS - start)) s"
