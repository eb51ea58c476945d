#!/usr/bin/env bash
# Build the third-party FMUs that orchestrator/tests/third_party.rs loads, into target/third-party/:
#
#   LowPass.fmu          pythonfmu: the first-order low-pass of tests/python/fixtures/low_pass.py
#   shear_container.fmu  fmu-manipulation-toolbox: an FMU Container holding fmu_shear.fmu alone
#   shear_low_pass.fmu   fmu-manipulation-toolbox: a sequential container, fmu_shear.fmu's acc3
#                        feeding LowPass.fmu's u (time_constant 0.05 s set through the container)
#   python-runtime.env   how a host that is not Python runs a pythonfmu FMU (see below)
#
# A pythonfmu FMU's binary embeds CPython but does not link libpython: its Python symbols are
# left undefined, to be found in the host process. Under fmpy (a Python process) they are; a
# Rust host must have libpython loaded globally before it loads the FMU (LD_PRELOAD, as the
# pythonfmu README says), and CPython must find its standard library: with the symbols taken
# from another program, it cannot locate itself, so PYTHONHOME names the installation. The
# FMU's Python code and pythonfmu's own modules travel in the FMU's resources/, so only the
# standard library is needed at run time. python-runtime.env records, for the interpreter the
# FMU was built with (.venv's base interpreter):
#
#   LIBPYTHON=<libpython3.X.so.1.0 to preload>
#   PYTHONHOME=<prefix[:exec_prefix]>
#
# Needs scripts/setup-python.sh's .venv and the shear FMU (scripts/build-fmus.sh).
#
#   scripts/make-third-party-fmus.sh
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
out="$target_dir/third-party"
python="$root/.venv/bin/python"
shear="$target_dir/fmu/fmu_shear.fmu"
step=0.01953125 # 1/51.2 s, the examples' sampling interval

[ -x "$python" ] || { echo "make-third-party-fmus: $python is missing: run scripts/setup-python.sh" >&2; exit 1; }
[ -f "$shear" ] || { echo "make-third-party-fmus: $shear is missing: run scripts/build-fmus.sh" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"

# --- pythonfmu -----------------------------------------------------------------------------------
"$root/.venv/bin/pythonfmu" build -f tests/python/fixtures/low_pass.py -d "$work" >"$work/pythonfmu.log" 2>&1 || {
  cat "$work/pythonfmu.log" >&2
  echo "make-third-party-fmus: pythonfmu build failed" >&2
  exit 1
}
[ -f "$work/LowPass.fmu" ] || { echo "make-third-party-fmus: pythonfmu wrote no LowPass.fmu" >&2; exit 1; }

"$python" - "$work/python-runtime.env" <<'EOF'
import os, sys, sysconfig
libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
if not sysconfig.get_config_var("Py_ENABLE_SHARED") or not libdir or not soname:
    sys.exit(f"make-third-party-fmus: {sys.executable} has no shared libpython; a pythonfmu FMU cannot run outside Python")
library = os.path.join(libdir, soname)
if not os.path.isfile(library):
    sys.exit(f"make-third-party-fmus: {library} does not exist")
home = sys.base_prefix if sys.base_prefix == sys.base_exec_prefix else f"{sys.base_prefix}:{sys.base_exec_prefix}"
with open(sys.argv[1], "w") as f:
    f.write(f"LIBPYTHON={library}\nPYTHONHOME={home}\n")
EOF

# --- fmu-manipulation-toolbox containers ---------------------------------------------------------
containers="$work/containers"
mkdir -p "$containers"
cp "$shear" "$containers/fmu_shear.fmu"
cp "$work/LowPass.fmu" "$containers/LowPass.fmu"
# Outputs of the shear FMU no container uses are dropped, so the builder has nothing to warn about.
unused='["fmu_shear.fmu", "disp1"], ["fmu_shear.fmu", "disp2"], ["fmu_shear.fmu", "disp3"],
        ["fmu_shear.fmu", "vel1"], ["fmu_shear.fmu", "vel2"], ["fmu_shear.fmu", "vel3"],
        ["fmu_shear.fmu", "drift1"], ["fmu_shear.fmu", "drift2"], ["fmu_shear.fmu", "drift3"]'
# …and the 27 sensitivity outputs d_acc{f}_d_{p}.
for f in 1 2 3; do
  for p in m1 m2 m3 c1 c2 c3 k1 k2 k3; do
    unused+=", [\"fmu_shear.fmu\", \"d_acc${f}_d_${p}\"]"
  done
done
cat >"$containers/shear_container.json" <<EOF
{
  "name": "shear_container.fmu",
  "step_size": $step,
  "auto_link": false, "auto_input": false, "auto_output": false,
  "fmu": ["fmu_shear.fmu"],
  "input": [["force", "fmu_shear.fmu", "force"], ["control_force", "fmu_shear.fmu", "control_force"]],
  "output": [["fmu_shear.fmu", "acc1", "acc1"], ["fmu_shear.fmu", "acc2", "acc2"], ["fmu_shear.fmu", "acc3", "acc3"]],
  "drop": [$unused]
}
EOF
cat >"$containers/shear_low_pass.json" <<EOF
{
  "name": "shear_low_pass.fmu",
  "step_size": $step,
  "sequential": true,
  "auto_link": false, "auto_input": false, "auto_output": false,
  "fmu": ["fmu_shear.fmu", "LowPass.fmu"],
  "input": [["force", "fmu_shear.fmu", "force"], ["control_force", "fmu_shear.fmu", "control_force"]],
  "link": [["fmu_shear.fmu", "acc3", "LowPass.fmu", "u"]],
  "output": [["fmu_shear.fmu", "acc1", "acc1"], ["fmu_shear.fmu", "acc2", "acc2"], ["fmu_shear.fmu", "acc3", "acc3"],
             ["LowPass.fmu", "y", "acc3_filtered"]],
  "start": [["LowPass.fmu", "time_constant", "0.05"]],
  "drop": [$unused]
}
EOF
for name in shear_container shear_low_pass; do
  log="$work/$name.log"
  if ! "$root/.venv/bin/fmucontainer" -container "$name.json" -fmu-directory "$containers" >"$log" 2>&1; then
    cat "$log" >&2
    echo "make-third-party-fmus: fmucontainer failed for $name" >&2
    exit 1
  fi
  # The toolbox reports wiring mistakes as ERROR/WARNING lines and still writes an FMU.
  if grep -E '^(ERROR|WARNING|CRITICAL)' "$log" >&2; then
    echo "make-third-party-fmus: fmucontainer complained about $name (above)" >&2
    exit 1
  fi
  [ -f "$containers/$name.fmu" ] || { echo "make-third-party-fmus: no $name.fmu" >&2; exit 1; }
done

# Replace the outputs only once everything is built: a failed run leaves the previous set whole.
mv "$work/LowPass.fmu" "$out/LowPass.fmu"
mv "$containers/shear_container.fmu" "$out/shear_container.fmu"
mv "$containers/shear_low_pass.fmu" "$out/shear_low_pass.fmu"
mv "$work/python-runtime.env" "$out/python-runtime.env"
echo "make-third-party-fmus: wrote $out/{LowPass.fmu,shear_container.fmu,shear_low_pass.fmu,python-runtime.env}"
