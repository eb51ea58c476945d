"""Universal files (dataset 58) written by pyuff, read by the twin (orchestrator/src/record/uff.rs).

pyuff is a third-party reader and writer of universal files. Each case writes the same numbers
twice — as a universal file by pyuff (ASCII 58 and binary 58b) and as the twin's CSV — and the
twin's answers on the two files must agree:

- FRFs (function type 4): `twin compare --frf` on the .uff and on the FRF CSV report the same
  measured magnitudes (dB) per channel, one channel's ordinate in g (converted to SI on reading);
- time responses (function type 1): `twin compare --data` on the .uff and on the record CSV
  report the same NMSE per channel.

The time grid is 50 Hz: dataset 58 writes an even abscissa's increment with 6 significant digits
(E13.5), which 1/51.2 s would not survive exactly.

Needs `twin` built (target/release/twin, or the path in TWIN_BINARY) and the FMUs
(scripts/build-fmus.sh).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import pyuff
from conftest import run_twin_ok

ROOT = Path(__file__).resolve().parents[2]
G = 9.80665


def write_uff(path: Path, datasets: list[dict]) -> None:
    if path.exists():
        path.unlink()
    pyuff.UFF(str(path)).write_sets(datasets, mode="add")


def frf_dataset(binary: int, node: int, frequency, h, units: str) -> dict:
    return pyuff.prepare_58(
        binary=binary, func_type=4, rsp_node=node, rsp_dir=1, ref_node=1, ref_dir=1,
        data=h, x=frequency, id1=f"FRF acc{node}/force1", rsp_ent_name="rig", ref_ent_name="rig",
        abscissa_spacing=1, abscissa_spec_data_type=18, ordinate_spec_data_type=12,
        orddenom_spec_data_type=13, ordinate_axis_units_lab=units, orddenom_axis_units_lab="N",
    )


def time_dataset(binary: int, node: int, kind: int, time, values, units: str) -> dict:
    return pyuff.prepare_58(
        binary=binary, func_type=1, rsp_node=node, rsp_dir=1, ref_node=1, ref_dir=1,
        data=values, x=time, id1=f"node {node}", rsp_ent_name="rig", ref_ent_name="rig",
        abscissa_spacing=1, abscissa_spec_data_type=17, ordinate_spec_data_type=kind,
        orddenom_spec_data_type=0, ordinate_axis_units_lab=units,
    )


@pytest.fixture(scope="module")
def rig(twin_binary, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("uff")
    run_twin_ok(twin_binary, "init", "--out", str(folder / "rig.ssp"))
    return folder / "rig.ssp"


@pytest.mark.parametrize("binary", [0, 1], ids=["ascii", "binary"])
def test_frfs_written_by_pyuff_read_as_the_csv(twin_binary, rig, tmp_path, binary):
    rng = np.random.default_rng(3)
    frequency = np.arange(1, 101) * 0.5
    h = [rng.normal(size=frequency.size) + 1j * rng.normal(size=frequency.size) for _ in range(3)]
    # acc2's FRF is written in g/N: the twin converts it to (m/s²)/N.
    units = ["m/s^2", "g", "m/s^2"]
    write_uff(tmp_path / "frf.uff",
              [frf_dataset(binary, i + 1, frequency, h[i], units[i]) for i in range(3)])
    with open(tmp_path / "frf.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frequency"] + [f"acc{i + 1}_{p}" for i in range(3) for p in ("re", "im")])
        for k, fk in enumerate(frequency):
            row = [repr(float(fk))]
            for i in range(3):
                scale = G if units[i] == "g" else 1.0
                row += [repr(float(h[i][k].real * scale)), repr(float(h[i][k].imag * scale))]
            w.writerow(row)
    reports = {}
    for name in ("frf.uff", "frf.csv"):
        report = tmp_path / f"{name}.json"
        run_twin_ok(twin_binary, "compare", "--twin", str(rig), "--frf", str(tmp_path / name),
             "--report", str(report))
        reports[name] = json.loads(report.read_text())
    uff, ref = reports["frf.uff"], reports["frf.csv"]
    assert uff["frequency"] == pytest.approx(ref["frequency"], rel=1e-12)
    assert [c["channel"] for c in uff["channels"]] == ["acc1", "acc2", "acc3"]
    for a, b in zip(uff["channels"], ref["channels"]):
        # ASCII 58 keeps 12 significant digits (E20.12 as pyuff writes it); 58b the doubles.
        assert np.allclose(a["measured_db"], b["measured_db"], rtol=0, atol=1e-8), a["channel"]


@pytest.mark.parametrize("binary", [0, 1], ids=["ascii", "binary"])
def test_time_responses_written_by_pyuff_read_as_the_csv(twin_binary, rig, tmp_path, binary):
    with open(ROOT / "data" / "dataset1.csv") as f:
        rows = list(csv.DictReader(f))
    n = len(rows)
    time = np.arange(n) * 0.02
    force = np.array([float(r["force"]) for r in rows])
    acc = [np.array([float(r[f"acc{i}"]) for r in rows]) for i in (1, 2, 3)]
    datasets = [time_dataset(binary, 1, 13, time, force, "N")]
    # acc3 written in g.
    datasets += [time_dataset(binary, i + 1, 12, time, acc[i] / (G if i == 2 else 1.0),
                              "g" if i == 2 else "m/s^2") for i in range(3)]
    write_uff(tmp_path / "record.uff", datasets)
    with open(tmp_path / "record.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "force", "acc1", "acc2", "acc3"])
        for k in range(n):
            # In SI as the twin converts acc3's g back: (a / G) · G, to the same double.
            w.writerow([f"{time[k]:.2f}", repr(float(force[k]))]
                       + [repr(float(acc[i][k] / G * G if i == 2 else acc[i][k])) for i in range(3)])
    reports = {}
    for name in ("record.uff", "record.csv"):
        report = tmp_path / f"{name}.json"
        run_twin_ok(twin_binary, "compare", "--twin", str(rig), "--data", str(tmp_path / name),
             "--report", str(report))
        reports[name] = json.loads(report.read_text())
    uff, ref = reports["record.uff"], reports["record.csv"]
    # ASCII 58 keeps 12 significant digits of each sample; the NMSE then agrees to 1e-6.
    assert np.allclose(uff["nmse"], ref["nmse"], rtol=1e-6), (uff["nmse"], ref["nmse"])
