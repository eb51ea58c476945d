#!/usr/bin/env python3
"""`twin modal --data` against strid (0.4.3) on one record, in the same run.

The record: one hour of the five-storey building of tests/python/modal_records.py at 100 Hz
(360 000 samples, force and acc1..acc5), written once as CSV. Timed, each the median of
`--repeats` runs, wall clock, from the CSV file to the modes:

- ours, output-only: `twin modal --data R.csv --output-only --report J.json` (read the CSV,
  spectra, SSI-COV at orders 2..40 with 20 block rows, the stabilisation diagram, the selection,
  the JSON report);
- ours, full: the same with LSCF on the H1 FRF too (the default when the force is measured);
- strid: pandas.read_csv, then CovarianceDrivenStochasticSID.perform at orders 2..40 with 20
  block rows, Mode.find_modes_from_ss, its StabilizationDiagram's filter and stability test, the
  grouping of stable poles (modal_records.strid_modes). One BLAS thread for both.

Printed: the times, the modes each found, and the ratios strid / ours.

    scripts/bench_modal.py --twin target/release/twin [--repeats 3]
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "python"))
import modal_records as mr  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--twin", required=True)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=3600.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as work:
        record = Path(work) / "hour.csv"
        report = Path(work) / "modes.json"
        mr.write_record(record, args.duration, 0.01, seed=7)
        print(f"record: {args.duration:.0f} s at 100 Hz, 5 channels, {record.stat().st_size / 1e6:.1f} MB")

        def ours(*extra):
            start = time.perf_counter()
            done = subprocess.run([args.twin, "modal", "--data", str(record), "--report",
                                   str(report), *extra], capture_output=True, text=True)
            elapsed = time.perf_counter() - start
            if done.returncode != 0:
                sys.exit(done.stderr)
            modes = json.loads(report.read_text())["record"]
            return elapsed, modes

        def strid():
            start = time.perf_counter()
            frame = pandas.read_csv(record)
            acc = frame[[f"acc{i + 1}" for i in range(5)]].to_numpy().T
            modes = mr.strid_modes(acc, 100.0)
            return time.perf_counter() - start, modes

        timings = {"ours, output-only": [], "ours, full": [], "strid": []}
        found = {}
        for _ in range(args.repeats):
            t, modes = ours("--output-only")
            timings["ours, output-only"].append(t)
            found["ours, output-only"] = [m["frequency"] for m in modes["ssi"]["modes"]]
            t, modes = ours()
            timings["ours, full"].append(t)
            found["ours, full"] = [m["frequency"] for m in modes["input_output"]["modes"]]
            t, modes = strid()
            timings["strid"].append(t)
            found["strid"] = [m[0] for m in modes]
        exact = [m[0] for m in mr.exact_modes()]
        print("exact:", " ".join(f"{f:.4f}" for f in exact), "Hz")
        medians = {name: statistics.median(ts) for name, ts in timings.items()}
        for name, median in medians.items():
            runs = ", ".join(f"{t:.2f}" for t in timings[name])
            print(f"{name:>18}: median {median:.2f} s ({runs}); modes "
                  + " ".join(f"{f:.4f}" for f in found[name]) + " Hz")
        for name in ("ours, output-only", "ours, full"):
            print(f"strid / {name}: {medians['strid'] / medians[name]:.1f}×")
        print(f"load average: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
