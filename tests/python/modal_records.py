"""Synthetic records of a known shear building for the modal cross-checks (the third-party test
and scripts/bench_modal.py), and strid's covariance-driven SSI on them with its own stability
criteria.

The building: floors' masses and storeys' stiffnesses below, Rayleigh damping 1 % on the first
mode and 2 % on the last, a white-noise force at the top floor, every floor's absolute
acceleration measured with white noise of 2 % of its RMS; simulated with the exact zero-order-hold
discretisation of the state space (scipy's matrix exponential).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.signal

MASS = [1.2e4, 1.1e4, 1.0e4, 0.9e4, 0.8e4]
STIFFNESS = [2.4e7, 2.2e7, 2.0e7, 1.8e7, 1.5e7]
DAMPING = (0.01, 0.02)
NOISE_FRACTION = 0.02


def matrices(stiffness=None):
    n = len(MASS)
    m = np.diag(MASS)
    k = np.zeros((n, n))
    for i, ki in enumerate(STIFFNESS if stiffness is None else stiffness):
        k[i, i] += ki
        if i > 0:
            k[i - 1, i - 1] += ki
            k[i - 1, i] -= ki
            k[i, i - 1] -= ki
    w = np.sqrt(np.sort(scipy.linalg.eigh(k, m, eigvals_only=True)))
    w1, wn = w[0], w[-1]
    b = 2.0 * (DAMPING[1] * wn - DAMPING[0] * w1) / (wn**2 - w1**2)
    a = 2.0 * DAMPING[0] * w1 - b * w1**2
    return m, a * m + b * k, k


def exact_modes():
    """(frequency Hz, damping ratio, displacement shape) of each mode, by frequency."""
    m, c, k = matrices()
    n = len(MASS)
    minv = np.linalg.inv(m)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ k, -minv @ c]])
    values, vectors = np.linalg.eig(a)
    modes = []
    for lam, vec in zip(values, vectors.T):
        if lam.imag > 0:
            modes.append((abs(lam) / (2 * np.pi), -lam.real / abs(lam), vec[:n]))
    return sorted(modes, key=lambda mode: mode[0])


def simulate(duration: float, dt: float, seed: int, stiffness=None):
    """(time, force, accelerations (floors × samples)); `stiffness` other storey stiffnesses
    (the damping stays the building's)."""
    m, c, _ = matrices()
    _, _, k = matrices(stiffness)
    n = len(MASS)
    minv = np.linalg.inv(m)
    load = np.zeros(n)
    load[-1] = 1.0
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ k, -minv @ c]])
    b = np.concatenate([np.zeros(n), minv @ load])[:, None]
    cmat = np.hstack([-minv @ k, -minv @ c])
    dmat = (minv @ load)[:, None]
    augmented = np.zeros((2 * n + 1, 2 * n + 1))
    augmented[: 2 * n, : 2 * n] = a
    augmented[: 2 * n, 2 * n :] = b
    exponential = scipy.linalg.expm(augmented * dt)
    ad, bd = exponential[: 2 * n, : 2 * n], exponential[: 2 * n, 2 * n :]
    samples = int(round(duration / dt))
    rng = np.random.default_rng(seed)
    force = 0.01 * 9.81 * sum(MASS) * rng.standard_normal(samples)
    _, y, _ = scipy.signal.dlsim((ad, bd, cmat, dmat, dt), force)
    y = y.T
    rms = np.sqrt(np.mean(y**2, axis=1, keepdims=True))
    y = y + NOISE_FRACTION * rms * rng.standard_normal(y.shape)
    return np.arange(samples) * dt, force, y


def write_record(path: Path, duration: float, dt: float, seed: int):
    time, force, acc = simulate(duration, dt, seed)
    header = "time,force," + ",".join(f"acc{i + 1}" for i in range(acc.shape[0]))
    np.savetxt(path, np.column_stack([time, force, acc.T]), delimiter=",", header=header,
               comments="", fmt="%.9g")
    return time, force, acc


def mac(a, b) -> float:
    return float(abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))


def strid_modes(acc: np.ndarray, fs: float, max_order: int = 40, block_rows: int = 20,
                min_fraction: float = 0.3):
    """strid's SSI-COV at orders 2..max_order, its own stability test (its StabilizationDiagram's
    filter_modes and find_stable_modes: 1 % frequency, 5 % damping, MAC 0.98 against the previous
    order); strid picks modes by hand in a plot, so its stable poles are grouped here by frequency
    (1 %), a group seen in at least `min_fraction` of the orders is a mode, and its median
    frequency and damping, and the shape of its pole nearest the median, are reported:
    [(frequency, damping, shape)]."""
    import strid

    ssid = strid.CovarianceDrivenStochasticSID(acc, fs)
    modes = {}
    for order in range(2, max_order + 1, 2):
        a, c, _, _ = ssid.perform(order, block_rows)
        modes[order] = strid.Mode.find_modes_from_ss(a, c, ssid.fs)
    # The two methods use nothing of the diagram's state (its figure): called without one.
    modes = strid.StabilizationDiagram.filter_modes(None, modes)
    stable = strid.StabilizationDiagram.find_stable_modes(None, modes)
    groups: list[list] = []
    for order in sorted(stable):
        for mode in stable[order]:
            if not 0 < mode.xi < 0.2:
                continue
            home = [g for g in groups if abs(mode.f / g[-1].f - 1) <= 0.01]
            if home:
                min(home, key=lambda g: abs(mode.f / g[-1].f - 1)).append(mode)
            else:
                groups.append([mode])
    needed = max(3, int(np.ceil(min_fraction * len(modes))))
    found = []
    for group in groups:
        if len(group) < needed:
            continue
        f = float(np.median([m.f for m in group]))
        xi = float(np.median([m.xi for m in group]))
        nearest = min(group, key=lambda m: abs(m.f - f))
        found.append((f, xi, nearest.v))
    return sorted(found, key=lambda mode: mode[0])
