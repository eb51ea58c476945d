"""A measurement CSV as the Python peers of the benchmarks read it, the way `twin` reads it
(orchestrator/src/record/read.rs): columns time, force, acc1..3; the step from the ends of the time
column, snapped to a round rate in mHz when that moves the end of the grid by at most 1 µs
(51.2 Hz -> 1/51.2 s); the first sample at least `transient` seconds after the start."""
from __future__ import annotations

from pathlib import Path

import numpy as np


class Record:
    def __init__(self, path: Path, transient: float):
        table = np.genfromtxt(path, delimiter=",", names=True)
        names = table.dtype.names or ()
        for column in ("time", "force", "acc1", "acc2", "acc3"):
            if column not in names:
                raise SystemExit(f"{path}: no '{column}' column")
        self.time = np.asarray(table["time"], dtype=float)
        self.force = np.asarray(table["force"], dtype=float)
        self.acc = np.stack([table["acc1"], table["acc2"], table["acc3"]]).astype(float)
        self.n = len(self.force)
        dt = (self.time[-1] - self.time[0]) / (self.n - 1)
        snapped = round(1000.0 / dt) / 1000.0
        self.dt = 1.0 / snapped if abs(1.0 / snapped - dt) * (self.n - 1) <= 1e-6 else dt
        hits = np.nonzero(self.time - self.time[0] >= transient)[0]
        self.first = int(hits[0]) if len(hits) else self.n
