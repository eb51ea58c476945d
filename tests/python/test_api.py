"""The shear_twin package against the `twin` CLI: the same numbers and the same messages.

Needs the package installed into .venv (scripts/test.sh does: pip install ./python) and the
FMUs and the release `twin` built (scripts/build-fmus.sh).
"""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import shear_twin as st

REPO = Path(__file__).resolve().parents[2]
TWIN = REPO / "target" / "release" / "twin"
DATA = REPO / "data"


def cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([str(TWIN), *args], cwd=cwd, capture_output=True, text=True)


def test_compare_gives_the_cli_report_and_predictions(tmp_path):
    report, predictions = tmp_path / "r.json", tmp_path / "p.csv"
    done = cli("compare", "--data", "data/dataset3.csv", "--report", str(report), "--predictions", str(predictions))
    assert done.returncode == 0, done.stderr
    expected = json.loads(report.read_text())
    c = st.Twin.default().compare(st.Record.read("data/dataset3.csv"))
    assert c.nmse == expected["nmse"]  # the same computation: equal to the bit
    assert c.failing_windows == expected["failing_windows"]
    assert c.to_dict().keys() == expected.keys()
    frame = pd.DataFrame(c.predictions)
    written = pd.read_csv(predictions)
    assert list(frame.columns) == list(written.columns)
    # The CSV holds the predictions printed with {:e} (17 significant digits at most).
    np.testing.assert_allclose(frame.to_numpy(), written.to_numpy(), rtol=1e-15, atol=0)


def test_record_from_arrays_is_the_record_from_its_file():
    from_file = st.Record.read(str(DATA / "dataset1.csv"))
    columns = from_file.to_dict()
    from_arrays = st.Record(columns["time"], columns["force"], columns["acc1"], columns["acc2"], columns["acc3"])
    assert from_arrays.dt == from_file.dt and len(from_arrays) == len(from_file) == 1024
    twin = st.Twin.default()
    assert twin.compare(from_arrays).nmse == twin.compare(from_file).nmse


def test_bad_data_raises_the_cli_message(tmp_path):
    lines = (DATA / "dataset1.csv").read_text().splitlines()
    lines[6] = lines[6].replace(",", ",x", 1)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    done = cli("compare", "--data", str(bad))
    assert done.returncode == 1
    message = done.stderr.strip().removeprefix("twin: error: ")
    assert ":7:" in message  # the file and line
    with pytest.raises(st.DataError) as caught:
        st.Record.read(str(bad))
    assert str(caught.value) == message
    assert isinstance(caught.value, st.ShearTwinError) and isinstance(caught.value, Exception)


def test_arrays_are_checked_like_a_file():
    t = np.arange(100) / 51.2
    z = np.zeros(100)
    with pytest.raises(st.DataError, match="'acc2' has 99 samples, 'time' has 100"):
        st.Record(t, z, z, z[:-1], z)
    bad_time = t.copy()
    bad_time[50] = bad_time[49]
    with pytest.raises(st.DataError, match="does not increase"):
        st.Record(bad_time, z, z, z, z)
    acc = z.copy()
    acc[3] = np.nan
    with pytest.raises(st.DataError, match="only finite numbers"):
        st.Record(t, z, acc, z, z)


def test_a_missing_twin_raises_the_cli_message(tmp_path):
    missing = tmp_path / "nothing.ssp"
    done = cli("compare", "--twin", str(missing), "--data", "data/dataset1.csv")
    with pytest.raises(st.TwinError) as caught:
        st.Twin.open(str(missing))
    assert str(caught.value) == done.stderr.strip().removeprefix("twin: error: ")


def test_diagnose_and_add_physics_find_the_contact(tmp_path):
    """The demo's story from Python: calibrate on dataset1, diagnose dataset3 (the contact
    between floors 2 and 3), add it, and the error falls."""
    twin, calibration = st.Twin.default().calibrate(st.Record.read(str(DATA / "dataset1.csv")))
    assert calibration.noise_variance and twin.noise_variance is not None
    record = st.Record.read(str(DATA / "dataset3.csv"))
    diagnosis = twin.diagnose(record)
    assert diagnosis.action == "add_physics"
    assert diagnosis.effect["label"].startswith("contact@2-3")
    new_twin, added = twin.add_physics(record, diagnosis=diagnosis)
    # The demo's measured fall is 68.6 % → 0.32 %; a 10× fall is the bar.
    assert max(added.nmse_after) < max(added.nmse_before) / 10
    assert new_twin.compare(record).nmse == pytest.approx(added.nmse_after, rel=1e-9)
    path = tmp_path / "with-contact.ssp"
    new_twin.save(str(path))
    assert st.Twin.open(str(path)).parameters["physics"]["contact23_enabled"] is True


def test_long_work_releases_the_gil():
    """While a calibration runs, another Python thread keeps running."""
    record = st.Record.read(str(DATA / "dataset1.csv"))
    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.01)

    ticker = threading.Thread(target=tick)
    ticker.start()
    started = time.perf_counter()
    st.Twin.default().calibrate(record, starts=2, threads=1)
    elapsed = time.perf_counter() - started
    done.set()
    ticker.join()
    during = [t for t in ticks if started <= t <= started + elapsed]
    # A held GIL would allow ~1 tick; sleeping 10 ms, a free thread ticks about elapsed/0.01
    # times — half of that is the bar (a loaded machine).
    assert len(during) > 0.5 * elapsed / 0.01, (len(during), elapsed)


def test_synth_and_control_and_watch(tmp_path):
    record, truth = st.synth({"seed": 3, "duration": 8.0}, out=str(tmp_path / "s.csv"))
    assert truth["effects"] == [] and len(record) == 8 * 512 // 10 + 1
    twin, _ = st.Twin.default().calibrate(record, starts=2)
    control = twin.control(record, [1e3, 5e3])
    assert [d["q"] for d in control.designs] == [1e3, 5e3]
    assert all(d["unstable"] is None for d in control.designs)
    summary = twin.watch(str(tmp_path / "s.csv"), str(tmp_path / "alerts.jsonl"))
    assert summary.samples == len(record)
    assert (tmp_path / "alerts.jsonl").read_text().strip().splitlines()[-1].find('"end"') > 0


def test_errors_of_options_are_exceptions():
    record = st.Record.read(str(DATA / "dataset1.csv"))
    with pytest.raises(st.ControlError, match="the control weight must be"):
        st.Twin.default().control(record, [1e3], r=-1)
    with pytest.raises(st.DiagnoseError):
        st.Twin.default().diagnose(record, effects=["nonsense@9"])
    with pytest.raises(st.TwinError, match="leaves nothing"):
        st.Twin.default().compare(record, transient=100.0)
