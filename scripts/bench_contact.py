#!/usr/bin/env python3
"""Times `twin compare --twin T.ssp --data long.csv --report R.json` as a process for twins that
differ only in their physics parameter set (resources/physics.ssv of the calibrated twin):
linear; the bumper between floors 2 and 3 (0.5 mm, 9000 N/m, both sides) with the
default integrator (exact flows per contact region) and with `integrator` = 1 (64 RK4 sub-steps
split at the gap); cubic stiffness on storey 3 (1e9 N/m^3) with the default integrator
(error-controlled Dormand-Prince 5(4)) and with `integrator` = 1. The twins run in turn, one of
each per round, after one untimed round; medians of wall and CPU (user + system of the child)
seconds over --repetitions rounds; ratios to the linear twin, and of the old integrator to the
new. The reports' worst-floor NMSE is printed too: the two integrators of one twin must agree.
Run through scripts/bench-contact.sh."""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import time
import zipfile
from pathlib import Path

GOAL = 3.0  # contact twin / linear twin, end to end

CONTACT = [
    ("contact23_enabled", "Boolean", "true"),
    ("contact23_gap", "Real", "5e-4"),
    ("contact23_stiffness", "Real", "9000"),
    ("contact23_side", "Integer", "0"),
]
CUBIC = [("cubic3_enabled", "Boolean", "true"), ("cubic3_stiffness", "Real", "1e9")]
OLD = [("integrator", "Integer", "1")]

TWINS = {
    "linear": [],
    "contact": CONTACT,
    "contact, 64 RK4 sub-steps": CONTACT + OLD,
    "cubic": CUBIC,
    "cubic, 64 RK4 sub-steps": CUBIC + OLD,
}


def with_parameters(linear: Path, out: Path, parameters: list[tuple[str, str, str]]) -> None:
    """A copy of the archive whose physics.ssv sets `parameters`."""
    lines = "".join(
        f'    <ssv:Parameter name="{name}"><ssv:{kind} value="{value}"/></ssv:Parameter>\n'
        for name, kind, value in parameters
    )
    with zipfile.ZipFile(linear) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "resources/physics.ssv":
                text = data.decode()
                if "<ssv:Parameters>" not in text:
                    raise SystemExit("physics.ssv has no <ssv:Parameters> element")
                text = text.replace("<ssv:Parameters>\n", "<ssv:Parameters>\n" + lines, 1)
                data = text.encode()
            dst.writestr(item, data)


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(command: list[str]) -> tuple[float, float]:
    cpu = children_cpu()
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start, children_cpu() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--twin-bin", required=True)
    parser.add_argument("--work", required=True, type=Path)
    parser.add_argument("--record", required=True)
    parser.add_argument("--repetitions", type=int, default=5)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()

    paths = {}
    for i, (name, parameters) in enumerate(TWINS.items()):
        paths[name] = args.work / f"twin{i}.ssp"
        with_parameters(args.work / "linear.ssp", paths[name], parameters)
    samples = sum(1 for _ in open(args.record)) - 1

    def compare(name: str) -> tuple[float, float]:
        report = args.work / f"report-{list(TWINS).index(name)}.json"
        return timed([args.twin_bin, "compare", "--twin", str(paths[name]), "--data", args.record,
                      "--report", str(report)])

    for name in TWINS:  # untimed round
        compare(name)
    wall = {name: [] for name in TWINS}
    cpu = {name: [] for name in TWINS}
    for _ in range(args.repetitions):
        for name in TWINS:
            w, c = compare(name)
            wall[name].append(w)
            cpu[name].append(c)

    def worst_nmse(name: str) -> float:
        report = json.loads((args.work / f"report-{list(TWINS).index(name)}.json").read_text())
        return max(report["nmse"])

    med = {name: (statistics.median(wall[name]), statistics.median(cpu[name])) for name in TWINS}
    print(f"twin compare on {samples} samples ({samples / 51.2:.0f} s at 51.2 Hz), "
          f"medians of {args.repetitions} rounds")
    print(f"{'twin':<28} {'wall s':>8} {'cpu s':>8} {'us/sample':>10} {'x linear (cpu)':>15} {'NMSE % worst':>13}")
    base = med["linear"][1]
    for name in TWINS:
        w, c = med[name]
        print(f"{name:<28} {w:8.3f} {c:8.3f} {1e6 * c / samples:10.3f} {c / base:15.2f} {worst_nmse(name):13.4g}")
    contact_ratio = med["contact"][1] / base
    print(f"contact / linear: {contact_ratio:.2f}x (cpu), {med['contact'][0] / med['linear'][0]:.2f}x (wall); "
          f"goal <= {GOAL:.0f}x: {'met' if contact_ratio <= GOAL else 'NOT met'}")
    print(f"contact, 64 RK4 sub-steps / contact: {med['contact, 64 RK4 sub-steps'][1] / med['contact'][1]:.2f}x (cpu)")
    print(f"cubic, 64 RK4 sub-steps / cubic: {med['cubic, 64 RK4 sub-steps'][1] / med['cubic'][1]:.2f}x (cpu)")
    if args.json:
        args.json.write_text(json.dumps({"samples": samples, "wall": wall, "cpu": cpu}, indent=2))


if __name__ == "__main__":
    main()
