"""The shear_twin package against the `twin` CLI: the same numbers and the same messages.

Needs the package installed into .venv (scripts/test.sh does: pip install ./python) and the
FMUs and the release `twin` built (scripts/build-fmus.sh).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import shear_twin as st
from conftest import run_twin, twin_binary_path

REPO = Path(__file__).resolve().parents[2]
TWIN = twin_binary_path()
DATA = REPO / "data"


def test_compare_gives_the_cli_report_and_predictions(tmp_path):
    report, predictions = tmp_path / "r.json", tmp_path / "p.csv"
    done = run_twin(TWIN, "compare", "--data", "data/dataset3.csv", "--report", str(report), "--predictions", str(predictions), cwd=REPO)
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


def test_records_with_units_column_maps_and_other_channels(tmp_path):
    d = st.Record.read(str(DATA / "dataset1.csv")).to_dict()
    # acc1 in g, acc2 under another name: converted to SI and renamed, as `twin --columns` does.
    named = {"time": d["time"], "force": d["force"], "acc1 (g)": d["acc1"] / 9.80665,
             "a2": d["acc2"], "acc3": d["acc3"]}
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({"a2": "acc2"}))
    pd.DataFrame(named).to_csv(tmp_path / "renamed.csv", index=False)
    records = [
        st.Record.from_arrays(named, columns={"a2": "acc2"}),
        st.record_from_frame(pd.DataFrame(named), columns=mapping),
        st.Record.read(str(tmp_path / "renamed.csv"), columns=str(mapping)),
    ]
    for record in records:
        assert record.channels == ["force", "acc1", "acc2", "acc3"]
        got = record.to_dict()
        assert list(got) == ["time", "force", "acc1", "acc2", "acc3"]
        np.testing.assert_array_equal(got["acc2"], d["acc2"])
        # g back to m/s²: measured at most 1.8e-16 relative on dataset1 (a rounding or two).
        np.testing.assert_allclose(got["acc1"], d["acc1"], rtol=1e-15, atol=0)
    # Another set of channels is a record: compare and train serve it channel by channel (the
    # corrector one GP per measured channel), and a floor the twin lacks is refused by name.
    velocities = st.Record.from_arrays({"time": d["time"], "force": d["force"], "vel2": d["acc2"]})
    assert velocities.channels == ["force", "vel2"]
    compared = st.Twin.default().compare(velocities)
    assert compared.channels == ["vel2"] and len(compared.nmse) == 1
    _, trained = st.Twin.default().train(velocities, stride=16)
    assert trained.channels == ["vel2"] and len(trained.nmse) == 1
    high = st.Record.from_arrays({"time": d["time"], "force": d["force"], "acc4": d["acc2"]})
    with pytest.raises(st.DataError, match="column 'acc4' is for floor 4; the structure has floors 1 to 3"):
        st.Twin.default().compare(high)
    with pytest.raises(st.DataError, match="missing column 'force' or 'ground_acc'"):
        st.Record.from_arrays({"time": d["time"], "acc1": d["acc1"]})


def test_bad_data_raises_the_cli_message(tmp_path):
    lines = (DATA / "dataset1.csv").read_text().splitlines()
    lines[6] = lines[6].replace(",", ",x", 1)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    done = run_twin(TWIN, "compare", "--data", str(bad), cwd=REPO)
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


def test_a_record_from_arrays_has_an_accelerometer_per_floor_given():
    t = np.arange(100) / 51.2
    z = np.zeros(100)
    five = st.Record(t, z, z, z, z, z, z)
    assert five.channels == ["force", "acc1", "acc2", "acc3", "acc4", "acc5"]
    with pytest.raises(st.DataError, match="no response column"):
        st.Record(t, z)


def test_a_missing_twin_raises_the_cli_message(tmp_path):
    missing = tmp_path / "nothing.ssp"
    done = run_twin(TWIN, "compare", "--twin", str(missing), "--data", "data/dataset1.csv", cwd=REPO)
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
    # Calibrated from a file, the twin remembers its record, as `twin calibrate`'s does: the
    # effects are refitted over dataset3 and dataset1.
    assert sorted(Path(r["record"]).name for r in added.records) == ["dataset1.csv", "dataset3.csv"]
    # The demo's measured fall is 68.6 % → 0.32 %; a 10× fall is the bar.
    assert max(added.nmse_after) < max(added.nmse_before) / 10
    assert new_twin.compare(record).nmse == pytest.approx(added.nmse_after, rel=1e-9)
    path = tmp_path / "with-contact.ssp"
    new_twin.save(str(path))
    assert st.Twin.open(str(path)).parameters["physics"]["contact23_enabled"] is True


def test_a_building_measured_by_velocity_sensors_is_diagnosed_in_their_quantity():
    """Velocity sensors in mm/s on every floor (``twin synth``'s frame): the twin calibrated on
    them diagnoses a hidden cubic stiffness in storey 1, each channel in its own quantity, as
    for accelerometers (tests/diagnose_sensors.rs holds the other effects, displacements and a
    mix, from Rust)."""
    channels = ["vel1 (mm/s)", "vel2 (mm/s)", "vel3 (mm/s)"]
    # 9e-5 m/s: 3 % of the change-free record's velocity RMS (2.9–3.6e-3 m/s), on every record.
    base, _ = st.synth({"seed": 1, "channels": channels, "noise": {"sd": [9e-5]}})
    twin, _ = st.Twin.default().calibrate(base)
    record, _ = st.synth({
        "seed": 2, "channels": channels, "noise": {"sd": [9e-5]},
        "force": {"windows": [{"start": 12, "end": 17, "gain": 3, "ramp": 0.5}]},
        "effects": [{"kind": "cubic", "location": [1], "stiffness": 2e9}],
    })
    d = twin.diagnose(record)
    assert d.channels == ["vel1", "vel2", "vel3"]
    assert d.action == "add_physics", d.reason
    assert d.effect["label"] == "cubic@1", d.reason
    # Measured: 1.99e9 for 2e9 and every channel's NMSE at its noise level; bars 5 % and 4×.
    assert abs(d.effect["parameters"]["stiffness"] - 2e9) < 0.05 * 2e9
    assert max(d.nmse_after) < max(d.nmse_before) / 4
    assert [s["quantity"] for s in d.sensing] == ["velocity"] * 3
    assert all(s["localisation"] == "differentiated once" and s["visibility"] > 3 for s in d.sensing)


def test_long_work_releases_the_gil():
    """While a diagnosis runs, another Python thread keeps running."""
    # Long enough (a whole diagnosis on one thread: one to three seconds) that a free thread's
    # ticks cannot be confused with the one a held GIL lets through at the call's edge; a
    # calibration of dataset1 now takes 20-30 ms, where one tick is all a loaded machine gives.
    twin, _ = st.Twin.default().calibrate(st.Record.read(str(DATA / "dataset1.csv")))
    record = st.Record.read(str(DATA / "dataset3.csv"))
    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.01)

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    try:
        started = time.perf_counter()
        twin.diagnose(record, threads=1)
        elapsed = time.perf_counter() - started
    finally:
        done.set()
        ticker.join()
    during = [t for t in ticks if started <= t <= started + elapsed]
    # A held GIL would allow ~1 tick; sleeping 10 ms, a free thread ticks about elapsed/0.01
    # times — a quarter of that, and at least ten, is the bar (a loaded machine).
    assert elapsed > 0.2, elapsed
    assert len(during) > max(10, 0.25 * elapsed / 0.01), (len(during), elapsed)


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


# ---------------------------------------------------------------------------------------------
# Every command as a call: train, learn, run, control's retune / schedule / SSP, watch from
# standard input and MQTT with a callback, fleet; errors with the CLI's messages.

def cli_error(*args: str) -> str:
    done = run_twin(TWIN, *args, cwd=REPO)
    assert done.returncode != 0, done.stdout
    return done.stderr.strip().removeprefix("twin: error: ")


@pytest.fixture(scope="module")
def calibrated():
    """The default twin calibrated on dataset1 with 2 starts (a twin with noise variances)."""
    twin, _ = st.Twin.default().calibrate(st.Record.read(str(DATA / "dataset1.csv")), starts=2)
    return twin


def test_train_is_the_cli_training(tmp_path):
    out, report = tmp_path / "t.ssp", tmp_path / "t.json"
    done = run_twin(TWIN, "train", "--data", "data/dataset1.csv", "--stride", "8", "--out", str(out), "--report", str(report), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads(report.read_text())
    twin, trained = st.Twin.default().train(st.Record.read("data/dataset1.csv"), stride=8)
    assert trained.nmse == expected["nmse"]  # the same fit: equal to the bit
    assert trained.training["points"] == expected["training"]["points"]
    assert set(trained.keys()) == set(expected.keys()) - {"out"}
    # The twin has its corrector: the comparison carries its latent variances.
    c = twin.compare(st.Record.read("data/dataset1.csv"))
    assert c.nmse == pytest.approx(trained.nmse, rel=1e-12)
    assert "latent_var1" in c.to_frame().columns


def test_train_selects_lags_and_refuses_a_zero_stride():
    record = st.Record.read(str(DATA / "dataset1.csv"))
    _, trained = st.Twin.default().train(record, stride=16, select_lags=[1, 3], selection_stride=16)
    assert sorted(s["lags"] for s in trained.lag_selection) == [1, 3]
    assert trained.training["lags"] == trained.lag_selection[0]["lags"]
    message = cli_error("train", "--data", "data/dataset1.csv", "--out", "/tmp/never.ssp", "--stride", "0")
    with pytest.raises(st.TrainError) as caught:
        st.Twin.default().train(record, stride=0)
    assert str(caught.value) == message == "--stride must be at least 1"
    with pytest.raises(st.TrainError, match="--target nonsense: expected one of discrepancy, measured"):
        st.Twin.default().train(record, target="nonsense")


def test_learn_is_the_cli_learning(tmp_path):
    report = tmp_path / "l.json"
    args = ["--mode", "uniform", "--initial", "64", "--nmse-every", "50"]
    done = run_twin(TWIN, "learn", "--data", "data/dataset1.csv", "data/dataset2.csv", *args, "--report", str(report), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads(report.read_text())
    records = [st.Record.read("data/dataset1.csv"), st.Record.read("data/dataset2.csv")]
    learned, twin = st.Twin.default().learn(records, mode="uniform", initial=64, nmse_every=50,
                                            out_dir=tmp_path / "plots")
    assert (tmp_path / "plots" / "learn-uniform.svg").stat().st_size > 1000
    assert set(learned.keys()) == set(expected.keys())
    [mode], [cli_mode] = learned.modes, expected["modes"]
    assert mode["mode"] == cli_mode["mode"] == "uniform"
    for ours, theirs in zip(mode["records"], cli_mode["records"]):
        assert ours["queries"] == theirs["queries"] and ours["final_nmse"] == theirs["final_nmse"]
    assert mode["final_gps_nmse"] == cli_mode["final_gps_nmse"]
    # One mode: the twin with the corrector as learned.
    assert twin is not None and "corrector" in twin.parameters
    message = cli_error("learn", "--data", "data/dataset1.csv", "--forgetting", "2")
    with pytest.raises(st.TrainError) as caught:
        st.Twin.default().learn(records, forgetting=2.0)
    assert str(caught.value) == message


def test_run_is_the_cli_run(tmp_path):
    fmu = REPO / "target" / "fmu" / "fmu_shear.fmu"
    output = tmp_path / "run.csv"
    done = run_twin(TWIN, "run", str(fmu), "--stop", "0.5", "--set", "k2=3000", "--output", str(output), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = pd.read_csv(output)
    ran = st.run(fmu, stop=0.5, sets={"k2": 3000})
    frame = ran.to_frame()
    assert list(frame.columns) == list(expected.columns)
    np.testing.assert_allclose(frame.to_numpy(), expected.to_numpy(), rtol=1e-15, atol=0)
    assert ran.stop == 0.5 and ran.terminated is None
    message = cli_error("run", str(fmu), "--set", "nonsense=1", "--output", str(tmp_path / "x.csv"))
    with pytest.raises(st.RunError) as caught:
        st.run(fmu, sets={"nonsense": 1})
    assert str(caught.value) == message
    with pytest.raises(st.RunError, match="--algorithm sideways: expected one of gauss-seidel, jacobi"):
        st.run(fmu, algorithm="sideways")


def test_control_retunes_schedules_and_exports_an_ssp(calibrated, tmp_path):
    record = st.Record.read(str(DATA / "dataset3.csv"))
    calibrated.save(str(tmp_path / "c.ssp"))
    report, ssp = tmp_path / "control.json", tmp_path / "controlled.ssp"
    flags = ["--q", "10", "--gap", "2-3:5e-4", "--retune", "--schedule"]
    done = run_twin(TWIN, "control", "--twin", str(tmp_path / "c.ssp"), "--data", str(DATA / "dataset3.csv"), *flags,
               "--report", str(report), "--ssp", str(tmp_path / "cli.ssp"), "--plot", str(tmp_path / "cli.svg"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads(report.read_text())
    control = calibrated.control(record, [10], gaps=["2-3:5e-4"], retune=True, schedule=True, ssp=ssp,
                                 plot=tmp_path / "py.svg")
    assert (tmp_path / "py.svg").read_bytes() == (tmp_path / "cli.svg").read_bytes()
    assert control.retune == expected["retune"] and control.retune["chosen_q"] > 10
    assert control.schedule["contacts"] == expected["schedule"]["contacts"]
    assert control.passive["contacts"] == expected["passive"]["contacts"]
    # The time histories: the passive structure's and the scheduled one's, at the record's rate.
    passive = control.frame("passive")
    assert list(passive.columns) == ["time", "acc1", "acc2", "acc3", "control"]
    assert len(passive) == len(record) and not passive["control"].any()
    assert control.responses["scheduled"]["control"].std() > 0
    # The SSP runs in any SSP tool; here through shear_twin.run.
    step = 1.0 / control.control_rate_hz  # the controller's, which the FMU insists on
    ran = st.run(ssp, stop=800 * step, step=step)
    assert "lqr.control_force" in ran.columns and len(ran["time"]) == 801
    # The same system as the CLI's --ssp: the same recording.
    from_cli = st.run(tmp_path / "cli.ssp", stop=800 * step, step=step).to_frame()
    pd.testing.assert_frame_equal(ran.to_frame(), from_cli)
    # And a compare closes the loop with the report's controller.
    looped = calibrated.compare(record, controller=control)
    assert looped.nmse != calibrated.compare(record).nmse


def test_control_options_raise_the_cli_messages(tmp_path):
    record = st.Record.read(str(DATA / "dataset1.csv"))
    twin = st.Twin.default()
    for flags, kwargs in [
        (["--gap", "2-4:5e-4"], {"gaps": ["2-4:5e-4"]}),
        (["--gap", "2-3:-1"], {"gaps": ["2-3:-1"]}),
        (["--schedule", "--variance-threshold", "maybe"], {"schedule": True, "variance_threshold": "maybe"}),
        (["--max-force", "0"], {"max_force": 0.0}),
        (["--sensor-noise=-1"], {"sensor_noise": -1.0}),
    ]:
        message = cli_error("control", "--data", "data/dataset1.csv", "--q", "1e3", *flags,
                            "--report", str(tmp_path / "never.json"))
        with pytest.raises(st.ControlError) as caught:
            twin.control(record, [1e3], **kwargs)
        assert str(caught.value) == message, flags


def test_watch_calls_back_per_alert_and_raises_what_the_callback_raised(calibrated, tmp_path):
    record, _ = st.synth({"seed": 4, "duration": 8.0, "effects": [{"kind": "contact", "location": [2, 3], "gap": 2e-4, "stiffness": 9000}]},
                         out=str(tmp_path / "s.csv"))
    seen = []
    summary = calibrated.watch(tmp_path / "s.csv", tmp_path / "alerts.jsonl", on_alert=seen.append,
                               diagnosis=False)
    written = [json.loads(line) for line in (tmp_path / "alerts.jsonl").read_text().splitlines()]
    assert seen == written and seen[-1]["kind"] == "end"
    assert summary.samples == len(record)

    class Stop(Exception):
        pass

    def stop(alert):
        raise Stop(alert["kind"])

    with pytest.raises(Stop):
        calibrated.watch(tmp_path / "s.csv", tmp_path / "alerts2.jsonl", on_alert=stop, diagnosis=False)
    message = cli_error("watch", "--source", "-", "--follow", "--alerts", str(tmp_path / "a.jsonl"))
    with pytest.raises(st.WatchError) as caught:
        calibrated.watch("-", tmp_path / "a.jsonl", follow=True)
    assert str(caught.value) == message


def test_watch_reads_standard_input(calibrated, tmp_path):
    calibrated.save(str(tmp_path / "c.ssp"))
    script = ("import sys, shear_twin as st; "
              f"s = st.Twin.open({str(tmp_path / 'c.ssp')!r}).watch('-', {str(tmp_path / 'a.jsonl')!r}, diagnosis=False); "
              "print(s.samples)")
    done = subprocess.run([sys.executable, "-c", script], input=(DATA / "dataset1.csv").read_text(),
                          capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) == 1024


def _mqtt_publish(port: int, topic: str, payloads: list[str]) -> None:
    """Publish `payloads` (QoS 0) as an MQTT 3.1.1 client would: CONNECT, PUBLISHes,
    DISCONNECT. Written out here (a few bytes each) rather than adding an MQTT client package
    to the test environment."""
    import socket

    def packet(kind: int, body: bytes) -> bytes:
        n, length = len(body), b""
        while True:
            byte, n = n % 128, n // 128
            length += bytes([byte | (128 if n else 0)])
            if not n:
                return bytes([kind]) + length + body

    def text(s: str) -> bytes:
        b = s.encode()
        return len(b).to_bytes(2, "big") + b

    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(packet(0x10, text("MQTT") + bytes([4, 2]) + (60).to_bytes(2, "big") + text("pytest-pub")))
        assert s.recv(4)[:1] == b"\x20"  # CONNACK
        for p in payloads:
            s.sendall(packet(0x30, text(topic) + p.encode()))
        s.sendall(packet(0xE0, b""))


def test_watch_from_mqtt_calls_back_per_alert(calibrated, tmp_path):
    mosquitto = next((p for p in ("/usr/sbin/mosquitto", "/usr/bin/mosquitto") if Path(p).exists()), None)
    if mosquitto is None:
        pytest.fail("mosquitto is not installed: run scripts/prerequisites.sh as root, or apt-get install mosquitto")
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    config = tmp_path / "mosquitto.conf"
    config.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\nuser root\n")
    broker = subprocess.Popen([mosquitto, "-c", str(config)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "mosquitto did not listen"
                time.sleep(0.02)
        connected = threading.Event()
        seen = []

        def on_alert(alert):
            seen.append(alert)
            if alert["kind"] == "connection" and alert["state"] == "connected":
                connected.set()

        result = {}
        watcher = threading.Thread(target=lambda: result.update(summary=calibrated.watch(
            f"mqtt://127.0.0.1:{port}/shear/data", tmp_path / "alerts.jsonl", on_alert=on_alert,
            idle=3.0, diagnosis=False)))
        watcher.start()
        assert connected.wait(20), seen
        lines = (DATA / "dataset1.csv").read_text().splitlines()[1:]
        # Messages of 64 lines each, without a header (the usual columns).
        _mqtt_publish(port, "shear/data", ["\n".join(lines[i:i + 64]) for i in range(0, len(lines), 64)])
        watcher.join(60)
        assert not watcher.is_alive()
    finally:
        broker.terminate()
        broker.wait(10)
    summary = result["summary"]
    assert summary.samples == len(lines) == 1024
    written = [json.loads(line) for line in (tmp_path / "alerts.jsonl").read_text().splitlines()]
    assert seen == written and seen[-1]["kind"] == "end"


def test_fleet_as_a_call(tmp_path):
    from shear_twin import fleet

    manifest = fleet.make_synthetic_fleet(tmp_path / "f", 2, duration=6.0, seed=5)
    m = json.loads(manifest.read_text())
    m["tasks"] = ["compare"]
    manifest.write_text(json.dumps(m))
    frame, summary = fleet.fleet(manifest, workers=1, out=tmp_path / "report")
    assert list(frame["structure"]) == ["s000", "s001"] and summary["structures"] == 2
    assert frame["error"].isna().all()
    assert list(pd.read_csv(tmp_path / "report" / "fleet.csv")["structure"]) == ["s000", "s001"]


def test_synth_with_a_controller_in_the_loop_is_the_cli_record(calibrated, tmp_path):
    record = st.Record.read(str(DATA / "dataset1.csv"))
    control = calibrated.control(record, [1e3])
    (tmp_path / "control.json").write_text(control.to_json())
    (tmp_path / "scenario.json").write_text(json.dumps({"seed": 5, "duration": 4.0}))
    done = run_twin(TWIN, "synth", "--scenario", str(tmp_path / "scenario.json"), "--controller", str(tmp_path / "control.json"),
               "--out", str(tmp_path / "cli.csv"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    ours, _ = st.synth({"seed": 5, "duration": 4.0}, controller=control)
    theirs = st.Record.read(str(tmp_path / "cli.csv")).to_dict()
    assert set(ours.to_dict()) == set(theirs) and "control" in theirs
    for name, column in ours.to_dict().items():
        # The CLI's file holds 9 significant digits (csv::round9).
        np.testing.assert_allclose(column, theirs[name], rtol=1e-8, atol=1e-12, err_msg=name)
    assert np.abs(theirs["control"]).max() > 0


def test_plots_are_the_cli_plots(tmp_path):
    """`plot=` draws what `--plot` draws, byte for byte (the same data, title and drawing)."""
    done = run_twin(TWIN, "compare", "--data", "data/dataset3.csv", "--plot", str(tmp_path / "cli.svg"), "--frf", cwd=REPO)
    assert done.returncode == 0, done.stderr
    st.Twin.default().compare(st.Record.read("data/dataset3.csv"), plot=tmp_path / "py.svg", frf=True)
    assert (tmp_path / "py.svg").read_bytes() == (tmp_path / "cli.svg").read_bytes()
    fmu = REPO / "target" / "fmu" / "fmu_shear.fmu"
    done = run_twin(TWIN, "run", str(fmu), "--stop", "0.5", "--output", str(tmp_path / "r.csv"), "--plot", str(tmp_path / "run-cli.svg"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    st.run(fmu, stop=0.5, plot=tmp_path / "run-py.svg")
    assert (tmp_path / "run-py.svg").read_bytes() == (tmp_path / "run-cli.svg").read_bytes()
    message = cli_error("compare", "--data", "data/dataset1.csv", "--plot", str(tmp_path / "x.png"))
    with pytest.raises(st.TwinError) as caught:
        st.Twin.default().compare(st.Record.read("data/dataset1.csv"), plot=tmp_path / "x.png")
    assert str(caught.value) == message


def test_export_fmus_writes_what_the_cli_writes(tmp_path):
    done = run_twin(TWIN, "export-fmus", "--out", str(tmp_path / "cli"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    written = st.export_fmus(tmp_path / "py")
    assert sorted(Path(p).name for p in written) == sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert len(written) == 4
    for p in written:
        assert Path(p).read_bytes() == (tmp_path / "cli" / Path(p).name).read_bytes()


def test_hybrid_threshold_and_run_are_the_cli_reports(tmp_path):
    short = ["--duration", "12", "--a-err", "0", "--a-err", "0.05"]
    done = run_twin(TWIN, "hybrid", "threshold", *short, "--report", str(tmp_path / "t.json"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads((tmp_path / "t.json").read_text())
    twin = st.Twin.default()
    threshold = twin.hybrid_threshold(duration=12.0, a_err=[0.0, 0.05])
    assert threshold.thresholds == expected["thresholds"]  # the same computation: equal to the bit
    assert {k: v for k, v in threshold.to_dict().items() if k != "seconds"} == \
        {k: v for k, v in expected.items() if k != "seconds"}
    done = run_twin(TWIN, "hybrid", "run", *short, "--report", str(tmp_path / "r.json"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    run = twin.hybrid_run(duration=12.0, a_err=[0.0, 0.05], plot=tmp_path / "run.svg")
    assert run.to_dict() == json.loads((tmp_path / "r.json").read_text())
    assert (tmp_path / "run.svg").stat().st_size > 1000
    message = cli_error("hybrid", "run", "--a-err=-2", "--report", str(tmp_path / "never.json"))
    with pytest.raises(st.HybridError) as caught:
        twin.hybrid_run(a_err=[-2.0])
    assert str(caught.value) == message
    with pytest.raises(st.HybridError, match="--coupling sideways: expected one of auto, monolithic, stepped"):
        twin.hybrid_threshold(coupling="sideways")
    # The split: the paper's by default, the other by name, as the CLI's --split.
    assert threshold.split == "specimen-floors-2-3"
    done = run_twin(TWIN, "hybrid", "threshold", *short, "--split", "specimen-floor-3", "--report", str(tmp_path / "t3.json"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    other = twin.hybrid_threshold(duration=12.0, a_err=[0.0, 0.05], split="specimen-floor-3")
    assert other.thresholds == json.loads((tmp_path / "t3.json").read_text())["thresholds"]
    assert other.split == "specimen-floor-3"
    with pytest.raises(st.HybridError, match="unknown split 'floor-9'"):
        twin.hybrid_threshold(split="floor-9")


def test_a_measured_frf_is_read_and_calibrated_on_as_the_cli_does(tmp_path):
    """`read_frf` reads the laboratory frame's FRF as `twin calibrate --frf` does (its dB
    columns, every line), and `calibrate(frf=...)` is that calibration: the same estimates."""
    frf = DATA / "frf" / "swansea-3storey-frf.csv"
    read = st.read_frf(frf)
    table = pd.read_csv(frf)
    assert sorted(read["channels"]) == ["acc1", "acc2", "acc3"]
    assert np.array_equal(read["frequency"], table["frequency"].to_numpy())
    assert np.allclose(read["channels"]["acc2"], table["acc2_db"].to_numpy(), rtol=0, atol=1e-12)
    drawings = tmp_path / "drawings.ssp"
    done = run_twin(TWIN, "init", "--nominal", str(DATA / "frf" / "nominal.json"), "--out", str(drawings), cwd=REPO)
    assert done.returncode == 0, done.stderr
    done = run_twin(TWIN, "calibrate", "--twin", str(drawings), "--frf", str(frf), "--band", "3:40", "--gain-offset",
               "--out", str(tmp_path / "cli.ssp"), "--report", str(tmp_path / "cli.json"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads((tmp_path / "cli.json").read_text())
    twin, report = st.Twin.open(drawings).calibrate(frf=frf, band=(3.0, 40.0), gain_offset=True)
    assert [p["name"] for p in report.parameters] == [p["name"] for p in expected["parameters"]]
    for ours, cli_p in zip(report.parameters, expected["parameters"]):
        assert ours["value"] == pytest.approx(cli_p["value"], rel=1e-9), ours["name"]
    assert twin.parameters["physics"]["k1"] == pytest.approx(report.parameters[
        [p["name"] for p in report.parameters].index("k1")]["value"], rel=1e-12)
    with pytest.raises(TypeError, match="band and gain_offset go with frf="):
        st.Twin.open(drawings).calibrate(st.Record.read(str(DATA / "dataset1.csv")), band=(3.0, 40.0))
    with pytest.raises(st.DataError, match="nowhere.csv"):
        st.read_frf(tmp_path / "nowhere.csv")


def test_add_physics_takes_the_hybrid_tests_contact_as_the_cli_does(calibrated, tmp_path):
    """`add_physics(hybrid=...)` is `twin add-physics --hybrid`: the hybrid test's contact law
    held, the structure refitted over the twin's records; the same report."""
    saved = tmp_path / "cal.ssp"
    calibrated.save(str(saved))
    hybrid = tmp_path / "h.json"
    done = run_twin(TWIN, "hybrid", "run", "--twin", str(saved), "--peak", "5", "--a-err", "0", "--report", str(hybrid), cwd=REPO)
    assert done.returncode == 0, done.stderr
    done = run_twin(TWIN, "add-physics", "--twin", str(saved), "--hybrid", str(hybrid), "--out", str(tmp_path / "a.ssp"),
               "--report", str(tmp_path / "a.json"), cwd=REPO)
    assert done.returncode == 0, done.stderr
    expected = json.loads((tmp_path / "a.json").read_text())
    twin, report = st.Twin.open(saved).add_physics(hybrid=hybrid)
    drop = {"seconds", "out"}
    assert {k: v for k, v in report.to_dict().items() if k not in drop} == \
        {k: v for k, v in expected.items() if k not in drop}
    assert twin.parameters["physics"]["contact23_enabled"] is True
    with pytest.raises(st.DiagnoseError, match="give no effects or diagnosis"):
        calibrated.add_physics(hybrid=hybrid, effects=["cubic@1"])
