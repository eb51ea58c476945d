"""`twin control`'s report against the trusted control tools: A and B rebuilt here from the
reported parameters (eqs 17-19 with the state in `state_scale` metres), Q = q·diag(0, I), and
the gain against scipy's `solve_continuous_are` and python-control's `lqr` on exactly the A, B,
Q, R the report says it used — for the paper's q = 1e3 and 5e3 with R = 0.1, in metres and in
millimetres, on a calibrated-looking twin and on a lightly damped one. The closed-loop poles are
checked against numpy's eigenvalues of A − B·K.

Bound: 1e-8 relative on the gain against both (the issue's bar). Measured: ≤ 3e-13 against
scipy, ≤ 1.6e-9 against python-control (its default solver's residuals are larger than ours; see
numerics/tests/riccati.rs).
"""

from __future__ import annotations

import json
from pathlib import Path

import control
import numpy as np
import pytest
import scipy.linalg
from conftest import run_twin

ROOT = Path(__file__).resolve().parents[2]


pytestmark = pytest.mark.usefixtures("twin_fmus")


def tridiagonal(c: list[float]) -> np.ndarray:
    m = np.zeros((3, 3))
    for i in range(3):
        m[i, i] += c[i]
        if i + 1 < 3:
            m[i, i] += c[i + 1]
            m[i, i + 1] -= c[i + 1]
            m[i + 1, i] -= c[i + 1]
    return m


def state_space(parameters: dict, scale: float) -> tuple[np.ndarray, np.ndarray]:
    m = [parameters[f"m{i}"] for i in (1, 2, 3)]
    c = [parameters[f"c{i}"] for i in (1, 2, 3)]
    k = [parameters[f"k{i}"] for i in (1, 2, 3)]
    m_inv = np.diag([1.0 / x for x in m])
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [-m_inv @ tridiagonal(k), -m_inv @ tridiagonal(c)]])
    b = np.zeros((6, 1))
    b[3, 0] = 1.0 / m[0] / scale
    return a, b


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def lightly_damped_twin(twin_binary, tmp_path_factory) -> Path:
    """The default twin: the paper's prior means, c = e^-4.605 ≈ 0.01 N s/m (ζ ≈ 0.02 %)."""
    path = tmp_path_factory.mktemp("twins") / "default.ssp"
    done = run_twin(twin_binary, "init", "--out", str(path))
    assert done.returncode == 0, done.stderr
    return path


@pytest.mark.parametrize("unit,scale", [("m", 1.0), ("mm", 1e-3)])
def test_gains_agree_with_scipy_and_python_control(twin_binary, lightly_damped_twin, tmp_path, unit, scale):
    report_path = tmp_path / "control.json"
    done = run_twin(
        twin_binary, "control", "--twin", str(lightly_damped_twin), "--data", str(ROOT / "data/dataset2.csv"),
        "--q", "1e3", "--q", "5e3", "--r", "0.1", "--state-unit", unit, "--report", str(report_path),
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(report_path.read_text())
    assert report["state_scale"] == scale
    a, b = state_space(report["parameters"], scale)
    assert relative(np.array(report["A"]), a) < 1e-14
    assert relative(np.array(report["B"]).reshape(6, 1), b) < 1e-14
    r = np.array([[report["R"]]])
    assert report["R"] == 0.1
    assert [d["q"] for d in report["designs"]] == [1e3, 5e3]
    for design in report["designs"]:
        q = np.array(design["Q"])
        assert np.array_equal(q, design["q"] * np.diag([0, 0, 0, 1, 1, 1.0]))
        gain = np.array(design["gain"]).reshape(1, 6)
        x = scipy.linalg.solve_continuous_are(a, b, q, r)
        k_scipy = np.linalg.solve(r, b.T @ x)
        k_control, _, _ = control.lqr(a, b, q, r)
        print(f"{unit} q={design['q']}: |ΔK|/|K| scipy {relative(gain, k_scipy):.2e}, "
              f"control {relative(gain, np.asarray(k_control)):.2e}")
        assert relative(gain, k_scipy) < 1e-8
        assert relative(gain, np.asarray(k_control)) < 1e-8
        assert design["riccati_residual"] <= 1e-10
        poles = np.sort_complex(np.linalg.eigvals(a - b @ gain))
        reported = np.sort_complex(np.array([complex(re, im) for re, im in design["closed_loop_poles"]]))
        assert np.max(np.abs(poles - reported)) <= 1e-8 * np.max(np.abs(poles))
        assert np.all(poles.real < 0)
