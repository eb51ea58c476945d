"""`twin run` against fmpy's `simulate_fmu`, the same FMU, inputs and step, in the same run.

Timed, median of N repetitions each:
- twin: the `twin run` process end to end (unpack, load, run, write the CSV);
- fmpy call: `fmpy.simulate_fmu(...)` inside an already running Python (unpack, load, run; no
  interpreter start), the fairest figure for fmpy;
- fmpy process: `python scripts/fmpy_run.py`, end to end as a user runs it from a shell.
Before timing, both outputs are compared row by row (scripts/fmpy_run.py's CSV against twin's).

    .venv/bin/python scripts/bench_run.py [--repetitions 7]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import csv
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
sys.path.insert(0, str(ROOT / "scripts"))

import fmpy  # noqa: E402
import fmpy_run  # noqa: E402  (the reference runner's input reading)


def force_csv(directory: Path) -> Path:
    path = directory / "force.csv"
    with open(ROOT / "data" / "dataset1.csv") as f, open(path, "w") as out:
        rows = list(csv.reader(f))
        out.write("time,force\n")
        for row in rows[1:]:
            out.write(f"{row[0]},{row[1]}\n")
    return path


def cases(directory: Path):
    force = str(force_csv(directory))
    inputs = ROOT / "tests" / "c-fmus" / "inputs"
    return [
        ("fmu_shear, dataset1 force, 1024 steps", TARGET / "fmu" / "fmu_shear.fmu",
         ["--input", force, "--stop", "20", "--step", "0.01953125"]),
        ("shear_container (fmu-manipulation-toolbox), 1024 steps", TARGET / "third-party" / "shear_container.fmu",
         ["--input", force, "--stop", "20", "--step", "0.01953125"]),
        ("BouncingBall (C), 300 steps", TARGET / "c-fmus" / "BouncingBall.fmu", []),
        ("Discrete (C), input events", TARGET / "c-fmus" / "Discrete.fmu", ["--input", str(inputs / "Discrete.csv")]),
    ]


def simulation_call(fmu: Path, extra: list[str]):
    """`simulate_fmu` as scripts/fmpy_run.py calls it, inputs read beforehand."""
    md = fmpy.read_model_description(str(fmu))
    variables = {v.name: v for v in md.modelVariables}
    options = dict(zip(extra[::2], extra[1::2]))
    step = float(options.get("--step", md.defaultExperiment.stepSize))
    signals = fmpy_run.read_input(options["--input"], variables) if "--input" in options else None
    outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type != "String"]
    stop = float(options["--stop"]) if "--stop" in options else None
    def call():
        with contextlib.redirect_stdout(io.StringIO()):  # fmpy prints its warnings
            fmpy.simulate_fmu(str(fmu), stop_time=stop, step_size=step, output_interval=step,
                              input=signals, output=outputs)
    return call


def timed(run, repetitions: int) -> float:
    samples = []
    for _ in range(repetitions):
        start = time.perf_counter()
        run()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def rows(path: Path):
    with open(path) as f:
        return list(csv.reader(f))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repetitions", type=int, default=7)
    args = parser.parse_args()
    twin = TARGET / "release" / "twin"
    print(f"{'case':58} {'twin run':>10} {'fmpy call':>10} {'fmpy proc':>10} {'call/twin':>9} {'proc/twin':>9}")
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        for label, fmu, extra in cases(scratch):
            ours, theirs = scratch / "twin.csv", scratch / "fmpy.csv"
            twin_cmd = [str(twin), "run", str(fmu), "--output", str(ours), *extra]
            fmpy_cmd = [sys.executable, str(ROOT / "scripts" / "fmpy_run.py"), str(fmu), "--output", str(theirs), *extra]
            subprocess.run(twin_cmd, check=True, capture_output=True)
            subprocess.run(fmpy_cmd, check=True, capture_output=True)
            a, b = rows(ours), rows(theirs)
            if len(a) != len(b):
                agreement = f"   rows differ: {len(a) - 1} against fmpy's {len(b) - 1}!"
            else:
                worst = 0.0  # the largest difference in a column, relative to the column's largest value
                for c in b[0]:
                    ours_c = [float(x[a[0].index(c)]) for x in a[1:]]
                    theirs_c = [float(y[b[0].index(c)]) for y in b[1:]]
                    scale = max(max(map(abs, theirs_c)), 1e-300)
                    worst = max(worst, max(abs(p - q) for p, q in zip(ours_c, theirs_c)) / scale)
                agreement = ("   same rows, bit-identical" if worst == 0
                             else f"   same rows, largest difference {worst:.1e} of the column's peak")
                if worst and fmpy.read_model_description(str(fmu)).coSimulation.canInterpolateInputs:
                    agreement += " (the FMU interpolates inputs: twin sends the slope, fmpy by default does not)"
            call = simulation_call(fmu, extra)
            t_twin = timed(lambda: subprocess.run(twin_cmd, check=True, capture_output=True), args.repetitions)
            t_call = timed(call, args.repetitions)
            t_proc = timed(lambda: subprocess.run(fmpy_cmd, check=True, capture_output=True), max(3, args.repetitions // 2))
            print(f"{label:58} {t_twin*1e3:8.1f}ms {t_call*1e3:8.1f}ms {t_proc*1e3:8.1f}ms "
                  f"{t_call/t_twin:8.1f}× {t_proc/t_twin:8.1f}×" + agreement)


if __name__ == "__main__":
    main()
