"""`twin synth` for buildings other than the paper's rig: the record has the channels asked for,
in their units (in the header), and without noise equals an independent integration of the same
structure by scipy (`solve_ivp`, DOP853 at rtol 1e-11, the excitation linear between samples as
synth's default `between_samples = linear` makes it):

- five storeys under ground motion, accelerometers on floors 1, 3 and 5 reading in g, a hidden
  cubic stiffness in storey 3;
- two storeys shaken at floor 2, velocity sensors in mm/s sampled at 1 kHz.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from conftest import run_twin, run_twin_ok

G = 9.80665

#: Largest difference between synth's noise-free channels and scipy's, relative to the channel's
#: largest |value|. Measured: 3.3e-9 (N = 5, base, cubic) and 1.1e-9 (N = 2, 1 kHz), the
#: written values' 9 significant digits and synth's fine RK4 (64 steps per sample); the bar
#: 1e-7 leaves a margin of 30, far below what a wrong channel, unit or floor gives (1e-1 or more).
RELATIVE_BAR = 1e-7


def synth(binary: Path, folder: Path, *flags: str) -> tuple[list[str], np.ndarray, dict]:
    out, truth = folder / "record.csv", folder / "truth.json"
    run_twin_ok(binary, "synth", "--out", str(out), "--truth", str(truth), *flags, timeout=300)
    lines = out.read_text().splitlines()
    header = lines[0].split(",")
    data = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    return header, data, json.loads(truth.read_text())


def reference(values: dict, excitation: str, t: np.ndarray, u: np.ndarray, dt: float, cubic=None):
    """Absolute accelerations, velocities and displacements (relative) at the sample times.
    The step is the nominal one, `dt` (the truth's sample_interval): the written times are rounded to
    1 µs (0.019531 s at 51.2 Hz), which would shift the reference by 1e-5."""
    m, c, k = (np.asarray(values[key], dtype=float) for key in ("m", "c", "k"))
    n = m.size
    stiffness, damping = np.zeros((n, n)), np.zeros((n, n))
    for s in range(n):
        for matrix, value in ((stiffness, k[s]), (damping, c[s])):
            matrix[s, s] += value
            if s > 0:
                matrix[s - 1, s - 1] += value
                matrix[s, s - 1] -= value
                matrix[s - 1, s] -= value
    load = -m if excitation == "base" else np.eye(n)[int(excitation.split(":")[1]) - 1]

    def acc(y, v, uk):
        g = np.zeros(n)
        if cubic is not None:
            storey, k3 = cubic
            d = y[storey] - (y[storey - 1] if storey > 0 else 0.0)
            g[storey] += k3 * d**3
            if storey > 0:
                g[storey - 1] -= k3 * d**3
        return (load * uk - damping @ v - stiffness @ y - g) / m

    x = np.zeros(2 * n)
    accs, vels, disps = [], [], []
    scale = 1e-6
    for i in range(len(t)):
        y, v = x[:n], x[n:]
        a = acc(y, v, u[i]) + (u[i] if excitation == "base" else 0.0)
        accs.append(a)
        vels.append(v.copy())
        disps.append(y.copy())
        if i + 1 == len(t):
            break
        h = dt
        u0, slope = u[i], (u[i + 1] - u[i]) / h
        sol = solve_ivp(
            lambda tau, z: np.concatenate([z[n:], acc(z[:n], z[n:], u0 + slope * tau)]),
            (0.0, h), x, method="DOP853", rtol=1e-11, atol=1e-14 * scale,
        )
        x = sol.y[:, -1]
        scale = max(scale, float(np.max(np.abs(x))))
    return np.array(accs), np.array(vels), np.array(disps)


def worst(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want)) / np.max(np.abs(want)))


def test_five_storeys_under_ground_motion_with_three_accelerometers_in_g_and_a_hidden_cubic(
    twin_binary, tmp_path  # noqa: F811
):
    values = {"m": [5.0, 5.2, 4.8, 5.1, 4.9], "c": [3.0, 2.5, 2.8, 3.2, 2.6],
              "k": [4200.0, 4000.0, 3900.0, 4100.0, 3800.0]}
    (tmp_path / "nominal.json").write_text(json.dumps(values))
    k3 = 2e8
    header, data, truth = synth(
        twin_binary, tmp_path, "--storeys", "5", "--excitation", "base",
        "--nominal", str(tmp_path / "nominal.json"), "--channels", "acc1,acc3,acc5",
        "--units", "acc=g", "--effect", f"cubic@3:stiffness={k3}", "--noise-fraction", "0",
        "--duration", "10", "--seed", "4",
    )
    assert header == ["time", "ground_acc", "acc1 (g)", "acc3 (g)", "acc5 (g)"]
    assert truth["record"]["columns"] == header
    assert truth["structure"]["excitation"] == "base"
    assert truth["structure"]["k"] == values["k"]
    assert truth["effects"][0]["fmu_prefix"] == "cubic3"
    t, ground = data[:, 0], data[:, 1]
    dt = truth["record"]["sample_interval"]
    acc, _, disp = reference(values, "base", t, ground, dt, cubic=(2, k3))
    linear, _, _ = reference(values, "base", t, ground, dt)
    for column, floor in ((2, 0), (3, 2), (4, 4)):
        got = data[:, column] * G
        print(f"acc{floor + 1}: {worst(got, acc[:, floor]):.2e} "
              f"(the cubic moves it by {worst(linear[:, floor], acc[:, floor]):.2e})")
        assert worst(got, acc[:, floor]) < RELATIVE_BAR
    # The hidden effect matters: storey 3's cubic force at its largest drift, against k3·drift.
    drift3 = np.max(np.abs(disp[:, 2] - disp[:, 1]))
    assert k3 * drift3**2 > 0.05 * values["k"][2], k3 * drift3**2 / values["k"][2]
    assert worst(linear[:, 2], acc[:, 2]) > 100 * RELATIVE_BAR


def test_two_storeys_shaken_at_floor_two_with_velocity_sensors_in_mm_per_s_at_1_khz(
    twin_binary, tmp_path  # noqa: F811
):
    header, data, truth = synth(
        twin_binary, tmp_path, "--storeys", "2", "--excitation", "force:2",
        "--channels", "vel1,vel2", "--units", "vel=mm/s", "--sample-rate", "1000",
        "--band-hz", "40", "--duration", "3", "--noise-fraction", "0", "--seed", "2",
    )
    assert header == ["time", "force", "vel1 (mm/s)", "vel2 (mm/s)"]
    assert truth["record"]["columns"] == header
    assert truth["record"]["sample_rate"] == 1000
    assert np.allclose(np.diff(data[:, 0]), 1e-3, atol=1e-9)
    values = {key: truth["structure"][key] for key in ("m", "c", "k")}
    assert len(values["m"]) == 2
    _, vel, _ = reference(values, "force:2", data[:, 0], data[:, 1], truth["record"]["sample_interval"])
    for column, floor in ((2, 0), (3, 1)):
        got = data[:, column] * 1e-3
        print(f"vel{floor + 1}: {worst(got, vel[:, floor]):.2e}")
        assert worst(got, vel[:, floor]) < RELATIVE_BAR


def test_a_site_or_channel_the_building_lacks_is_refused_by_name(twin_binary, tmp_path):  # noqa: F811
    for flags, says in (
        (["--storeys", "5", "--effect", "cubic@6"], "cubic is at storey"),
        (["--storeys", "5", "--channels", "acc6"], "acc6"),
        (["--storeys", "2", "--excitation", "force:3"], "force:3"),
        (["--units", "acc=mm/s"], "mm/s"),
    ):
        completed = run_twin(twin_binary, "synth", "--out", str(tmp_path / "x.csv"), *flags, timeout=60)
        assert completed.returncode != 0, flags
        assert says in completed.stderr, (flags, completed.stderr)
        assert not (tmp_path / "x.csv").exists()
