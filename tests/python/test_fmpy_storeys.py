"""The shear FMU for any number of storeys and either excitation, as `twin init --storeys N
--excitation force:K|base --nominal NOMINAL.json` writes it: fmpy's `validate_fmu` finds no
problem, and the FMU driven by fmpy (`fmpy.fmi2.FMU2Slave`) equals an independent solution of
`M ÿ + C ẏ + K y = L u` — the exact discretisation of the continuous model with the input held
over each step, from `scipy.linalg.expm` — for N = 1, 2, 3, 5, 10, 20.

The FMU is one library for every N: its structure comes from `resources/structure.json`, its
variables from the modelDescription written for it. Under a force at floor K the accelerometers
read ÿ; under ground acceleration the model is in coordinates relative to the ground and the
accelerometers read the absolute ÿ + a_g.
"""

from __future__ import annotations

import json
import os
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from conftest import run_twin, run_twin_ok

ROOT = Path(__file__).resolve().parents[2]
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
STEP = 1.0 / 51.2
STEPS = 1024

#: Largest difference between the FMU and the exact discretisation, relative to the largest
#: |value| of the same output over the run, over every floor's acceleration and displacement.
#: Measured: 3.7e-8 at most (N = 3, force:1; 3.0e-9 to 3.7e-8 over the cases below), RK4's
#: truncation error at 64 sub-steps per step against expm; the bar is 2e-7, a margin of about
#: 5, far below what a wrong matrix entry, load or output convention gives (1e-2 or more).
RELATIVE_BAR = 2e-7

CASES = [
    (1, "force:1"),
    (1, "base"),
    (2, "force:2"),
    (2, "base"),
    (3, "force:1"),
    (3, "force:3"),
    (3, "base"),
    (5, "force:2"),
    (5, "base"),
    (10, "force:7"),
    (10, "base"),
    (20, "force:1"),
    (20, "base"),
]


def nominal(storeys: int, seed: int) -> dict:
    """Floors and storeys that all differ (so a swapped index shows): m ~ U(4, 6) kg,
    c ~ U(0.5, 5) N s/m, k ~ U(3000, 5000) N/m."""
    rng = np.random.default_rng(seed)
    return {
        "m": rng.uniform(4.0, 6.0, storeys).tolist(),
        "c": rng.uniform(0.5, 5.0, storeys).tolist(),
        "k": rng.uniform(3000.0, 5000.0, storeys).tolist(),
    }


def make_fmu(twin_binary: Path, storeys: int, excitation: str, values: dict, folder: Path) -> Path:
    """The shear FMU inside the twin that `twin init` writes for this structure."""
    nominal_path = folder / "nominal.json"
    nominal_path.write_text(json.dumps(values))
    twin = folder / "twin.ssp"
    run_twin_ok(twin_binary, "init", "--storeys", str(storeys), "--excitation", excitation,
                "--nominal", str(nominal_path), "--out", str(twin), timeout=120)
    fmu = folder / "fmu_shear.fmu"
    with zipfile.ZipFile(twin) as archive, archive.open("resources/fmu_shear.fmu") as source:
        fmu.write_bytes(source.read())
    return fmu


def excitation_signal(storeys: int, base: bool) -> np.ndarray:
    """A deterministic broadband input: sines from 0.1 to 20 Hz, about 1 N (0.5 m/s² at the base)."""
    rng = np.random.default_rng(100 + storeys)
    t = np.arange(STEPS) * STEP
    frequencies = np.linspace(0.1, 20.0, 60)
    phases = rng.uniform(0.0, 2 * np.pi, frequencies.size)
    u = np.sin(2 * np.pi * np.outer(t, frequencies) + phases).sum(axis=1) / np.sqrt(frequencies.size / 2)
    return (0.5 if base else 1.0) * u


def reference(values: dict, excitation: str, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute accelerations and relative displacements at t_k (after the input u_k is set),
    the input held over each step: exact discretisation with expm."""
    m, c, k = (np.asarray(values[key]) for key in ("m", "c", "k"))
    n = m.size
    stiffness = np.zeros((n, n))
    damping = np.zeros((n, n))
    for s in range(n):  # storey s joins floor s − 1 (the ground for s = 0) and floor s
        for matrix, value in ((stiffness, k[s]), (damping, c[s])):
            matrix[s, s] += value
            if s > 0:
                matrix[s - 1, s - 1] += value
                matrix[s, s - 1] -= value
                matrix[s - 1, s] -= value
    m_inv = np.diag(1.0 / m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-m_inv @ stiffness, -m_inv @ damping]])
    load = np.zeros(n)
    if excitation == "base":
        load[:] = -1.0  # −M 1 a_g, divided by M
    else:
        load[int(excitation.split(":")[1]) - 1] = 1.0 / m[int(excitation.split(":")[1]) - 1]
    b = np.concatenate([np.zeros(n), load])
    augmented = np.zeros((2 * n + 1, 2 * n + 1))
    augmented[: 2 * n, : 2 * n] = a
    augmented[: 2 * n, 2 * n] = b
    step = scipy.linalg.expm(augmented * STEP)
    phi, gamma = step[: 2 * n, : 2 * n], step[: 2 * n, 2 * n]
    x = np.zeros(2 * n)
    acc, disp = [], []
    for uk in u:
        relative = a[n:] @ x + b[n:] * uk
        acc.append(relative + (uk if excitation == "base" else 0.0))
        disp.append(x[:n].copy())
        x = phi @ x + gamma * uk
    return np.array(acc), np.array(disp)


def run_fmu(fmu: Path, folder: Path, storeys: int, excitation: str, u: np.ndarray):
    description = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in description.modelVariables}
    unzipped = folder / "unzipped"
    shutil.unpack_archive(str(fmu), str(unzipped), "zip")
    slave = FMU2Slave(
        guid=description.guid,
        unzipDirectory=str(unzipped),
        modelIdentifier=description.coSimulation.modelIdentifier,
        instanceName="shear",
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    input_vr = vr["ground_acc" if excitation == "base" else "force"]
    outputs = [vr[f"acc{i}"] for i in range(1, storeys + 1)] + [
        vr[f"disp{i}"] for i in range(1, storeys + 1)
    ]
    rows = []
    for n, uk in enumerate(u):
        slave.setReal([input_vr], [float(uk)])
        rows.append(slave.getReal(outputs))
        slave.doStep(currentCommunicationPoint=n * STEP, communicationStepSize=STEP)
    slave.terminate()
    slave.freeInstance()
    rows = np.array(rows)
    return rows[:, :storeys], rows[:, storeys:], description


@pytest.mark.parametrize("storeys,excitation", CASES, ids=[f"N{n}-{e}" for n, e in CASES])
def test_the_fmu_for_n_storeys_validates_and_equals_the_exact_discretisation(
    twin_binary, tmp_path, storeys, excitation
):
    values = nominal(storeys, seed=storeys * 7 + len(excitation))
    fmu = make_fmu(twin_binary, storeys, excitation, values, tmp_path)
    problems = validate_fmu(str(fmu))
    assert problems == [], problems

    base = excitation == "base"
    u = excitation_signal(storeys, base)
    acc, disp, description = run_fmu(fmu, tmp_path, storeys, excitation, u)
    names = {v.name for v in description.modelVariables}
    assert {f"acc{i}" for i in range(1, storeys + 1)} <= names
    assert f"acc{storeys + 1}" not in names
    assert ("ground_acc" in names) == base and ("force" in names) == (not base)
    starts = {v.name: float(v.start) for v in description.modelVariables if v.causality == "parameter" and v.type == "Real"}
    for key, prefix in (("m", "m"), ("c", "c"), ("k", "k")):
        for i, value in enumerate(values[key], start=1):
            assert starts[f"{prefix}{i}"] == pytest.approx(value, rel=1e-15)

    acc_ref, disp_ref = reference(values, excitation, u)
    worst = 0.0
    for got, want in ((acc, acc_ref), (disp, disp_ref)):
        for floor in range(storeys):
            scale = np.max(np.abs(want[:, floor]))
            assert scale > 0.0
            worst = max(worst, float(np.max(np.abs(got[:, floor] - want[:, floor])) / scale))
    print(f"N = {storeys}, {excitation}: worst relative difference {worst:.2e}")
    assert worst < RELATIVE_BAR, worst


def test_a_structure_the_fmu_cannot_model_is_refused_by_name(twin_binary, tmp_path):
    bad = tmp_path / "nominal.json"
    bad.write_text(json.dumps({"m": [5.0, -1.0], "c": [1.0, 1.0], "k": [4000.0, 4000.0]}))
    completed = run_twin(twin_binary, "init", "--nominal", str(bad), "--out", str(tmp_path / "t.ssp"), timeout=60)
    assert completed.returncode != 0
    assert "nominal.json" in completed.stderr and "m2" in completed.stderr, completed.stderr
    assert not (tmp_path / "t.ssp").exists()
