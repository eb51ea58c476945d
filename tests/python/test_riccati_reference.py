"""The committed Riccati fixture (numerics/tests/data/care_reference.json), which the Rust solver
is tested against (numerics/tests/riccati.rs), checked against the problems it claims to solve,
so that it cannot go stale or wrong:

- every case's problem (A, B, Q, R) is rebuilt by scripts/riccati_reference.py and must be the
  stored one (to 1e-14: the random case goes through LAPACK on the way);
- each stored solution X (scipy's and python-control/SLICOT's) must solve its problem: relative
  residual at most `RESIDUAL` and stabilising (A − G X Hurwitz, G = B R⁻¹ Bᵀ), and the two
  solvers must agree to `riccati_reference.SOLVER_AGREEMENT`;
- each solver, run live with the installed scipy and python-control, must land within the
  distance from the stored X that the problem's conditioning earns for two computed solutions
  (below), not within a fixed number of bits: OpenBLAS, under numpy, scipy and slycot, picks its
  kernels for the CPU at run time, and SLICOT's X moves by up to 1.9e-8 (relative) between an
  AVX-512 and an AVX2 machine on the q = 1e6 cases while its residuals there are ~5e-9.

The earned distance. To first order, a computed X̃ with residual R(X̃) = AᵀX̃ + X̃A − X̃GX̃ + Q is
X + Ω⁻¹(R(X̃)) with Ω(Z) = A_cᵀZ + ZA_c, A_c = A − GX (the closed-loop Lyapunov operator), so
two computed solutions are at most (‖R(X₁)‖ + ‖R(X₂)‖) / sep apart, sep = σ_min(I ⊗ A_cᵀ + A_cᵀ ⊗ I)
(Frobenius norms), and their gains at most ‖R⁻¹Bᵀ‖₂ times that. The test allows twice that
(second-order terms) plus 64 ulps of ‖X‖ (the residual's own rounding). Measured with the
kernels forced by OPENBLAS_CORETYPE=Haswell (AVX2) and =Sandybridge (AVX) on an AVX-512 machine:
the worst distance is 0.55 of the first-order bound (the double integrator, whose residuals are at
rounding level), 0.23 on the shear cases.

    .venv/bin/python -m pytest tests/python/test_riccati_reference.py -q
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO_ROOT / "scripts"))

import riccati_reference  # noqa: E402

FIXTURE = REPO_ROOT / "numerics" / "tests" / "data" / "care_reference.json"
# The largest relative residual a stored solution may have: SLICOT's reach 8.1e-9 on the q = 1e6
# shear cases (scipy's 2.6e-12); a 2.5x margin.
RESIDUAL = 2e-8

PROBLEMS = list(riccati_reference.problems())


@pytest.fixture(scope="module")
def fixture_cases() -> dict:
    reference = json.loads(FIXTURE.read_text())
    return {case["name"]: case for case in reference["cases"]}


def residual(a, b, q, r, x) -> np.ndarray:
    g = b @ np.linalg.solve(r, b.T)
    atx = a.T @ x
    return atx + atx.T - x @ g @ x + q


def separation(a, b, r, x) -> float:
    """σ_min of the closed-loop Lyapunov operator Z ↦ A_cᵀZ + ZA_c (Frobenius norm)."""
    n = a.shape[0]
    closed = a - b @ np.linalg.solve(r, b.T) @ x
    operator = np.kron(np.eye(n), closed.T) + np.kron(closed.T, np.eye(n))
    return float(np.linalg.svd(operator, compute_uv=False)[-1])


def test_fixture_has_exactly_the_generated_cases(fixture_cases):
    assert list(fixture_cases) == [name for name, *_ in PROBLEMS]


@pytest.mark.parametrize("problem", PROBLEMS, ids=[name for name, *_ in PROBLEMS])
def test_stored_solutions_solve_their_problem(problem, fixture_cases):
    name, a, b, q, r = problem
    case = fixture_cases[name]
    for key, matrix in (("a", a), ("b", b), ("q", q), ("r", r)):
        # The generator's random case goes through LAPACK (an eigenvalue shift) and BLAS: a few
        # ulps apart on another CPU (measured 2e-16 relative); the shear cases are exact.
        np.testing.assert_allclose(np.array(case[key]), matrix, rtol=0, atol=1e-14 * np.linalg.norm(matrix),
                                   err_msg=f"{name}: {key}")
    a, b, q, r = (np.array(case[key]) for key in ("a", "b", "q", "r"))
    for solver in ("scipy", "control"):
        x = np.array(case[solver]["x"])
        assert np.allclose(x, x.T, rtol=0, atol=1e-12 * np.linalg.norm(x)), f"{name}: {solver} X not symmetric"
        relative = riccati_reference.relative_residual(a, b, q, r, x)
        assert relative <= RESIDUAL, f"{name}: {solver}'s stored X has residual {relative:.2e}"
        gain = np.array(case[solver]["gain"])
        assert np.allclose(gain, np.linalg.solve(r, b.T @ x), rtol=1e-12, atol=0), f"{name}: {solver} K ≠ R⁻¹BᵀX"
        poles = np.linalg.eigvals(a - b @ gain)
        assert np.all(poles.real < 0), f"{name}: {solver}'s stored X is not stabilising"
    stored = riccati_reference.relative_difference(np.array(case["scipy"]["x"]), np.array(case["control"]["x"]))
    assert stored <= riccati_reference.SOLVER_AGREEMENT


@pytest.mark.parametrize("problem", PROBLEMS, ids=[name for name, *_ in PROBLEMS])
def test_live_solvers_land_where_the_conditioning_allows(problem, fixture_cases):
    name = problem[0]
    case = fixture_cases[name]
    a, b, q, r = (np.array(case[key]) for key in ("a", "b", "q", "r"))
    live = riccati_reference.solve(a, b, q, r)
    gain_map = np.linalg.norm(np.linalg.solve(r, b.T), 2)
    for solver in ("scipy", "control"):
        stored_x = np.array(case[solver]["x"])
        live_x = live[solver]["x"]
        first_order = (np.linalg.norm(residual(a, b, q, r, stored_x)) + np.linalg.norm(residual(a, b, q, r, live_x))) / separation(a, b, r, stored_x)
        allowed = 2.0 * first_order + 64 * np.finfo(float).eps * np.linalg.norm(stored_x)
        moved = np.linalg.norm(live_x - stored_x)
        assert moved <= allowed, f"{name}: {solver}'s X moved {moved:.2e}, its conditioning allows {allowed:.2e}"
        moved_gain = np.linalg.norm(live[solver]["gain"] - np.array(case[solver]["gain"]))
        assert moved_gain <= gain_map * allowed, f"{name}: {solver}'s K moved {moved_gain:.2e}, allowed {gain_map * allowed:.2e}"
    assert max(live["agreement"].values()) <= riccati_reference.SOLVER_AGREEMENT
