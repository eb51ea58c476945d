"""The shear FMU's effect library at a high site of a tall building, as `twin init --storeys N`
writes the FMU: fmpy sets the effect's parameters by their variable names and drives the FMU,
and the result equals an independent fine integration of `M ÿ + C ẏ + K y + g(y, ẏ) = L u`
(scipy's `solve_ivp`, DOP853 at rtol 1e-11, the input held over each step as the FMU holds it).

Each effect is sized from the linear response of the same run (scipy), so that it matters: a
contact gap at half the storey's largest linear drift, a cubic stiffness whose force at that
drift is 30 % of the storey's linear spring force, a friction force of 10 % of the floor's
largest inertia force. The test also checks that the effect changes the response by far more
than the tolerance, so that a site the FMU ignored would fail.
"""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

from test_fmpy_storeys import STEP, excitation_signal, make_fmu, nominal

import shutil
from fmpy.fmi2 import FMU2Slave

#: Largest difference between the FMU (Dormand–Prince 5(4), local error 1e-10, split at the
#: contact kinks) and solve_ivp, relative to the largest |value| of the same output, over every
#: floor's acceleration and displacement. Measured: 3.6e-9 to 1.3e-8 over the cases below; the bar
#: is 1e-6, while the effects change the responses by 2.7e-1 or more (asserted below).
RELATIVE_BAR = 1e-6
#: The effect must move the response at least this much (relative, as above) to be tested.
EFFECT_MOVES = 1e-3

STEPS = 512

CASES = [
    # storeys, excitation, kind, site (1-based: storey, or the lower floor of a contact, or floor)
    (5, "base", "cubic", 4),
    (10, "force:7", "contact", 9),
    (12, "base", "contact", 10),
    (20, "base", "friction", 12),
]


def matrices(values: dict):
    m, c, k = (np.asarray(values[key], dtype=float) for key in ("m", "c", "k"))
    n = m.size
    stiffness = np.zeros((n, n))
    damping = np.zeros((n, n))
    for s in range(n):
        for matrix, value in ((stiffness, k[s]), (damping, c[s])):
            matrix[s, s] += value
            if s > 0:
                matrix[s - 1, s - 1] += value
                matrix[s, s - 1] -= value
                matrix[s - 1, s] -= value
    return m, damping, stiffness


def drift(y: np.ndarray, storey: int) -> float:
    """Storey `storey` (0-based: 0 is ground–floor 1)."""
    return y[0] if storey == 0 else y[storey] - y[storey - 1]


def storey_force(g: np.ndarray, storey: int, f: float) -> None:
    g[storey] += f
    if storey > 0:
        g[storey - 1] -= f


def simulate(values: dict, excitation: str, u: np.ndarray, effect=None):
    """Absolute accelerations and relative displacements at t_k (after u_k is set)."""
    m, damping, stiffness = matrices(values)
    n = m.size
    load = np.zeros(n)
    if excitation == "base":
        load[:] = -m
    else:
        load[int(excitation.split(":")[1]) - 1] = 1.0

    def g_of(y, v):
        g = np.zeros(n)
        if effect is not None:
            effect(y, v, g)
        return g

    def acc(y, v, uk):
        return (load * uk - damping @ v - stiffness @ y - g_of(y, v)) / m

    x = np.zeros(2 * n)
    scale = 1e-3
    out_acc, out_disp = [], []
    for uk in u:
        y, v = x[:n], x[n:]
        a = acc(y, v, uk)
        out_acc.append(a + (uk if excitation == "base" else 0.0))
        out_disp.append(y.copy())
        sol = solve_ivp(
            lambda _t, z: np.concatenate([z[n:], acc(z[:n], z[n:], uk)]),
            (0.0, STEP), x, method="DOP853", rtol=1e-11, atol=1e-14 * scale,
        )
        x = sol.y[:, -1]
        scale = max(scale, float(np.max(np.abs(x))))
    return np.array(out_acc), np.array(out_disp)


def run_fmu(fmu, folder, storeys, excitation, u, settings):
    description = read_model_description(str(fmu))
    variables = {v.name: v for v in description.modelVariables}
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
    for name, value in settings.items():
        v = variables[name]
        if v.type == "Boolean":
            slave.setBoolean([v.valueReference], [bool(value)])
        elif v.type == "Integer":
            slave.setInteger([v.valueReference], [int(value)])
        else:
            slave.setReal([v.valueReference], [float(value)])
    slave.exitInitializationMode()
    input_vr = variables["ground_acc" if excitation == "base" else "force"].valueReference
    outputs = [variables[f"acc{i}"].valueReference for i in range(1, storeys + 1)] + [
        variables[f"disp{i}"].valueReference for i in range(1, storeys + 1)
    ]
    rows = []
    for k, uk in enumerate(u):
        slave.setReal([input_vr], [float(uk)])
        rows.append(slave.getReal(outputs))
        slave.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
    slave.terminate()
    slave.freeInstance()
    rows = np.array(rows)
    return rows[:, :storeys], rows[:, storeys:], variables


def worst_relative(a, b, reference):
    worst = 0.0
    for got, want, ref in zip(a, b, reference):
        for floor in range(ref.shape[1]):
            scale = np.max(np.abs(ref[:, floor]))
            worst = max(worst, float(np.max(np.abs(got[:, floor] - want[:, floor])) / scale))
    return worst


@pytest.mark.parametrize(
    "storeys,excitation,kind,site", CASES, ids=[f"N{n}-{e}-{k}{s}" for n, e, k, s in CASES]
)
def test_an_effect_at_a_high_site_equals_a_fine_integration(
    twin_binary, tmp_path, storeys, excitation, kind, site  # noqa: F811
):
    values = nominal(storeys, seed=storeys * 11 + 3)
    fmu = make_fmu(twin_binary, storeys, excitation, values, tmp_path)
    assert validate_fmu(str(fmu)) == []
    base = excitation == "base"
    u = excitation_signal(storeys, base)[:STEPS]
    linear_acc, linear_disp = simulate(values, excitation, u)
    m, _, _ = matrices(values)

    if kind == "cubic":
        storey = site - 1
        largest = max(abs(drift(y, storey)) for y in linear_disp)
        k3 = 0.3 * values["k"][storey] / largest**2
        prefix = f"cubic{site}"
        settings = {f"{prefix}_enabled": True, f"{prefix}_stiffness": k3}

        def effect(y, v, g):
            storey_force(g, storey, k3 * drift(y, storey) ** 3)
    elif kind == "contact":
        storey = site  # the storey between floors `site` and `site + 1`
        largest = max(abs(drift(y, storey)) for y in linear_disp)
        gap, kc = 0.5 * largest, 2.0 * values["k"][storey]
        prefix = f"contact{site}{site + 1}" if site + 1 < 10 else f"contact{site}to{site + 1}"
        settings = {f"{prefix}_enabled": True, f"{prefix}_gap": gap, f"{prefix}_stiffness": kc}

        def effect(y, v, g):
            d = drift(y, storey)
            f = kc * (d - gap) if d > gap else kc * (d + gap) if d < -gap else 0.0
            storey_force(g, storey, f)
    else:
        floor = site - 1
        fc = 0.1 * m[floor] * float(np.max(np.abs(linear_acc[:, floor])))
        vs = 1e-3
        prefix = f"friction{site}"
        settings = {f"{prefix}_enabled": True, f"{prefix}_force": fc, f"{prefix}_velocity_scale": vs}

        def effect(y, v, g):
            g[floor] += fc * np.tanh(v[floor] / vs)

    acc, disp, variables = run_fmu(fmu, tmp_path, storeys, excitation, u, settings)
    for name in settings:
        assert name in variables, name
    ref_acc, ref_disp = simulate(values, excitation, u, effect)
    moved = worst_relative((linear_acc, linear_disp), (ref_acc, ref_disp), (ref_acc, ref_disp))
    worst = worst_relative((acc, disp), (ref_acc, ref_disp), (ref_acc, ref_disp))
    print(f"N = {storeys}, {excitation}, {prefix}: the effect moves the response by {moved:.2e}, "
          f"the FMU differs by {worst:.2e}")
    assert moved > EFFECT_MOVES, moved
    assert worst < RELATIVE_BAR, worst
