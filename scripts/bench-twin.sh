# Sourced by the benchmarks that run `twin` against a Python peer on the example records:
# the Python environment, the FMUs and `twin` in release; sets `twin`, TWIN_FMU_DIR and `work`
# (a temporary directory removed on exit) and writes the twin calibrated on dataset1 to
# "$work/cal.ssp". Expects to be in the repository root with `target_dir` set.
scripts/setup-python.sh >/dev/null
[[ -f "$target_dir/fmu/fmu_shear.fmu" && -f "$target_dir/fmu/fmu_gp_corrector.fmu" ]] || scripts/build-fmus.sh
cargo build --release --quiet -p orchestrator --bin twin
twin="$target_dir/release/twin"
export TWIN_FMU_DIR="$target_dir/fmu"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$twin" calibrate --data data/dataset1.csv --out "$work/cal.ssp" >/dev/null
