#!/usr/bin/env bash
# The demo on the bundled example data: build the FMUs and the twin CLI, then compare the
# default twin with each example record (reports, predictions and plots under out/).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/build-fmus.sh
twin=target/release/twin
out=out/demo
mkdir -p "$out"

"$twin" init --out "$out/default.ssp"
for n in 1 2 3; do
  echo
  echo "== twin compare on dataset$n =="
  "$twin" compare --twin "$out/default.ssp" --data "data/dataset$n.csv" \
    --report "$out/compare-dataset$n.json" --predictions "$out/predictions-dataset$n.csv" \
    --plot "$out/compare-dataset$n.svg" --frf
done
echo
echo "reports, predictions and plots are in $out/"
