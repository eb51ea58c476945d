#!/usr/bin/env python3
"""Reference solutions of the LQR's Riccati equation for numerics::control (numerics/tests/riccati.rs).

Writes numerics/tests/data/care_reference.json: for each case the problem (A, B, Q, R) and the
stabilising solution X with the gain K = R^-1 B^T X from two independent solvers,

- scipy.linalg.solve_continuous_are (LAPACK: QZ of the balanced extended pencil), and
- control.lqr(A, B, Q, R, N = 0, method="slycot") (python-control on SLICOT's SB02OD, the
  extended pencil; without N python-control calls SB02MD, unscaled, whose relative residuals
  reach 1e-5 on the q = 1e6 shear cases),

after checking that the two agree (relative Frobenius difference of X and of K at most 1e-7: on
the q >= 1e5 shear cases SLICOT's residuals are ~1e-9 against scipy's ~1e-14, and the two differ
by up to ~1.5e-8). Stored with each case: both answers, their difference and the relative residual
of each, ||A^T X + X A - X G X + Q||_F / (||Q||_F + 2 ||A^T X||_F + ||X G X||_F), G = B R^-1 B^T.
The cases:

- the 3-storey shear model, A = [[0, I], [-M^-1 K, -M^-1 C]], B = [0; M^-1 phi], phi = [1, 0, 0],
  m = 5.2 kg, k = 4021 N/m per storey (K tridiagonal: k1 + k2, -k2; -k2, k2 + k3, -k3; -k3, k3),
  C = (c/k) K with c = 0.01 Ns/m (lightly damped) and c = 1, states in metres and in millimetres
  (B scaled by 1000), Q = q diag(0, 0, 0, 1, 1, 1), R = 0.1, q = 1, 10, ..., 1e6;
- a random stable 4x4 system with 2 inputs, an unstable but stabilisable system (an uncontrollable
  stable mode beside two unstable controllable ones) and the double integrator.

tests/python/test_riccati_reference.py recomputes every case with the installed scipy and
python-control and checks the committed file against them.

    .venv/bin/python scripts/riccati_reference.py [--out numerics/tests/data/care_reference.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import control
import numpy as np
import scipy
import scipy.linalg

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO_ROOT / "numerics" / "tests" / "data" / "care_reference.json"

# The agreement required between scipy and python-control/SLICOT before a case is written.
SOLVER_AGREEMENT = 1e-7

MASS = 5.2
STIFFNESS = 4021.0


def shear_model(damping: float, unit: float, q: float):
    """A, B, Q, R of the 3-storey shear model; unit = 1 (metres) or 1000 (millimetres)."""
    k = STIFFNESS
    stiffness = np.array([[2 * k, -k, 0.0], [-k, 2 * k, -k], [0.0, -k, k]])
    damping_matrix = stiffness * (damping / k)
    m_inv = np.eye(3) / MASS
    a = np.block([[np.zeros((3, 3)), np.eye(3)],
                  [-m_inv @ stiffness, -m_inv @ damping_matrix]])
    phi = np.array([[1.0], [0.0], [0.0]])
    b = np.vstack([np.zeros((3, 1)), m_inv @ phi]) * unit
    weights = q * np.diag([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    return a, b, weights, np.array([[0.1]])


def generic_cases():
    rng = np.random.default_rng(20240611)
    # A random stable 4x4 with 2 inputs: a random matrix shifted left of its rightmost eigenvalue.
    a = rng.standard_normal((4, 4))
    a -= (np.max(np.linalg.eigvals(a).real) + 0.5) * np.eye(4)
    b = rng.standard_normal((4, 2))
    c = rng.standard_normal((2, 4))
    q = c.T @ c + 0.1 * np.eye(4)
    s = rng.standard_normal((2, 2))
    r = s @ s.T + 0.5 * np.eye(2)
    yield "random_stable_n4_m2", a, b, q, r
    # Unstable (eigenvalues 1 and 2, controllable) beside a stable uncontrollable mode (-1).
    a = np.array([[1.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -1.0]])
    b = np.array([[0.0], [1.0], [0.0]])
    yield "unstable_stabilisable_n3", a, b, np.eye(3), np.array([[1.0]])
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    b = np.array([[0.0], [1.0]])
    yield "double_integrator", a, b, np.eye(2), np.array([[1.0]])


def problems():
    """Every case as (name, A, B, Q, R), in the file's order."""
    for damping, damping_name in ((0.01, "light"), (1.0, "c1")):
        for unit, unit_name in ((1.0, "m"), (1000.0, "mm")):
            for exponent in range(7):
                q = 10.0 ** exponent
                name = f"shear_{damping_name}_{unit_name}_q1e{exponent}"
                yield (name, *shear_model(damping, unit, q))
    yield from generic_cases()


def relative_difference(x, y) -> float:
    return float(np.linalg.norm(x - y) / np.linalg.norm(y))


def relative_residual(a, b, q, r, x) -> float:
    g = b @ np.linalg.solve(r, b.T)
    atx = a.T @ x
    xgx = x @ g @ x
    res = atx + atx.T - xgx + q
    return float(np.linalg.norm(res) / (np.linalg.norm(q) + 2 * np.linalg.norm(atx) + np.linalg.norm(xgx)))


def solve(a, b, q, r):
    """X and K from scipy and from python-control with SLICOT, and how far apart they are."""
    x_scipy = scipy.linalg.solve_continuous_are(a, b, q, r)
    k_scipy = np.linalg.solve(r, b.T @ x_scipy)
    no_cross_term = np.zeros(b.shape)
    k_control, x_control, _ = control.lqr(a, b, q, r, no_cross_term, method="slycot")
    x_control = np.asarray(x_control)
    k_control = np.asarray(k_control)
    return {
        "scipy": {"x": x_scipy, "gain": k_scipy,
                  "relative_residual": relative_residual(a, b, q, r, x_scipy)},
        "control": {"x": x_control, "gain": k_control,
                    "relative_residual": relative_residual(a, b, q, r, x_control)},
        "agreement": {
            "x": relative_difference(x_scipy, x_control),
            "gain": relative_difference(k_scipy, k_control),
        },
    }


def as_lists(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {key: as_lists(item) for key, item in value.items()}
    return value


def build() -> dict:
    cases = []
    for name, a, b, q, r in problems():
        solution = solve(a, b, q, r)
        worst = max(solution["agreement"].values())
        if not worst <= SOLVER_AGREEMENT:
            raise SystemExit(f"{name}: scipy and python-control/SLICOT differ by {worst:.3e}")
        cases.append(as_lists({"name": name, "a": a, "b": b, "q": q, "r": r, **solution}))
    return {
        "generator": "scripts/riccati_reference.py",
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__,
                     "control": control.__version__},
        "solver_agreement": SOLVER_AGREEMENT,
        "cases": cases,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    reference = build()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(reference, indent=1) + "\n")
    for case in reference["cases"]:
        agreement = case["agreement"]
        print(f"{case['name']:<28} scipy vs control: X {agreement['x']:.1e}  K {agreement['gain']:.1e}"
              f"   residual scipy {case['scipy']['relative_residual']:.1e}"
              f"  control {case['control']['relative_residual']:.1e}")
    print(f"wrote {len(reference['cases'])} cases to {args.out}")


if __name__ == "__main__":
    main()
