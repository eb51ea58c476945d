"""Run an FMI 2.0 co-simulation FMU under fmpy and write its outputs as CSV: the reference that
`twin run MODEL.fmu` is compared with.

    .venv/bin/python scripts/fmpy_run.py MODEL.fmu --output OUT.csv [--start T0] [--stop T1]
        [--step H] [--input IN.csv] [--set NAME=VALUE ...] [--set-input-derivatives]

This is `fmpy.simulate_fmu(MODEL.fmu, start_time=T0, stop_time=T1, step_size=H,
output_interval=H, input=..., start_values=..., output=<the outputs>)`:

- T0 and T1 default to the DefaultExperiment (fmpy's own defaults: 0 and T0 + 1 without one);
  H defaults to the DefaultExperiment's stepSize, passed explicitly (fmpy, left to itself,
  would double it until the run has at most 1000 intervals). Without a stepSize, fmpy chooses.
- IN.csv: a header line, then rows; the first column is the time, the others are named like the
  FMU's inputs (or tunable parameters). Real columns are read as floats, Integer and Enumeration
  columns as integers, Boolean columns as 0/1/true/false. fmpy interpolates Real inputs linearly
  between rows (a repeated time is a step in the signal) and holds the others from the last row
  at or before the time.
- --set NAME=VALUE (repeatable): a start value, converted by the variable's type.
- --set-input-derivatives: fmpy sends first-order input derivatives (FMUs with
  canInterpolateInputs="true" only). fmpy 0.3.32 keeps them in a buffer of exactly nine elements
  and fails with "Can only assign sequence of same size" for any other number of continuous
  inputs; this script sizes that buffer to the number of inputs (as the test fixture
  `fmpy_input_derivatives_fixed` in tests/python/conftest.py does) and changes nothing else.

OUT.csv: `time,<every output in modelDescription order>`, one row per row of fmpy's result.
Reals and the time are written with %.17g (they read back bit for bit), Integers and
Enumerations as integers, Booleans as 0/1. String outputs are left out: fmpy does not record them.
"""

from __future__ import annotations

import argparse
import csv
import sys

import numpy as np

import fmpy
import fmpy.simulation

INT_TYPES = {"Integer", "Enumeration"}


def parse_bool(text: str) -> bool:
    value = text.strip().lower()
    if value in {"1", "true"}:
        return True
    if value in {"0", "false"}:
        return False
    raise ValueError(f"'{text}' is not a Boolean (0, 1, true or false)")


def parse_value(variable, text: str):
    if variable.type == "Real":
        return float(text)
    if variable.type in INT_TYPES:
        return int(text.strip())
    if variable.type == "Boolean":
        return parse_bool(text)
    if variable.type == "String":
        return text
    raise ValueError(f"variable '{variable.name}' has the unsupported type {variable.type}")


def dtype_of(variable):
    if variable.type == "Real":
        return np.float64
    if variable.type in INT_TYPES:
        return np.int32
    if variable.type == "Boolean":
        return np.bool_
    raise ValueError(f"input '{variable.name}' is a {variable.type}: fmpy cannot take it from a CSV signal")


def read_input(path: str, variables: dict) -> np.ndarray:
    """The input CSV as the structured array fmpy's `input` takes."""
    with open(path, newline="") as f:
        rows = [row for row in csv.reader(f) if row and any(cell.strip() for cell in row)]
    if len(rows) < 2:
        raise SystemExit(f"fmpy_run: {path}: expected a header line and at least one row")
    header = [name.strip() for name in rows[0]]
    fields = [("time", np.float64)]
    columns = []
    for name in header[1:]:
        variable = variables.get(name)
        if variable is None or not (variable.causality == "input" or variable.variability == "tunable"):
            raise SystemExit(f"fmpy_run: {path}: the column '{name}' is not an input of the FMU")
        fields.append((name, dtype_of(variable)))
        columns.append(variable)
    data = []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise SystemExit(f"fmpy_run: {path}:{line}: {len(row)} columns, the header has {len(header)}")
        try:
            data.append((float(row[0]),) + tuple(parse_value(v, cell) for v, cell in zip(columns, row[1:])))
        except ValueError as error:
            raise SystemExit(f"fmpy_run: {path}:{line}: {error}")
    times = np.array([r[0] for r in data])
    if np.any(np.diff(times) < 0):
        raise SystemExit(f"fmpy_run: {path}: the time column decreases")
    return np.array(data, dtype=fields)


def size_input_derivatives():
    """fmpy 0.3.32's Input holds the derivatives in `(value_type * 9)()`; size it to the inputs."""
    original_init = fmpy.simulation.Input.__init__

    def init(self, *args, **kwargs):
        original_init(self, *args, **kwargs)
        self.continuous = [
            info._replace(derivatives=(info.derivatives._type_ * len(info.values))())
            for info in getattr(self, "continuous", [])
        ]

    fmpy.simulation.Input.__init__ = init


def format_cell(value, kind: str) -> str:
    if kind == "Real":
        return "%.17g" % float(value)
    if kind == "Boolean":
        return "1" if value else "0"
    return "%d" % int(value)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("fmu")
    parser.add_argument("--output", required=True, help="the CSV to write")
    parser.add_argument("--start", type=float)
    parser.add_argument("--stop", type=float)
    parser.add_argument("--step", type=float)
    parser.add_argument("--input", help="CSV: time, then columns named like the inputs")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a start value")
    parser.add_argument("--set-input-derivatives", action="store_true")
    args = parser.parse_args(argv)

    md = fmpy.read_model_description(args.fmu)
    if md.fmiVersion != "2.0" or md.coSimulation is None:
        raise SystemExit(f"fmpy_run: {args.fmu} is not an FMI 2.0 co-simulation FMU")
    variables = {v.name: v for v in md.modelVariables}

    start_values = {}
    for item in args.set:
        name, sep, text = item.partition("=")
        if not sep:
            raise SystemExit(f"fmpy_run: --set {item}: expected NAME=VALUE")
        if name not in variables:
            raise SystemExit(f"fmpy_run: --set {item}: the FMU has no variable '{name}'")
        try:
            start_values[name] = parse_value(variables[name], text)
        except ValueError as error:
            raise SystemExit(f"fmpy_run: --set {item}: {error}")

    step = args.step
    if step is None and md.defaultExperiment is not None and md.defaultExperiment.stepSize is not None:
        step = float(md.defaultExperiment.stepSize)
    if step is not None and not step > 0:
        raise SystemExit(f"fmpy_run: the step must be positive (got {step})")

    signals = read_input(args.input, variables) if args.input else None

    outputs = [v for v in md.modelVariables if v.causality == "output" and v.type != "String"]
    if args.set_input_derivatives:
        size_input_derivatives()

    result = fmpy.simulate_fmu(
        args.fmu,
        start_time=args.start,
        stop_time=args.stop,
        step_size=step,
        output_interval=step,
        input=signals,
        start_values=start_values,
        output=[v.name for v in outputs],
        set_input_derivatives=args.set_input_derivatives,
    )

    kinds = ["Real"] + ["Boolean" if v.type == "Boolean" else "Real" if v.type == "Real" else "Integer" for v in outputs]
    names = ["time"] + [v.name for v in outputs]
    with open(args.output, "w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(names)
        for row in result:
            writer.writerow([format_cell(row[name], kind) for name, kind in zip(names, kinds)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
