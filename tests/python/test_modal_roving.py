"""``shear_twin.identify_modes`` (``twin modal --data RUN1 --data RUN2 …``) on a roving test: the
issue's laboratory frame (3.170 / 9.030 / 13.430 Hz, 0.39 / 1.05 / 1.48 %), a shaker at floor 1
band-limited to 1–60 Hz, 500 Hz for 30 s per run, one accelerometer moved floor to floor over
three runs (``shear_twin.synth``, 2 % sensor noise). The three runs merge into three modes with
shapes at the three floors, checked against the exact modes of the frame's M, C, K (scipy);
one run alone gives the same frequencies with a one-floor shape; a run sampled at another rate
is refused with ``DataError``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import shear_twin as st

MASS = [5.201, 5.201, 5.201]
DAMPING = [4.0, 4.0, 4.0]
STIFFNESS = [9562.0, 11806.0, 11332.0]


def scenario(floor: int, seed: int) -> dict:
    return {"storeys": 3, "parameters": {"m": MASS, "c": DAMPING, "k": STIFFNESS},
            "excitation": "force:1", "sample_rate": 500.0, "duration": 30.0, "seed": seed,
            "force": {"rms": 1.0, "band_hz": 60.0, "low_hz": 1.0},
            "noise": {"fraction": 0.02}, "channels": [f"acc{floor} (m/s2)"]}


def storey(values) -> np.ndarray:
    v = np.asarray(values, float)
    a = np.diag(v + np.append(v[1:], 0.0))
    return a - np.diag(v[1:], 1) - np.diag(v[1:], -1)


def exact_modes():
    """(frequency Hz, damping ratio, displacement shape) of the frame, by frequency."""
    n = len(MASS)
    minv = np.diag(1.0 / np.asarray(MASS))
    a = np.block([[np.zeros((n, n)), np.eye(n)],
                  [-minv @ storey(STIFFNESS), -minv @ storey(DAMPING)]])
    values, vectors = scipy.linalg.eig(a)
    modes = [(abs(v) / (2 * np.pi), -v.real / abs(v), vectors[:n, i])
             for i, v in enumerate(values) if v.imag > 0]
    return sorted(modes, key=lambda m: m[0])


def mac(a, b) -> float:
    return float(abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))


def shape(mode) -> np.ndarray:
    return np.array([complex(re, im) for re, im in mode["displacement_shape"]])


@pytest.fixture(scope="module")
def runs():
    return [st.synth(scenario(floor, 40 + floor))[0] for floor in (1, 2, 3)]


def test_three_roving_runs_give_three_modes_with_shapes_at_three_floors(runs):
    found = st.identify_modes(runs)
    assert found["floors"] == [1, 2, 3]
    modes = found["input_output"]["modes"]
    exact = exact_modes()
    assert len(modes) == len(exact), [m["frequency"] for m in modes]
    for k, (mode, (f, z, phi)) in enumerate(zip(modes, exact)):
        error = mode["frequency"] / f - 1
        damping = mode["damping"] / z - 1
        shape_mac = mac(shape(mode), phi)
        print(f"mode {k + 1}: {mode['frequency']:.4f} Hz ({100 * error:+.3f} %), "
              f"ζ {100 * mode['damping']:.3f} % for {100 * z:.3f} %, MAC {shape_mac:.5f}")
        # Measured: within 0.002 % in frequency, 0.3 % in damping (mode 1: 0.386 % for
        # 0.387 %), MAC 1.00000; held to the 1 %, 10 % and MAC 0.95.
        assert abs(error) < 0.01, (k, mode["frequency"], f)
        assert abs(damping) < 0.10, (k, mode["damping"], z)
        assert shape_mac >= 0.95, (k, shape_mac)


def test_one_run_alone_gives_the_frequencies_at_its_floor(runs):
    found = st.identify_modes(runs[1])
    assert found["floors"] == [2]
    frequencies = [m["frequency"] for m in found["input_output"]["modes"]]
    for f, _, _ in exact_modes():
        nearest = min(frequencies, key=lambda g: abs(g / f - 1))
        # Measured within 0.01 %; held to 1 %.
        assert abs(nearest / f - 1) < 0.01, (f, frequencies)


def test_runs_of_another_sampling_rate_are_refused(runs):
    other = scenario(3, 43)
    other["sample_rate"] = 250.0
    with pytest.raises(st.DataError, match="Hz|sampl"):
        st.identify_modes(runs[:2] + [st.synth(other)[0]])
