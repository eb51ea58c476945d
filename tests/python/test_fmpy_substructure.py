"""The hybrid test's substructure FMU (`fmu_substructure`) under fmpy: validation, the physical
roles driven step by step through `fmpy.fmi2.FMU2Slave` with a prescribed actuator motion against
an independent numpy model of storey 3, the bumper and floor 3 (and floor 2's inertia when the
specimen holds floor 2, role 2), and bad parameters refused.

The FMU is `target/fmu/fmu_substructure.fmu` (scripts/build-fmus.sh), or the file named by the
environment variable SUBSTRUCTURE_FMU.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from shear_drive import nmse

REPO_ROOT = Path(__file__).resolve().parents[2]
#: The bar of the cross-check against the independent model (percent), as the shear FMU's.
NMSE_BAR = 0.05
#: The control step of the drive: 1/51.2 s over 8.
H = 1.0 / 51.2 / 8
STEPS = 2048
#: Storey 3, floor 3 and the bumper (the hybrid test's structure).
PHYSICAL = {"m3": 4.9, "c3": 2.6, "k3": 4650.0, "gap": 5e-4, "contact_stiffness": 9000.0}
#: Floor 2's mass, in the specimen under role 2.
M2 = 5.3


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    path = Path(
        os.environ.get("SUBSTRUCTURE_FMU", REPO_ROOT / "target" / "fmu" / "fmu_substructure.fmu")
    )
    if not path.is_file():
        pytest.fail(f"{path} does not exist: run scripts/build-fmus.sh", pytrace=False)
    md = read_model_description(str(path))
    unzip = tmp_path_factory.mktemp("fmu_substructure")
    extract(str(path), unzipdir=str(unzip))
    return path, md, unzip


def _slave(fmu, name):
    path, md, unzip = fmu
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=str(unzip),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName=name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    return slave, vrs


def _motion(steps: int, h: float):
    """floor 2's imposed displacement and rate at the control steps: two tones, 2 mm peak."""
    t = np.arange(steps + 1) * h
    w1, w2 = 2 * np.pi * 4.1, 2 * np.pi * 11.3
    y = 1.5e-3 * np.sin(w1 * t) + 0.6e-3 * np.sin(w2 * t) * (1 - np.exp(-t))
    v = 1.5e-3 * w1 * np.cos(w1 * t) + 0.6e-3 * (
        w2 * np.cos(w2 * t) * (1 - np.exp(-t)) + np.sin(w2 * t) * np.exp(-t)
    )
    return y, v


def _reference(y, v, h, substeps, m2=0.0):
    """Storey 3 + bumper + floor 3 with floor 2 moving as the cubic Hermite between the control
    steps (in power form), RK4 at `substeps` steps per control step; the measured force at every
    control step, with floor 2's inertia `m2` times the Hermite's acceleration at the step's end
    (0 at the first point: floor 2 at rest); and that acceleration."""
    m, c, k, d, knl = (PHYSICAL[n] for n in ("m3", "c3", "k3", "gap", "contact_stiffness"))

    def force(y2, v2, y3, v3):
        r = y2 - y3
        return c * (v2 - v3) + k * r + knl * max(0.0, r - d)

    y3, v3 = 0.0, 0.0
    out = [force(y[0], v[0], y3, v3)]
    accelerations = [0.0]
    hs = h / substeps
    for i in range(len(y) - 1):
        y0, v0, y1, v1 = float(y[i]), float(v[i]), float(y[i + 1]), float(v[i + 1])
        a2 = (3.0 * (y1 - y0) / h - 2.0 * v0 - v1) / h
        a3 = (2.0 * (y0 - y1) / h + v0 + v1) / h**2

        def acc(tau, p, q):
            y2 = y0 + tau * (v0 + tau * (a2 + tau * a3))
            v2 = v0 + tau * (2.0 * a2 + 3.0 * a3 * tau)
            return force(y2, v2, p, q) / m

        for j in range(substeps):
            t0 = j * hs
            k1p, k1v = v3, acc(t0, y3, v3)
            k2p, k2v = v3 + hs / 2 * k1v, acc(t0 + hs / 2, y3 + hs / 2 * k1p, v3 + hs / 2 * k1v)
            k3p, k3v = v3 + hs / 2 * k2v, acc(t0 + hs / 2, y3 + hs / 2 * k2p, v3 + hs / 2 * k2v)
            k4p, k4v = v3 + hs * k3v, acc(t0 + hs, y3 + hs * k3p, v3 + hs * k3v)
            y3 += hs / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
            v3 += hs / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        end = 2.0 * a2 + 6.0 * a3 * h
        accelerations.append(end)
        out.append(force(y1, v1, y3, v3) + m2 * end)
    return np.array(out), np.array(accelerations)


def _drive_physical(fmu, y, v, h, substeps, role=1):
    """A physical role through FMU2Slave: at each point set the motion of the control step
    that ends there, read the measured force (the specimen at the end of that motion), step."""
    slave, vrs = _slave(fmu, f"physical-{role}-{substeps}")
    slave.setInteger([vrs["role"], vrs["substeps"]], [role, substeps])
    slave.setReal(
        [vrs[n] for n in PHYSICAL] + [vrs["control_step"], vrs["m2"]],
        list(PHYSICAL.values()) + [h, M2],
    )
    slave.exitInitializationMode()
    motion = [vrs[n] for n in ("y2_start", "v2_start", "y2_end", "v2_end")]
    out = []
    y3 = []
    accelerations = []
    for i in range(len(y)):
        start = (y[i - 1], v[i - 1]) if i > 0 else (y[0], v[0])
        slave.setReal(motion, [start[0], start[1], y[i], v[i]])
        fm, relative, d3, a2 = slave.getReal(
            [vrs["measured_force"], vrs["relative"], vrs["y3"], vrs["a2"]]
        )
        accelerations.append(a2)
        assert relative == pytest.approx(y[i] - d3, abs=1e-18)
        out.append(fm)
        y3.append(d3)
        # The numerical role's outputs read 0 in this role.
        assert slave.getReal([vrs["y1"], vrs["y2"]]) == [0.0, 0.0]
        slave.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
    slave.terminate()
    slave.freeInstance()
    return np.array(out), np.array(y3), np.array(accelerations)


def test_validate_fmu_reports_no_problem(fmu):
    problems = validate_fmu(str(fmu[0]))
    assert problems == [], "fmpy.validation.validate_fmu:\n" + "\n".join(problems)


def test_the_physical_role_is_storey_3_with_the_bumper(fmu):
    y, v = _motion(STEPS, H)
    # Floor 2 starts at rest: the first point's motion is then none at all.
    v = v.copy()
    v[0] = 0.0
    by_fmu, y3, _ = _drive_physical(fmu, y, v, H, 1)
    independent, _ = _reference(y, v, H, 1)
    closed = np.sum(y - y3 > PHYSICAL["gap"])
    assert closed > 50, f"the bumper is closed at only {closed} of {STEPS} control steps"
    # The same RK4 on the same Hermite, written twice: agreement to rounding (measured 2.3e-15
    # of the peak force; the bumper closed at 637 of the 2048 points).
    np.testing.assert_allclose(by_fmu, independent, rtol=0, atol=1e-12 * np.max(np.abs(independent)))
    # Against a converged reference (64 RK4 steps per control step), the FMU at 8: the bar
    # (measured 8.3e-8 %; 3.4e-4 % at one step per control step).
    converged, _ = _reference(y, v, H, 64)
    at_8, _, _ = _drive_physical(fmu, y, v, H, 8)
    error = nmse(converged[:, None], at_8[:, None])
    assert np.all(error < NMSE_BAR), f"NMSE {error} %"


def test_role_2_adds_floor_2s_inertia_to_the_measured_force(fmu):
    """The specimen holding floor 2 (the reference paper's split): the measured force is role
    1's plus m2 times floor 2's acceleration, the imposed Hermite's at the motion's end, which
    the FMU also reads out as `a2`."""
    y, v = _motion(STEPS, H)
    v = v.copy()
    v[0] = 0.0
    by_fmu, _, a2 = _drive_physical(fmu, y, v, H, 1, role=2)
    independent, accelerations = _reference(y, v, H, 1, m2=M2)
    scale = np.max(np.abs(independent))
    # Written twice from the same Hermite: agreement to rounding of the inertia term (measured
    # 2.4e-15 of the peak force).
    worst = np.max(np.abs(by_fmu - independent)) / scale
    print(f"role 2 against the numpy model: {worst:.2e} of the peak force")
    assert worst < 1e-9
    np.testing.assert_allclose(a2, accelerations, rtol=0, atol=1e-9 * np.max(np.abs(accelerations)))
    # The inertia is a real part of the force here: m2 a2 against the whole.
    assert np.max(np.abs(M2 * accelerations)) > 0.1 * scale


def test_bad_parameters_are_refused(fmu):
    for name, value in [("m3", -1.0), ("m1", 0.0), ("gap", -1e-3)]:
        slave, vrs = _slave(fmu, f"bad-{name}")
        slave.setReal([vrs[name]], [value])
        with pytest.raises(FMICallException):
            slave.exitInitializationMode()
        slave.freeInstance()
    slave, vrs = _slave(fmu, "bad-role")
    with pytest.raises(FMICallException):
        slave.setInteger([vrs["role"]], [3])
    slave.freeInstance()
