#!/usr/bin/env python3
"""A real shake-table record checked by hand against `twin modal --data`.

Converts one run of a small three-storey frame on a uniaxial shake table, one Xsens DOT
inertial sensor per level recorded in sync (ground, floors 1-3; the frame and its files are
described in docs/src/decisions/real-record-check.md), into a record
`time,ground_acc,acc1,acc2,acc3` (s, m/s²), then lists the peaks of its H1 FRF (ground to each
floor, Welch, Hann) with their coherence: the reference the identified modes are read against.

    python3 scripts/real_record_check.py RUN_DIR LABEL OUT.csv [--segment 1024 2048]

RUN_DIR holds the four level folders (`Ground Floor`, `1st Floor`, `2nd Floor`,
`3rd Floor (Top floor)`); LABEL picks the run's file in each, e.g. `(Northridge)`.
Each sensor's horizontal acceleration is taken along its own principal direction (the table
shakes along one axis; each sensor sits at its own heading), its sign chosen so the floor moves
with the table below 1 Hz, and gravity's offset (the mean) removed.
"""

import argparse
import pathlib

import numpy as np
from scipy import signal

LEVELS = ["Ground Floor", "1st Floor", "2nd Floor", "3rd Floor (Top floor)"]


def read_sensor(path):
    """The sensor's rows: packet counter, sample time (µs), Euler angles, acc (m/s²), gyro."""
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("PacketCounter"))
    return np.loadtxt(lines[start + 1 :], delimiter=",")


def levels(run_dir, label):
    rows = []
    for level in LEVELS:
        matches = sorted(p for p in (run_dir / level).glob("*.csv") if label in p.name)
        if len(matches) != 1:
            raise SystemExit(f"{run_dir / level}: {len(matches)} files match {label!r}")
        rows.append(read_sensor(matches[0]))
    # the samples every sensor recorded (they share one clock), the first all-zero row dropped
    t0 = max(r[0, 1] for r in rows)
    t1 = min(r[-1, 1] for r in rows)
    rows = [r[(r[:, 1] >= t0) & (r[:, 1] <= t1)] for r in rows]
    rows = [r[1:] if not r[0, 5:8].any() else r for r in rows]
    n = min(len(r) for r in rows)
    rows = [r[:n] for r in rows]
    clock = rows[0][:, 1]
    for r in rows:
        if not np.array_equal(r[:, 1], clock):
            raise SystemExit("the sensors' sample times differ: not one synchronised run")
    return clock, rows


def along_shaking(rows, rate):
    series = []
    for r in rows:
        horizontal = r[:, 5:7] - r[:, 5:7].mean(axis=0)
        _, vectors = np.linalg.eigh(horizontal.T @ horizontal)
        series.append(horizontal @ vectors[:, -1])
    for j in range(1, len(series)):
        f, cross = signal.csd(series[0], series[j], fs=rate, nperseg=1024)
        if np.real(cross[(f > 0.3) & (f < 1.0)]).sum() < 0:
            series[j] = -series[j]
    return series


def write_record(path, times, series):
    with open(path, "w") as out:
        out.write("time,ground_acc,acc1,acc2,acc3\n")
        for k, t in enumerate(times):
            out.write(f"{t:.6f}," + ",".join(f"{s[k]:.6g}" for s in series) + "\n")


def frf_peaks(series, rate, segment):
    """Peaks of the floors' FRF magnitudes taken together (root sum of squares), each standing
    twice above the curve's lowest level within ±10 % on both sides, with the largest coherence
    of any floor at the peak's bin and within two bins of it."""
    ground = series[0]
    f, pxx = signal.welch(ground, fs=rate, nperseg=segment)
    frfs, cohs = [], []
    for s in series[1:]:
        _, pxy = signal.csd(ground, s, fs=rate, nperseg=segment)
        frfs.append(pxy / pxx)
        cohs.append(signal.coherence(ground, s, fs=rate, nperseg=segment)[1])
    level = np.sqrt((np.abs(np.array(frfs)) ** 2).sum(axis=0))
    coh = np.array(cohs)
    found = []
    for k in signal.find_peaks(level)[0]:
        width = max(2, int(0.1 * k))
        lo, hi = level[max(0, k - width) : k + 1].min(), level[k : k + width + 1].min()
        if f[k] < 0.5 or level[k] < 2 * lo or level[k] < 2 * hi:
            continue
        a, b, c = np.log(level[k - 1 : k + 2])
        shift = 0.5 * (a - c) / (a - 2 * b + c)
        found.append(
            (
                f[k] + shift * (f[1] - f[0]),
                level[k] / level.max(),
                coh[:, k].max(),
                coh[:, max(0, k - 2) : k + 3].max(),
            )
        )
    return f[1] - f[0], found


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=pathlib.Path)
    parser.add_argument("label")
    parser.add_argument("out", type=pathlib.Path)
    parser.add_argument("--segment", type=int, nargs="+", default=[1024, 2048])
    parser.add_argument("--least", type=float, default=0.05, help="peaks below this share of the largest are not listed")
    args = parser.parse_args()
    clock, rows = levels(args.run_dir, args.label)
    rate = 1e6 / np.median(np.diff(clock))
    series = along_shaking(rows, rate)
    write_record(args.out, (clock - clock[0]) / 1e6, series)
    print(f"{args.out}: {len(clock)} samples at {rate:.4f} Hz")
    for segment in args.segment:
        resolution, found = frf_peaks(series, rate, segment)
        averages = 2 * len(clock) // segment - 1
        print(f"H1, segments of {segment} ({averages} averages, bins {resolution:.4f} Hz):")
        for freq, share, at_bin, near in found:
            if share >= args.least:
                print(f"  {freq:8.3f} Hz  {share:5.1%} of the largest  coherence {at_bin:.2f} (within 2 bins {near:.2f})")


if __name__ == "__main__":
    main()
