"""Driving the shear FMU through fmpy's FMI 2.0 wrapper (`fmpy.fmi2.FMU2Slave`), the data it is
driven with, and the error measure the paper uses. Shared by the tests of this folder.

A run is the one loop of a fixed-step master with first-order input interpolation:

    apply the force of the step (value + slope) → do the step → record the outputs

so the record holds the outputs at t_0 (after initialization) and at the end of every step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.model_description import ModelDescription

#: The examples' communication step, 1/51.2 s = 5/256 s: exact in binary, so k·STEP is exact too.
STEP = 1.0 / 51.2
ACCELERATIONS = ("acc1", "acc2", "acc3")
DISPLACEMENTS = ("disp1", "disp2", "disp3")


@dataclass
class ShearFmu:
    """The FMU archive, its model description and the folder it was extracted to."""

    path: Path
    model_description: ModelDescription
    unzip_dir: Path
    variables: dict = field(init=False)

    def __post_init__(self):
        self.variables = {v.name: v for v in self.model_description.modelVariables}

    @classmethod
    def open(cls, path: Path, unzip_dir: Path) -> "ShearFmu":
        model_description = read_model_description(str(path))
        extract(str(path), unzipdir=str(unzip_dir))
        return cls(path, model_description, unzip_dir)

    def vr(self, name: str) -> int:
        return self.variables[name].valueReference

    def start_value(self, name: str):
        variable = self.variables[name]
        kinds = {"Real": float, "Integer": int, "Boolean": lambda s: str(s).lower() == "true"}
        return kinds[variable.type](variable.start)

    @property
    def model_identifier(self) -> str:
        return self.model_description.coSimulation.modelIdentifier


def set_parameters(slave: FMU2Slave, fmu: ShearFmu, parameters: dict) -> None:
    """Set parameters by name, each with the setter of its type."""
    for name, value in parameters.items():
        variable = fmu.variables[name]
        if variable.type == "Real":
            slave.setReal([variable.valueReference], [float(value)])
        elif variable.type == "Integer":
            slave.setInteger([variable.valueReference], [int(value)])
        elif variable.type == "Boolean":
            slave.setBoolean([variable.valueReference], [bool(value)])
        else:
            raise ValueError(f"{name}: no setter for a {variable.type} variable")


def instantiate(fmu: ShearFmu, parameters: dict, force0: float, instance_name: str = "shear") -> FMU2Slave:
    """Instantiate → set up at t = 0 → set the parameters and the initial force → initialize."""
    slave = FMU2Slave(
        guid=fmu.model_description.guid,
        unzipDirectory=str(fmu.unzip_dir),
        modelIdentifier=fmu.model_identifier,
        instanceName=instance_name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    set_parameters(slave, fmu, parameters)
    slave.setReal([fmu.vr("force")], [float(force0)])
    slave.exitInitializationMode()
    return slave


def run(
    fmu: ShearFmu,
    parameters: dict,
    force0: float,
    values: np.ndarray,
    slopes: np.ndarray,
    outputs=ACCELERATIONS,
) -> np.ndarray:
    """Drive one instance: step k applies `values[k]` with slope `slopes[k]` over [t_k, t_k + STEP].

    Returns the outputs, one row per recorded point: t_0 (after initialization with `force0`) and
    the end of each step, read right after the step with no new input set.
    """
    slave = instantiate(fmu, parameters, force0)
    force_vr = [fmu.vr("force")]
    output_vrs = [fmu.vr(name) for name in outputs]
    rows = [slave.getReal(output_vrs)]
    try:
        for k, (value, slope) in enumerate(zip(values, slopes)):
            slave.setReal(force_vr, [float(value)])
            slave.setRealInputDerivatives(force_vr, [1], [float(slope)])
            slave.doStep(k * STEP, STEP)
            rows.append(slave.getReal(output_vrs))
    finally:
        slave.terminate()
        slave.freeInstance()
    return np.array(rows)


def forward_slopes(force: np.ndarray) -> np.ndarray:
    """Slope of the segment that starts at each sample: what a master interpolating the samples
    linearly gives the FMU over [t_k, t_k+1]."""
    return np.diff(force) / STEP


def run_direct(fmu: ShearFmu, parameters: dict, force: np.ndarray, outputs=ACCELERATIONS) -> np.ndarray:
    """The exact cross-check: on each step the force is the straight line through the two samples
    that bound it, so the outputs recorded at t_k+1 see F_k + slope·STEP = F_k+1 (to rounding)."""
    return run(fmu, parameters, force[0], force[:-1], forward_slopes(force), outputs)


def nmse(reference: np.ndarray, prediction: np.ndarray) -> np.ndarray:
    """The paper's NMSE in percent, per column: 100 / (N var(y)) · Σ (y − ŷ)²."""
    reference = np.asarray(reference)
    n = reference.shape[0]
    return 100.0 * np.sum((reference - np.asarray(prediction)) ** 2, axis=0) / (n * np.var(reference, axis=0))


@dataclass
class Record:
    """A measurement record on the exact 51.2 Hz grid."""

    time: np.ndarray
    force: np.ndarray


def read_record(path: Path) -> Record:
    """Read `time,force,...` and put it on the exact grid k·STEP.

    The CSV prints time with 6 decimals (19.980469 for 1023·5/256 = 19.98046875): fmpy steps to
    exact multiples of the output interval and looks the input up at those instants, so handing it
    the printed times would make it interpolate between samples, up to 5e-7 s away from them.
    """
    data = np.genfromtxt(path, delimiter=",", names=True)
    for column in ("time", "force"):
        if column not in data.dtype.names:
            raise ValueError(f"{path}: no '{column}' column")
    grid = np.arange(len(data)) * STEP
    printed = data["time"]
    if np.max(np.abs(printed - grid)) > 1e-6:
        raise ValueError(f"{path}: time is not the 51.2 Hz grid to the printed precision")
    return Record(time=grid, force=np.asarray(data["force"], dtype=float))


def assert_within(actual: np.ndarray, expected: np.ndarray, relative: float, what: str) -> None:
    """Every column of `actual` within `relative` × the largest |value| of that column of `expected`."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, f"{what}: shapes {actual.shape} and {expected.shape}"
    scale = np.max(np.abs(expected), axis=0)
    deviation = np.max(np.abs(actual - expected), axis=0) / scale
    assert np.all(deviation <= relative), (
        f"{what}: largest deviation per column {np.array2string(deviation, precision=3)} of the column's peak, "
        f"allowed {relative:g}"
    )
