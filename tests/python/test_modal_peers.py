"""`twin modal --data` against two third-party modal toolboxes on the same records, made by the
project's own generator (`twin synth`):

- pyOMA2 1.4.3: its covariance-driven SSI (`SSI`, method "cov") against ours (SSI-COV), and its
  EFDD against our FDD/EFDD; output-only, from the responses alone.
- sdypy-EMA 0.31.0: its LSCF on the H1 FRF (scipy's Welch, the segment `twin modal` uses by
  default: a quarter of the record) against our LSCF; input-output, through the measured force.

The peers pick poles by hand in a stabilisation diagram; here their poles are picked
automatically near our modes' frequencies: a pole counts when it is stable (pyOMA2: its own
label of a stable pole; sdypy-EMA: within 0.5 % in frequency and 10 % in damping of a pole of the
order below) and within 1 % of our frequency, and at least three such poles make the peer's
mode (their median). Two habits of the peers this works around, both seen on these records:
sdypy-EMA's pole frequencies carry the sign of the pole's imaginary part, so its own
`select_closest_poles` finds the negative-frequency half unstable and returns 0 Hz for most
modes; pyOMA2's pLSCF is not used: its automatic `mpe(order="find_min")` looks for a stability
label (7) its pole labelling never gives (0 or 1), and over the record's whole band (0–100 Hz,
the force only to 40 Hz) its stable poles at order 20 sit at 14.7 Hz alone (measured).

The `twin` binary is target/release/twin, or the file named by the environment variable TWIN_BIN.
"""

from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from conftest import run_twin_ok


# The band-limited five-storey building of tests/modal_buildings.rs (5.0–33.9 Hz, 0.36–2.3 %):
# force at floor 2, 0.5–40 Hz, 200 Hz for 300 s, every floor measured, 2 % sensor noise.
FIVE = ["--storeys", "5", "--excitation", "force:2", "--mass", "5.2,5.2,5.2,5.2,5.2",
        "--stiffness", "64000,64000,64000,64000,64000", "--damping", "14,14,14,14,14",
        "--sample-rate", "200", "--duration", "300", "--low-hz", "0.5", "--band-hz", "40",
        "--noise-fraction", "0.02", "--force-rms", "1", "--seed", "11"]
# The laboratory frame (3.170 / 9.030 / 13.430 Hz, 0.39 / 1.05 / 1.48 %): a shaker at
# floor 1, 1–60 Hz, 500 Hz for 30 s, one accelerometer per run.
LAB = ["--storeys", "3", "--excitation", "force:1", "--mass", "5.201,5.201,5.201",
       "--stiffness", "9562,11806,11332", "--damping", "4,4,4", "--sample-rate", "500",
       "--duration", "30", "--low-hz", "1", "--band-hz", "60", "--noise-fraction", "0.02",
       "--force-rms", "1"]




def synth_and_identify(twin: Path, folder: Path, name: str, flags: list[str]):
    """`twin synth` a record, `twin modal --data` it: (force, responses, fs, our report's
    record modes, the truth's m, c, k)."""
    record, truth, report = (folder / f"{name}.csv", folder / f"{name}.json",
                             folder / f"{name}-modes.json")
    for command in (["synth", "--out", str(record), "--truth", str(truth), *flags],
                    ["modal", "--data", str(record), "--report", str(report)]):
        run_twin_ok(twin, *command, timeout=600)
    data = np.loadtxt(record, delimiter=",", skiprows=1)
    structure = json.loads(truth.read_text())["structure"]
    mck = tuple(np.asarray(structure[key], float) for key in ("m", "c", "k"))
    fs = 1.0 / (data[1, 0] - data[0, 0])
    return data[:, 1], data[:, 2:], fs, json.loads(report.read_text())["record"], mck


def exact_modes(m, c, k) -> list[tuple[float, float]]:
    """(frequency Hz, damping ratio) of the shear building of floor masses m and storey
    dampers c and springs k, by frequency."""
    def storey(values):
        a = np.diag(values + np.append(values[1:], 0.0))
        return a - np.diag(values[1:], 1) - np.diag(values[1:], -1)
    n = len(m)
    minv = np.diag(1.0 / m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ storey(k), -minv @ storey(c)]])
    values = [v for v in scipy.linalg.eigvals(a) if v.imag > 0]
    return sorted((abs(v) / (2 * np.pi), -v.real / abs(v)) for v in values)


def near(poles: np.ndarray, frequency: float, least: int = 3):
    """The median (frequency, damping) of the stable poles [(f, ζ)] within 1 % of `frequency`,
    None when fewer than `least`."""
    close = poles[np.abs(poles[:, 0] / frequency - 1.0) < 0.01] if len(poles) else poles
    if len(close) < least:
        return None
    return float(np.median(close[:, 0])), float(np.median(close[:, 1]))


def pyoma2_ssi_poles(acc: np.ndarray, fs: float) -> np.ndarray:
    """pyOMA2's SSI-COV (20 block rows, orders to 40, as ours): its stable poles [(f, ζ)]."""
    from pyoma2.algorithms import SSI
    from pyoma2.setup import SingleSetup

    setup = SingleSetup(acc, fs=fs)
    setup.add_algorithms(SSI(name="ssi", method="cov", br=20, ordmax=40))
    setup.run_all()
    result = setup["ssi"].result
    f, z = np.nan_to_num(result.Fn_poles), np.nan_to_num(result.Xi_poles)
    stable = (np.asarray(result.Lab) == 1) & (z > 0) & (z < 0.2)
    return np.column_stack([f[stable], z[stable]])


def pyoma2_efdd(acc: np.ndarray, fs: float, frequencies: list[float]):
    """pyOMA2's EFDD at `frequencies`: [(f, ζ)]."""
    from pyoma2.algorithms import EFDD
    from pyoma2.setup import SingleSetup

    setup = SingleSetup(acc, fs=fs)
    setup.add_algorithms(EFDD(name="efdd", nxseg=4096))
    setup.run_all()
    setup.mpe("efdd", sel_freq=frequencies)
    result = setup["efdd"].result
    return list(zip(np.asarray(result.Fn, float), np.asarray(result.Xi, float)))


def sdypy_lscf_poles(force, acc, fs, band) -> np.ndarray:
    """sdypy-EMA's LSCF (orders to 40) on the H1 FRF over `band`, Welch segments of a quarter
    of the record: its poles [(f, ζ)] stable from one order to the next (0.5 %, 10 %)."""
    from sdypy import EMA

    segment = len(force) // 4
    f, pff = scipy.signal.welch(force, fs, nperseg=segment)
    frf = np.array([scipy.signal.csd(force, y, fs, nperseg=segment)[1] / pff for y in acc.T])
    model = EMA.Model(frf=frf, freq=f, lower=band[0], upper=band[1], pol_order_high=40,
                      frf_form="accelerance")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.get_poles(show_progress=False)
    stable = []
    for below, poles in zip(model.all_poles, model.all_poles[1:]):
        below = np.asarray(below)
        below = below[below.imag > 0]
        if not len(below):
            continue
        for pole in np.asarray(poles):
            f_pole, z_pole = abs(pole) / (2 * np.pi), -pole.real / abs(pole)
            if pole.imag <= 0 or not 0 < z_pole < 0.2:
                continue
            j = np.argmin(np.abs(np.abs(below) - abs(pole)))
            z_below = -below[j].real / abs(below[j])
            if abs(abs(below[j]) / abs(pole) - 1) < 0.005 and abs(z_below / z_pole - 1) < 0.1:
                stable.append((f_pole, z_pole))
    return np.array(stable).reshape(-1, 2)


def fz(mode) -> tuple[float, float]:
    return mode["frequency"], mode["damping"]


@pytest.fixture(scope="module")
def five_storeys(twin_binary, tmp_path_factory):
    logging.disable(logging.WARNING)  # pyOMA2 logs each step at INFO/WARNING
    return synth_and_identify(twin_binary, tmp_path_factory.mktemp("peers"), "five", FIVE)


def test_ssi_cov_agrees_with_pyoma2s(five_storeys):
    _, acc, fs, ours, mck = five_storeys
    exact = exact_modes(*mck)
    theirs = pyoma2_ssi_poles(acc, fs)
    ssi = ours["ssi"]["modes"]
    assert len(ssi) == len(exact), [m["frequency"] for m in ssi]
    for k, (mode, (f_exact, _)) in enumerate(zip(ssi, exact)):
        f, z = fz(mode)
        peer = near(theirs, f)
        print(f"mode {k + 1}: exact {f_exact:.4f} Hz; ours {f:.4f} Hz {100 * z:.3f} %; "
              f"pyOMA2 {peer}")
        assert peer is not None, f"pyOMA2's SSI has no stable pole near {f} Hz"
        # Measured: within 0.006 % in frequency and 0.9 % in damping (mode 5, 2.14 % against
        # 2.16 %); held to 0.05 % and 5 %.
        assert abs(f / peer[0] - 1) < 5e-4, (k, f, peer)
        assert abs(z / peer[1] - 1) < 0.05, (k, z, peer)


def test_lscf_agrees_with_sdypy_emas(five_storeys):
    force, acc, fs, ours, mck = five_storeys
    exact = exact_modes(*mck)
    io = ours["input_output"]
    theirs = sdypy_lscf_poles(force, acc, fs, io["band"])
    assert len(io["modes"]) == len(exact), [m["frequency"] for m in io["modes"]]
    for k, (mode, (f_exact, z_exact)) in enumerate(zip(io["modes"], exact)):
        f, z = fz(mode)
        peer = near(theirs, f)
        print(f"mode {k + 1}: exact {f_exact:.4f} Hz {100 * z_exact:.3f} %; ours {f:.4f} Hz "
              f"{100 * z:.3f} %; sdypy-EMA {peer}")
        assert peer is not None, f"sdypy-EMA's LSCF has no stable pole near {f} Hz"
        # Measured: within 0.015 % in frequency (mode 5) and 10.2 % in damping (mode 1:
        # ours, refined in the time domain, 0.346 % against sdypy-EMA's 0.385 %; the exact
        # 0.345 %; the other modes within 0.8 %); held to 0.1 % and 15 %.
        assert abs(f / peer[0] - 1) < 1e-3, (k, f, peer)
        assert abs(z / peer[1] - 1) < 0.15, (k, z, peer)
    # Nothing of ours that sdypy-EMA's stable poles do not support, and the reverse for the
    # exact modes: every one is in both.
    for f_exact, _ in exact:
        assert near(theirs, f_exact) is not None, f_exact


def test_fdd_agrees_with_pyoma2s_efdd(five_storeys):
    _, acc, fs, ours, mck = five_storeys
    exact = exact_modes(*mck)
    fdd = [m for m in ours["fdd"]["modes"]
           if any(abs(m["frequency"] / f - 1) < 0.01 for f, _ in exact)]
    assert len(fdd) == len(exact), [m["frequency"] for m in ours["fdd"]["modes"]]
    theirs = pyoma2_efdd(acc, fs, [m["frequency"] for m in fdd])
    for k, (mode, peer) in enumerate(zip(fdd, theirs)):
        f, z = fz(mode)
        print(f"mode {k + 1}: ours FDD/EFDD {f:.4f} Hz {100 * z:.3f} %; pyOMA2 EFDD "
              f"{peer[0]:.4f} Hz {100 * peer[1]:.3f} %")
        # Measured: within 0.46 % (mode 3) in frequency; held to 1 %. The damping is not
        # compared: pyOMA2's EFDD gives 1.66 % for mode 1 (exact 0.36 %, ours 0.26 %) and
        # 2.9 % for mode 2 (exact 1.0 %) on this record — its SDOF bell takes in the
        # neighbouring bins of a peak narrower than its 0.05 Hz bins.
        assert abs(f / peer[0] - 1) < 0.01, (k, f, peer)


@pytest.mark.parametrize("floor", [1, 2, 3])
def test_a_lab_frames_runs_agree_with_sdypy_emas_lscf(twin_binary, tmp_path, floor):
    force, acc, fs, ours, mck = synth_and_identify(
        twin_binary, tmp_path, f"lab{floor}",
        LAB + ["--channels", f"acc{floor}", "--seed", str(40 + floor)])
    exact = exact_modes(*mck)
    io = ours["input_output"]
    theirs = sdypy_lscf_poles(force, acc, fs, io["band"])
    for k, (f_exact, z_exact) in enumerate(exact):
        mode = min(io["modes"], key=lambda m: abs(m["frequency"] / f_exact - 1))
        f, z = fz(mode)
        peer = near(theirs, f)
        print(f"run {floor} mode {k + 1}: exact {f_exact:.4f} Hz {100 * z_exact:.3f} %; ours "
              f"{f:.4f} Hz {100 * z:.3f} %; sdypy-EMA {peer}")
        assert abs(f / f_exact - 1) < 0.01, (k, f, f_exact)
        assert peer is not None, f"sdypy-EMA's LSCF has no stable pole near {f} Hz"
        # Measured (runs 1, 2, 3): mode 1 −0.03, +0.38, +0.38 % from sdypy-EMA's (ours within
        # 0.003 % of the exact), modes 2–3 within 0.15 %; held to 1 %, the bar.
        assert abs(f / peer[0] - 1) < 0.01, (k, f, peer)
        # Ours against the exact damping: measured within 0.3 % (mode 1, 0.39 %, narrower
        # than a bin of a 30 s run's FRF, refined in the time domain); held to the 10 %.
        assert abs(z / z_exact - 1) < 0.10, (k, z, z_exact)
        if k > 0:
            # Modes 2–3, measured within 12.3 % of sdypy-EMA's damping (run 2's mode 2: 1.052 %
            # against 1.200 %; the exact 1.054 %); held to 25 %. Mode 1 is leaked high by
            # sdypy-EMA's FRF fit (1.23–1.78 % for 0.39 %), so it is not compared.
            assert abs(z / peer[1] - 1) < 0.25, (k, z, peer)
