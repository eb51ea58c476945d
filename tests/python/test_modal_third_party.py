"""The third-party check of `twin modal --data`: a synthetic record of a known five-storey
building (tests/python/modal_records.py) identified by `twin modal --data` and by strid's
covariance-driven SSI (strid 0.4.3, with its own stability criteria) gives the same modes, and
both agree with the exact modes of the building's M, C, K.

The `twin` binary is target/release/twin (cargo build --release -p orchestrator --bin twin), or
the file named by the environment variable TWIN_BIN.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import modal_records as mr
from conftest import run_twin_ok


DURATION = 1200.0
DT = 0.01




@pytest.fixture(scope="module")
def identified(twin_binary, tmp_path_factory):
    folder = tmp_path_factory.mktemp("modal")
    record = folder / "five-storey.csv"
    _, _, acc = mr.write_record(record, DURATION, DT, seed=3)
    report = folder / "modes.json"
    run_twin_ok(twin_binary, "modal", "--data", str(record), "--report", str(report), timeout=600)
    ours = json.loads(report.read_text())["record"]
    theirs = mr.strid_modes(acc, 1.0 / DT)
    return ours, theirs, mr.exact_modes()


def shape(mode) -> np.ndarray:
    return np.array([complex(re, im) for re, im in mode["displacement_shape"]])


def test_ours_and_strid_find_the_same_modes_as_the_exact_ones(identified):
    ours, theirs, exact = identified
    ssi = ours["ssi"]["modes"]
    lscf = ours["input_output"]["modes"]
    assert len(ssi) == len(exact) == len(theirs) == len(lscf), (ssi, theirs)
    for k, (e, s, t, io) in enumerate(zip(exact, ssi, theirs, lscf)):
        f_exact, z_exact, phi_exact = e
        f_theirs, z_theirs, phi_theirs = t
        print(f"mode {k + 1}: exact {f_exact:.4f} Hz {100 * z_exact:.3f} %; "
              f"ours SSI-COV {s['frequency']:.4f} Hz {100 * s['damping']:.3f} %, "
              f"LSCF {io['frequency']:.4f} Hz {100 * io['damping']:.3f} %; "
              f"strid {f_theirs:.4f} Hz {100 * z_theirs:.3f} %; "
              f"MAC ours/strid {mr.mac(shape(s), phi_theirs):.5f}")
        # All three against the exact modes: the bars (0.5 %, 10 %, MAC 0.99). Measured
        # on this record: ours (SSI-COV) within 0.05 % in frequency, 5.5 % in damping, MAC 0.9999;
        # LSCF within 0.003 %, 0.8 %; strid within 0.05 %, 4.6 %.
        for name, f, z, phi in [("ours", s["frequency"], s["damping"], shape(s)),
                                ("LSCF", io["frequency"], io["damping"], shape(io)),
                                ("strid", f_theirs, z_theirs, phi_theirs)]:
            assert abs(f / f_exact - 1) < 0.005, (name, k, f, f_exact)
            assert abs(z / z_exact - 1) < 0.10, (name, k, z, z_exact)
            assert mr.mac(phi, phi_exact) > 0.99, (name, k)
        # Ours against strid's, the same method (SSI-COV, 20 block rows, orders 2..40): measured
        # within 0.093 % in frequency (mode 5), 7.0 % in damping (mode 5), MAC ≥ 0.9965; held to
        # 0.4 %, 15 % and 0.99.
        assert abs(s["frequency"] / f_theirs - 1) < 0.004
        assert abs(s["damping"] / z_theirs - 1) < 0.15
        assert mr.mac(shape(s), phi_theirs) > 0.99
