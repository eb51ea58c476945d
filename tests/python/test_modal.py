"""``Twin.modes()`` (``twin modal --twin``) against scipy: the natural frequencies, damping ratios
and shapes of a five-storey twin equal those of scipy's eigen-decomposition of the same M, C, K
(an independent solver: LAPACK's geev on the first-order system); an uncalibrated twin has no
sds; the shapes plot is written.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

import shear_twin as st

NOMINAL = {"m": [5.2, 5.0, 4.8, 4.6, 4.4], "c": [3.0, 2.5, 2.5, 2.0, 2.0],
           "k": [5200.0, 4800.0, 4400.0, 4000.0, 3600.0]}


def storey_matrix(values):
    n = len(values)
    a = np.zeros((n, n))
    for i, v in enumerate(values):
        a[i, i] += v
        if i > 0:
            a[i - 1, i - 1] += v
            a[i - 1, i] -= v
            a[i, i - 1] -= v
    return a


def scipy_modes(m, c, k):
    n = len(m)
    minv = np.diag(1.0 / np.asarray(m))
    a = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-minv @ storey_matrix(k), -minv @ storey_matrix(c)]])
    values, vectors = scipy.linalg.eig(a)
    keep = values.imag > 0
    values, vectors = values[keep], vectors[:n, keep]
    order = np.argsort(np.abs(values))
    values, vectors = values[order], vectors[:, order]
    shapes = []
    for j in range(vectors.shape[1]):
        v = vectors[:, j]
        v = v / v[np.argmax(np.abs(v))]
        shapes.append(v.real)
    return np.abs(values) / (2 * np.pi), -values.real / np.abs(values), shapes


def test_the_twins_modes_are_scipys(tmp_path):
    twin = st.init(storeys=5, excitation="base", nominal=NOMINAL)
    plot = tmp_path / "modes.svg"
    modes = twin.modes(plot=str(plot))
    assert modes["storeys"] == 5 and modes["excitation"] == "base"
    assert plot.read_text().startswith("<svg")
    f, z, shapes = scipy_modes(NOMINAL["m"], NOMINAL["c"], NOMINAL["k"])
    got = modes["modes"]
    assert len(got) == 5
    for mode, fi, zi, si in zip(got, f, z, shapes):
        # Two eigen-solvers on the same matrix: agreement to rounding (seen ≤ 1e-13).
        assert abs(mode["frequency"] - fi) / fi < 1e-9
        assert abs(mode["damping"] - zi) < 1e-9
        assert np.max(np.abs(np.asarray(mode["shape"]) - si)) < 1e-9
        # Uncalibrated: no posterior, no sd.
        assert mode["frequency_sd"] is None and mode["sampled"] is None
