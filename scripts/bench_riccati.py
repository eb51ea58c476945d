#!/usr/bin/env python3
"""The peers of numerics::control::solve_care on its criterion bench's problem, in the same run.

The problem (numerics/benches/riccati.rs, `shear_n6_q1e3_light`): the 3-storey shear model of
scripts/riccati_reference.py, m = 5.2 kg, k = 4021 N/m, c = 0.01 Ns/m per storey, states in
metres, Q = 1e3 diag(0, 0, 0, 1, 1, 1), R = 0.1 (n = 6, m = 1). Timed here, each as the median
over `--repeats` batches of `--number` calls, one thread:

- scipy.linalg.solve_continuous_are (X only);
- control.lqr (K, X and the closed-loop poles, as solve_care returns them; python-control's
  default method, SLICOT's SB02MD when slycot is installed, as the project's environment has it).

Ours is the criterion median read from target/criterion (scripts/bench-riccati.sh runs the bench
first). Printed: the three times and the ratios peer / ours. Not run by the tests.

    scripts/bench_riccati.py --criterion target/criterion [--repeats 200] [--number 20]
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import timeit  # noqa: E402
from pathlib import Path  # noqa: E402

import control  # noqa: E402
import scipy  # noqa: E402
import scipy.linalg  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from riccati_reference import shear_model  # noqa: E402

BENCH = "shear_n6_q1e3_light"


def median_seconds(call, repeats: int, number: int) -> float:
    call()  # warm up (imports, LAPACK's first calls)
    return statistics.median(timeit.repeat(call, repeat=repeats, number=number)) / number


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--criterion", type=Path, required=True,
                        help="criterion's output folder (target/criterion)")
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--number", type=int, default=20)
    args = parser.parse_args()

    estimates = args.criterion / "riccati" / BENCH / "new" / "estimates.json"
    ours = json.loads(estimates.read_text())["median"]["point_estimate"] * 1e-9
    a, b, q, r = shear_model(0.01, 1.0, 1e3)
    peers = {
        f"scipy {scipy.__version__} solve_continuous_are": lambda: scipy.linalg.solve_continuous_are(a, b, q, r),
        f"python-control {control.__version__} lqr": lambda: control.lqr(a, b, q, r),
    }
    print(f"problem: {BENCH} (n = 6, m = 1); medians")
    print(f"  {'numerics::control::solve_care':<45} {ours * 1e6:9.1f} µs")
    for name, call in peers.items():
        seconds = median_seconds(call, args.repeats, args.number)
        print(f"  {name:<45} {seconds * 1e6:9.1f} µs   {seconds / ours:6.1f}× ours")


if __name__ == "__main__":
    main()
