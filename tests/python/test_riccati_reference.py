"""The committed Riccati fixture (numerics/tests/data/care_reference.json) is what scipy and
python-control (on SLICOT) give today: every case's problem is rebuilt by
scripts/riccati_reference.py and solved again, live, and the file must match to 1e-10 (relative,
Frobenius) — so the reference the Rust solver is tested against cannot go stale.

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
TOLERANCE = 1e-10

PROBLEMS = list(riccati_reference.problems())


@pytest.fixture(scope="module")
def fixture_cases() -> dict:
    reference = json.loads(FIXTURE.read_text())
    return {case["name"]: case for case in reference["cases"]}


def test_fixture_has_exactly_the_generated_cases(fixture_cases):
    assert list(fixture_cases) == [name for name, *_ in PROBLEMS]


@pytest.mark.parametrize("problem", PROBLEMS, ids=[name for name, *_ in PROBLEMS])
def test_fixture_matches_scipy_and_python_control(problem, fixture_cases):
    name, a, b, q, r = problem
    case = fixture_cases[name]
    for key, matrix in (("a", a), ("b", b), ("q", q), ("r", r)):
        np.testing.assert_array_equal(np.array(case[key]), matrix, err_msg=f"{name}: {key}")
    live = riccati_reference.solve(a, b, q, r)
    for solver in ("scipy", "control"):
        for key in ("x", "gain"):
            stored = np.array(case[solver][key])
            difference = riccati_reference.relative_difference(stored, live[solver][key])
            assert difference <= TOLERANCE, f"{name}: {solver} {key} moved by {difference:.2e}"
    assert max(live["agreement"].values()) <= riccati_reference.SOLVER_AGREEMENT
