#!/usr/bin/env bash
# Build the hand-written C test FMUs of tests/c-fmus/ (FMI 2.0 co-simulation; what each one does is
# in tests/c-fmus/README.md) into ${CARGO_TARGET_DIR:-target}/c-fmus/<Name>.fmu:
#
#   BouncingBall.fmu  Discrete.fmu  Table.fmu  Stopper.fmu  NoInterp.fmu  Interp.fmu
#
# Every directory tests/c-fmus/<Name>/ holding a model.c is one FMU: model.c (which includes
# tests/c-fmus/common.h) is compiled into binaries/linux64/<Name>.so, and modelDescription.xml and
# resources/ (when there is one) are packed beside it. The FMI 2.0 headers are not kept in the
# repository: they come from fmpy's package in .venv (fmpy/c-code). Each library must export the
# 44 functions of fmi2Functions.h and nothing else. The archives are written with fixed time stamps,
# so the same sources give the same bytes.
#
# Needs gcc, nm and scripts/setup-python.sh's .venv (fmpy). Takes a few seconds.
#
#   scripts/make-c-fmus.sh
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
target_dir=${CARGO_TARGET_DIR:-$root/target}
out="$target_dir/c-fmus"
src="$root/tests/c-fmus"
python="$root/.venv/bin/python"

command -v gcc >/dev/null || { echo "make-c-fmus: gcc is missing: install it (apt-get install gcc)" >&2; exit 1; }
command -v nm >/dev/null || { echo "make-c-fmus: nm is missing: install binutils" >&2; exit 1; }
[ -x "$python" ] || { echo "make-c-fmus: $python is missing: run scripts/setup-python.sh" >&2; exit 1; }
headers=$("$python" -c 'import fmpy, os; print(os.path.join(os.path.dirname(fmpy.__file__), "c-code"))' 2>/dev/null) || {
  echo "make-c-fmus: $python cannot import fmpy: run scripts/setup-python.sh" >&2
  exit 1
}
for h in fmi2Functions.h fmi2FunctionTypes.h fmi2TypesPlatform.h; do
  [ -f "$headers/$h" ] || { echo "make-c-fmus: $headers/$h is missing (fmpy's FMI headers)" >&2; exit 1; }
done

names=()
for model in "$src"/*/model.c; do
  [ -f "$model" ] && names+=("$(basename "$(dirname "$model")")")
done
[ ${#names[@]} -gt 0 ] || { echo "make-c-fmus: no $src/<Name>/model.c found" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

for name in "${names[@]}"; do
  dir="$src/$name"
  fmu_dir="$work/$name"
  [ -f "$dir/modelDescription.xml" ] || { echo "make-c-fmus: $dir/modelDescription.xml is missing" >&2; exit 1; }
  grep -q "modelIdentifier=\"$name\"" "$dir/modelDescription.xml" || {
    echo "make-c-fmus: $dir/modelDescription.xml does not declare modelIdentifier=\"$name\"" >&2
    exit 1
  }
  mkdir -p "$fmu_dir/binaries/linux64"
  so="$fmu_dir/binaries/linux64/$name.so"
  gcc -shared -fPIC -O2 -Wall -Wextra -Werror -fvisibility=hidden -I"$headers" -I"$src" \
    -o "$so" "$dir/model.c" -Wl,--no-undefined -lm || {
    echo "make-c-fmus: gcc failed for $name (above)" >&2
    exit 1
  }
  exported=$(nm -D --defined-only "$so" | awk '$2 == "T" { print $3 }' | sort)
  count=$(grep -c '^fmi2' <<<"$exported" || true)
  others=$(grep -v '^fmi2' <<<"$exported" || true)
  if [ "$count" -ne 44 ] || [ -n "$others" ]; then
    echo "make-c-fmus: $name.so exports $count fmi2 functions (44 expected)${others:+ and also: $others}" >&2
    exit 1
  fi
  cp "$dir/modelDescription.xml" "$fmu_dir/"
  [ -d "$dir/resources" ] && cp -R "$dir/resources" "$fmu_dir/resources"
  "$python" - "$fmu_dir" "$work/$name.fmu" <<'EOF'
import os, sys, zipfile
top, archive = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
    for here, dirs, files in os.walk(top):
        dirs.sort()
        for f in sorted(files):
            path = os.path.join(here, f)
            info = zipfile.ZipInfo(os.path.relpath(path, top).replace(os.sep, "/"), (1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with open(path, "rb") as data:
                z.writestr(info, data.read())
EOF
done

# Replace the outputs only once everything is built: a failed run leaves the previous set whole.
mkdir -p "$out"
for name in "${names[@]}"; do
  mv "$work/$name.fmu" "$out/$name.fmu"
done
echo "make-c-fmus: wrote $out/{$(IFS=,; echo "${names[*]}")}.fmu"
