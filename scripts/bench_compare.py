#!/usr/bin/env python3
"""`twin compare` against fmpy's `simulate_fmu` on the same FMU and the same input, in the same
run: dataset1's force, 1023 steps of 1/51.2 s, the shear FMU's three accelerations.

End to end (medians of --repetitions runs, after two untimed ones):

- twin: `twin compare --data data/dataset1.csv --report R.json` as a process: start, read the
  CSV, open the FMU (from the FMU cache, which the untimed runs filled: the first run after an
  FMU is built unpacks it there, about 0.4 ms more), load it, run, compare, write the report,
  exit;
- fmpy, in process: one `fmpy.simulate_fmu("fmu_shear.fmu", ...)` call, the interpreter started
  and fmpy imported beforehand (this favours fmpy: no process start);
- fmpy, as a process: `python -c "import fmpy ...; simulate_fmu(...)"`, the like of the twin
  process.

Excluding the FMU load:

- twin: the master alone, in process, with the FMU already loaded (instantiate, initialise,
  1023 steps with the force replayed as ramps, accelerations recorded), from
  `target/release/examples/bench_master` (orchestrator/examples/bench_master.rs), which also
  times the same calls without the master and the load alone;
- fmpy: `simulate_fmu` on an FMU already extracted, its modelDescription read and an instance
  made; each run sets up, initialises, steps, terminates, then `reset`.

fmpy 0.3.32 is timed as shipped: it cannot set input derivatives on this FMU (a fixed
nine-element buffer, see tests/python/conftest.py), so it sets the force as values; the FMU's
work per step is the same either way. Both wall-clock and CPU time (user + system, of the child
process or of this process) are reported: on a loaded machine the wall clock includes waiting for
a CPU, the CPU time does not. Run through scripts/bench-compare.sh.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
STEP = 1.0 / 51.2  # 5/256 s, exact in binary
OUTPUTS = ["acc1", "acc2", "acc3"]
GOAL = 40.0  # fmpy's process / the twin's process, end to end


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed_process(command: list[str], env: dict) -> tuple[float, float]:
    """Wall and CPU seconds of one child process, which must succeed."""
    cpu = children_cpu()
    start = time.perf_counter()
    completed = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    wall = time.perf_counter() - start
    if completed.returncode != 0:
        sys.exit(f"bench-compare: {' '.join(command)} failed:\n{completed.stderr.decode(errors='replace')}")
    return wall, children_cpu() - cpu


def timed_call(function) -> tuple[float, float]:
    cpu = time.process_time()
    start = time.perf_counter()
    function()
    return time.perf_counter() - start, time.process_time() - cpu


def medians(samples: list[tuple[float, float]]) -> dict:
    return {
        "wall_s": statistics.median(s[0] for s in samples),
        "cpu_s": statistics.median(s[1] for s in samples),
        "runs": len(samples),
    }


def repeat(repetitions: int, run) -> dict:
    for _ in range(2):
        run()
    return medians([run() for _ in range(repetitions)])


def input_signal(data: Path) -> np.ndarray:
    table = np.genfromtxt(data, delimiter=",", names=True)
    if table.dtype.names is None or "force" not in table.dtype.names:
        sys.exit(f"bench-compare: {data}: no 'force' column")
    signal = np.zeros(len(table), dtype=[("time", np.float64), ("force", np.float64), ("control_force", np.float64)])
    signal["time"] = np.arange(len(table)) * STEP
    signal["force"] = table["force"]
    return signal


FMPY_PROCESS = """
import sys
import numpy as np
import fmpy
fmu, data, step = sys.argv[1], sys.argv[2], float(sys.argv[3])
table = np.genfromtxt(data, delimiter=",", names=True)
signal = np.zeros(len(table), dtype=[("time", float), ("force", float), ("control_force", float)])
signal["time"] = np.arange(len(table)) * step
signal["force"] = table["force"]
result = fmpy.simulate_fmu(fmu, input=signal, output=["acc1", "acc2", "acc3"], output_interval=step,
                           stop_time=signal["time"][-1])
assert len(result) == len(table), len(result)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repetitions", type=int, default=21)
    parser.add_argument("--data", type=Path, default=ROOT / "data" / "dataset1.csv")
    parser.add_argument("--twin", type=Path, default=TARGET / "release" / "twin")
    parser.add_argument("--fmu", type=Path, default=TARGET / "fmu" / "fmu_shear.fmu")
    parser.add_argument("--master-bench", type=Path, default=TARGET / "release" / "examples" / "bench_master")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    if args.repetitions < 1:
        sys.exit("bench-compare: --repetitions must be at least 1")
    for path, how in ((args.twin, "scripts/build-fmus.sh"), (args.fmu, "scripts/build-fmus.sh"),
                      (args.master_bench, "cargo build --release -p orchestrator --example bench_master"),
                      (args.data, "a measurement file")):
        if not path.is_file():
            sys.exit(f"bench-compare: {path} does not exist: {how}")

    import fmpy
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    env = dict(os.environ, TWIN_FMU_DIR=str(args.fmu.parent))
    env.pop("TWIN_FMU_LOG", None)
    signal = input_signal(args.data)
    steps = len(signal) - 1
    stop_time = steps * STEP
    n = args.repetitions

    with tempfile.TemporaryDirectory(prefix="bench-compare-") as scratch:
        report = Path(scratch) / "report.json"
        twin_command = [str(args.twin), "compare", "--data", str(args.data), "--report", str(report)]
        twin_end_to_end = repeat(n, lambda: timed_process(twin_command, env))
        if not report.is_file():
            sys.exit("bench-compare: twin compare wrote no report")

        def fmpy_call():
            result = fmpy.simulate_fmu(str(args.fmu), input=signal, output=OUTPUTS, output_interval=STEP, stop_time=stop_time)
            assert len(result) == len(signal), len(result)

        fmpy_in_process = repeat(n, lambda: timed_call(fmpy_call))
        fmpy_command = [sys.executable, "-c", FMPY_PROCESS, str(args.fmu), str(args.data), repr(STEP)]
        fmpy_as_process = repeat(n, lambda: timed_process(fmpy_command, env))

        # fmpy without the load: extracted, described and instantiated once.
        unzipdir = extract(str(args.fmu), unzipdir=str(Path(scratch) / "fmu"))
        model_description = read_model_description(unzipdir)
        slave = FMU2Slave(guid=model_description.guid, unzipDirectory=unzipdir,
                          modelIdentifier=model_description.coSimulation.modelIdentifier, instanceName="bench")
        slave.instantiate()

        def fmpy_loop():
            result = fmpy.simulate_fmu(unzipdir, model_description=model_description, fmu_instance=slave, input=signal,
                                       output=OUTPUTS, output_interval=STEP, stop_time=stop_time)
            slave.reset()
            assert len(result) == len(signal), len(result)

        fmpy_loop_only = repeat(n, lambda: timed_call(fmpy_loop))
        slave.freeInstance()

    completed = subprocess.run([str(args.master_bench), "--data", str(args.data), "--repetitions", str(n)],
                               capture_output=True, text=True, env=env)
    if completed.returncode != 0:
        sys.exit(f"bench-compare: {args.master_bench} failed:\n{completed.stderr}")
    rust = json.loads(completed.stdout)

    figures = {
        "steps": steps,
        "repetitions": n,
        "load_average": os.getloadavg(),
        "cpus": os.cpu_count(),
        "twin_compare_process": twin_end_to_end,
        "fmpy_simulate_fmu_call": fmpy_in_process,
        "fmpy_simulate_fmu_process": fmpy_as_process,
        "fmpy_loop_only": fmpy_loop_only,
        "twin_in_process": rust,
    }
    ratio = {
        "end_to_end_wall": fmpy_in_process["wall_s"] / twin_end_to_end["wall_s"],
        "end_to_end_cpu": fmpy_in_process["cpu_s"] / twin_end_to_end["cpu_s"],
        "process_to_process_wall": fmpy_as_process["wall_s"] / twin_end_to_end["wall_s"],
        "process_to_process_cpu": fmpy_as_process["cpu_s"] / twin_end_to_end["cpu_s"],
        "excluding_load_wall": fmpy_loop_only["wall_s"] / rust["master_run_s"],
    }
    figures["ratio_fmpy_over_twin"] = ratio

    ms = lambda s: f"{1e3 * s:9.2f} ms"  # noqa: E731
    print(f"bench-compare: {args.data.name}, {steps} steps of 1/51.2 s, medians of {n} runs; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print(f"{'':44} {'wall':>12} {'CPU':>12}")
    print("end to end")
    print(f"  {'twin compare (process, report written)':42} {ms(twin_end_to_end['wall_s'])} {ms(twin_end_to_end['cpu_s'])}")
    print(f"  {'fmpy simulate_fmu (call in a warm Python)':42} {ms(fmpy_in_process['wall_s'])} {ms(fmpy_in_process['cpu_s'])}")
    print(f"  {'fmpy simulate_fmu (python -c, a process)':42} {ms(fmpy_as_process['wall_s'])} {ms(fmpy_as_process['cpu_s'])}")
    print(f"  {'ratio fmpy call / twin':42} {ratio['end_to_end_wall']:11.1f}× {ratio['end_to_end_cpu']:11.1f}×")
    print(f"  {'ratio fmpy process / twin':42} {ratio['process_to_process_wall']:11.1f}× {ratio['process_to_process_cpu']:11.1f}×")
    print("excluding the FMU load (wall)")
    print(f"  {'twin master run (in process)':42} {ms(rust['master_run_s'])}")
    print(f"  {'  the same FMU calls without the master':42} {ms(rust['direct_run_s'])}")
    print(f"  {'fmpy simulate_fmu, instance reused':42} {ms(fmpy_loop_only['wall_s'])}")
    print(f"  {'ratio fmpy / twin master':42} {ratio['excluding_load_wall']:11.1f}×")
    print(f"  {'twin FMU load alone (FMU cache + dlopen)':42} {ms(rust['fmu_load_s'])}")
    # The goal compares like with like: the twin's process with fmpy's process (issue 16).
    verdict = lambda r: "met" if r >= GOAL else "NOT met"  # noqa: E731
    print(f"goal fmpy process / twin process ≥ {GOAL:.0f}× end to end: "
          f"{verdict(ratio['process_to_process_cpu'])} by CPU time "
          f"({ratio['process_to_process_cpu']:.1f}×), "
          f"{verdict(ratio['process_to_process_wall'])} by wall clock "
          f"({ratio['process_to_process_wall']:.1f}×, load average {os.getloadavg()[0]:.2f})")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
