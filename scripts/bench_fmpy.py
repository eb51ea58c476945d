#!/usr/bin/env python3
"""Time fmpy's `simulate_fmu` on the shear FMU: one record of dataset1's force, 1024 steps of
1/51.2 s (0 → 20 s), repeated; report the median seconds per run and µs per step.

Two ways of running it are timed:

- end to end: `simulate_fmu("fmu_shear.fmu", ...)` as a user calls it: unzip, read and validate
  the modelDescription, load the library, instantiate, initialize, 1024 steps, free;
- loop only: the FMU extracted, its modelDescription read and one instance made beforehand;
  each run is `simulate_fmu(..., fmu_instance=...)` (set up, initialize, 1024 steps, terminate)
  then `reset`, the closest match to a 1024-step record through the C ABI.

Stock fmpy 0.3.32 is timed as shipped: `set_input_derivatives=True` raises a ValueError on this
FMU (a fixed nine-element derivative buffer, see tests/python/conftest.py), so the force is set
as values only; the FMU's work per step is the same either way.

With --criterion-estimates, also reads criterion's estimates.json of our own benchmark (median
ns of one 1024-step record) and prints both per-step times, steps per second and the ratio
fmpy / ours. Run through scripts/bench-step.sh, which runs both in the same run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import fmpy
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

ROOT = Path(__file__).resolve().parents[1]
STEP = 1.0 / 51.2  # 5/256 s, exact in binary
STEPS = 1024
OUTPUTS = ["acc1", "acc2", "acc3"]


def read_force(path: Path) -> np.ndarray:
    data = np.genfromtxt(path, delimiter=",", names=True)
    if data.dtype.names is None or "force" not in data.dtype.names:
        raise SystemExit(f"{path}: no 'force' column")
    if len(data) != STEPS:
        raise SystemExit(f"{path}: {len(data)} samples, expected {STEPS}")
    return np.asarray(data["force"], dtype=float)


def input_signal(force: np.ndarray) -> np.ndarray:
    # The exact grid k·STEP: fmpy looks the input up at exact multiples of the output interval.
    signal = np.zeros(len(force), dtype=[("time", np.float64), ("force", np.float64), ("control_force", np.float64)])
    signal["time"] = np.arange(len(force)) * STEP
    signal["force"] = force
    return signal


def timed_runs(run, repetitions: int) -> tuple[list[float], np.ndarray]:
    """Warm up once, then time `repetitions` runs; every run must give the same record."""
    first = run()
    times = []
    for _ in range(repetitions):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
        if not np.array_equal(result, first):
            raise SystemExit("two runs of the same record gave different outputs: not one thing being measured")
    if first.shape != (STEPS + 1, len(OUTPUTS)):
        raise SystemExit(f"expected {STEPS + 1} recorded points, got {first.shape[0]}")
    return times, first


def record_array(result) -> np.ndarray:
    return np.stack([result[name] for name in OUTPUTS], axis=1)


def bench(fmu_path: Path, force: np.ndarray, repetitions: int) -> dict:
    signal = input_signal(force)
    stop_time = STEPS * STEP
    common = dict(input=signal, output=OUTPUTS, output_interval=STEP, stop_time=stop_time)

    def end_to_end():
        return record_array(fmpy.simulate_fmu(str(fmu_path), **common))

    model_description = read_model_description(str(fmu_path))
    with tempfile.TemporaryDirectory() as unzip_dir:
        extract(str(fmu_path), unzipdir=unzip_dir)
        instance = FMU2Slave(
            guid=model_description.guid,
            unzipDirectory=unzip_dir,
            modelIdentifier=model_description.coSimulation.modelIdentifier,
            instanceName="bench",
        )
        instance.instantiate()

        def loop_only():
            result = fmpy.simulate_fmu(unzip_dir, model_description=model_description, fmu_instance=instance, **common)
            instance.reset()
            return record_array(result)

        try:
            loop_times, loop_record = timed_runs(loop_only, repetitions)
        finally:
            instance.freeInstance()
    e2e_times, e2e_record = timed_runs(end_to_end, repetitions)
    if not np.array_equal(loop_record, e2e_record):
        raise SystemExit("the two ways of running gave different records")

    def summary(times):
        median = statistics.median(times)
        return {"median_s": median, "min_s": min(times), "max_s": max(times), "us_per_step": median / STEPS * 1e6}

    return {
        "fmpy_version": fmpy.__version__,
        "fmu": str(fmu_path),
        "steps": STEPS,
        "step_size_s": STEP,
        "repetitions": repetitions,
        "end_to_end": summary(e2e_times),
        "loop_only": summary(loop_times),
    }


def criterion_median_ns(path: Path) -> float:
    estimates = json.loads(path.read_text())
    try:
        return float(estimates["median"]["point_estimate"])
    except (KeyError, TypeError, ValueError) as error:
        raise SystemExit(f"{path}: no median.point_estimate ({error})")


def print_report(results: dict, ours_ns: float | None) -> None:
    print(f"fmpy {results['fmpy_version']} simulate_fmu, {results['steps']} steps of {results['step_size_s']:g} s, "
          f"median of {results['repetitions']} runs")
    for key, label in (("end_to_end", "end to end (.fmu file)"), ("loop_only", "loop only (instance reused)")):
        r = results[key]
        print(f"  {label:30s} {r['median_s'] * 1e3:9.3f} ms/run  {r['us_per_step']:9.3f} µs/step  "
              f"{1e6 / r['us_per_step']:12.0f} steps/s")
    if ours_ns is None:
        return
    ours_us = ours_ns / STEPS / 1e3
    print(f"ours: criterion fmi2DoStep/record_1024_steps, median {ours_ns / 1e6:.3f} ms/record")
    print(f"  {'through the C ABI':30s} {ours_ns / 1e6:9.3f} ms/run  {ours_us:9.3f} µs/step  "
          f"{1e6 / ours_us:12.0f} steps/s")
    for key, label in (("loop_only", "loop only"), ("end_to_end", "end to end")):
        print(f"ratio fmpy ({label}) / ours: {results[key]['us_per_step'] / ours_us:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", type=Path, default=ROOT / "target" / "fmu" / "fmu_shear.fmu")
    parser.add_argument("--data", type=Path, default=ROOT / "data" / "dataset1.csv")
    parser.add_argument("--repetitions", type=int, default=15)
    parser.add_argument("--json", type=Path, help="also write the figures to this file")
    parser.add_argument("--criterion-estimates", type=Path,
                        help="criterion's estimates.json of fmi2DoStep/record_1024_steps, to compare with")
    args = parser.parse_args()

    if not args.fmu.is_file():
        raise SystemExit(f"{args.fmu} does not exist: run scripts/build-fmus.sh")
    if args.repetitions < 1:
        raise SystemExit("--repetitions must be at least 1")
    ours_ns = criterion_median_ns(args.criterion_estimates) if args.criterion_estimates else None

    results = bench(args.fmu, read_force(args.data), args.repetitions)
    if ours_ns is not None:
        ours_us = ours_ns / STEPS / 1e3
        results["ours"] = {"median_ns_per_record": ours_ns, "us_per_step": ours_us, "steps_per_s": 1e6 / ours_us}
        results["ratio_fmpy_loop_only_to_ours"] = results["loop_only"]["us_per_step"] / ours_us
        results["ratio_fmpy_end_to_end_to_ours"] = results["end_to_end"]["us_per_step"] / ours_us
    print_report(results, ours_ns)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    sys.exit(main())
