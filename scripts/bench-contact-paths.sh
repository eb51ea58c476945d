#!/usr/bin/env bash
# Instructions per step of the exact contact stepper on the paper's rig (fmu-shear's
# examples/contact_paths.rs), by path: the difference of cachegrind's instruction totals at 13
# and 3 records of 1024 steps, divided by 10 × 1024. Counts, not time: robust to a shared machine.
#   scripts/bench-contact-paths.sh [PATH ...]     (default: array inline)
set -euo pipefail
cd "$(dirname "$0")/.."
target=${CARGO_TARGET_DIR:-target}
cargo build --release -p fmu-shear --example contact_paths >&2
bin=$target/release/examples/contact_paths
count() {
    valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null "$bin" "$1" "$2" 2>&1 \
        | sed -n 's/.*I *refs: *//p' | tr -d ,
}
for path in "${@:-array inline}"; do
    for p in $path; do
        low=$(count "$p" 3)
        high=$(count "$p" 13)
        echo "$p: $(( (high - low) / 10240 )) instructions per step"
    done
done
"$bin" all 5 | tail -2
