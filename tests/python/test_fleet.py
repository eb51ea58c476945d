"""Fleets on Dask: a killed worker loses nothing and counts nothing twice; bad data gets its
error in its row; `twin fleet` writes the report.

Real clusters on 127.0.0.1 only: `dask scheduler` and two `dask worker` processes of one thread
each (no nanny, so a killed worker stays dead), and LocalClusters.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

import shear_twin as st
from shear_twin import fleet
from conftest import run_twin, run_twin_ok

REPO = Path(__file__).resolve().parents[2]
VENV_BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def synthetic_fleet(tmp_path_factory):
    """Four synthetic structures (8 s records, hidden effects in turn) and one malformed record;
    diagnose and act, calibrations with 4 starts."""
    out = tmp_path_factory.mktemp("fleet")
    manifest = fleet.make_synthetic_fleet(out, 4, duration=8.0, seed=2, bad=1)
    m = json.loads(manifest.read_text())
    m["calibrate_starts"] = 4
    manifest.write_text(json.dumps(m))
    return manifest


@pytest.fixture(scope="module")
def one_worker(synthetic_fleet):
    return fleet.run_fleet(synthetic_fleet, workers=1)


def results(rows):
    """What a row says about its structure, without where and how long it ran."""
    return [{k: r[k] for k in ("structure", "action", "effect", "nmse_before", "nmse_after", "error")} for r in rows]


def test_bad_data_is_an_error_in_its_row_and_the_fleet_goes_on(synthetic_fleet, one_worker, tmp_path, twin_binary):
    rows, summary = one_worker
    bad = [r for r in rows if r["structure"] == "bad00"]
    assert len(bad) == 1
    done = run_twin(twin_binary, "compare", "--data", bad[0]["record"], cwd=REPO)
    assert bad[0]["error"] == done.stderr.strip().removeprefix("twin: error: ")
    assert "bad00.csv:5:" in bad[0]["error"]
    good = [r for r in rows if r["structure"] != "bad00"]
    assert all(r["error"] is None and r["nmse_after"] is not None for r in good)
    assert summary["errors"] == 1 and summary["structures"] == 5


def test_the_hidden_effects_are_acted_on(one_worker, synthetic_fleet):
    rows, _ = one_worker
    hidden = {s["name"]: s["hidden"] for s in json.loads(synthetic_fleet.read_text())["structures"]}
    by_name = {r["structure"]: r for r in rows}
    # The unchanged structure: nothing to do; the others acted on and their error cut at least
    # 4× (the diagnosis's own gate; measured: 6.7× for the weakest, cubic stiffness, which ends
    # at the noise level, and 100× or more for the others).
    assert by_name["s000"]["action"] == "none", by_name["s000"]
    for name, label in hidden.items():
        if label in ("none", "bad data"):
            continue
        r = by_name[name]
        if r["action"] != "none":
            assert r["action"] in ("add_physics", "recalibrate"), r
            assert r["nmse_after"] < r["nmse_before"] / 4, r
    assert sum(1 for r in rows if r["action"] in ("add_physics", "recalibrate")) >= 2


def test_a_killed_worker_loses_nothing_and_counts_nothing_twice(synthetic_fleet, one_worker, tmp_path):
    from distributed import Client

    scheduler_file = tmp_path / "scheduler.json"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs = [subprocess.Popen([str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(scheduler_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        deadline = time.time() + 60
        while not scheduler_file.exists() and time.time() < deadline:
            time.sleep(0.1)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        workers = {}
        for i in range(2):
            workers[f"w{i}"] = subprocess.Popen(
                [str(VENV_BIN / "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                 "--host", "127.0.0.1", "--no-dashboard", "--name", f"w{i}"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            procs.append(workers[f"w{i}"])
        client = Client(address)
        client.wait_for_workers(2, timeout=60)
        outcome = {}

        def run():
            outcome["value"] = fleet.run_fleet(synthetic_fleet, client=client)

        runner = threading.Thread(target=run)
        runner.start()
        # Wait until a task of a diagnosed structure has run a while on some worker, then
        # SIGKILL that worker.
        killed = None
        deadline = time.time() + 120
        while killed is None and time.time() < deadline:
            busy = {w: ts for w, ts in client.processing().items() if ts}
            long_running = [w for w, ts in busy.items() if any(not k.endswith(("s000", "bad00")) for k in ts)]
            if long_running:
                time.sleep(1.0)
                victim = long_running[0]
                if client.processing().get(victim):
                    name = client.scheduler_info()["workers"][victim]["name"]
                    workers[name].send_signal(signal.SIGKILL)
                    killed = victim
            time.sleep(0.05)
        assert killed is not None, "no task was running to kill"
        runner.join(timeout=300)
        assert not runner.is_alive()
        rows, summary = outcome["value"]
        client.close()
    finally:
        for p in procs:
            p.kill()
            p.wait()
    names = [r["structure"] for r in rows]
    assert sorted(names) == sorted(set(names)) and len(names) == 5  # each exactly once
    assert summary["workers"] == 2
    # The task running on the killed worker finished on the other one.
    assert sum(1 for r in rows if r["worker"] == killed) < sum(1 for r in rows if r["worker"] != killed)
    assert results(rows) == results(one_worker[0])  # deterministic: as with one worker


def test_twin_fleet_writes_the_report(synthetic_fleet, tmp_path, twin_binary):
    # Compare only (the diagnoses ran above), to keep the test short.
    manifest = json.loads(synthetic_fleet.read_text())
    manifest["tasks"] = ["compare"]
    for s in manifest["structures"]:
        s["twin"] = str(synthetic_fleet.parent / s["twin"])
        s["record"] = str(synthetic_fleet.parent / s["record"])
    compare_only = tmp_path / "manifest.json"
    compare_only.write_text(json.dumps(manifest))
    out = tmp_path / "report"
    done = run_twin_ok(twin_binary, "fleet", str(compare_only), "--workers", "2", "--out", str(out), cwd=REPO,
                       extra_env={"TWIN_PYTHON": sys.executable})
    frame = pd.read_parquet(out / "fleet.parquet")
    assert list(frame["structure"]) == ["s000", "s001", "s002", "s003", "bad00"]
    assert list(pd.read_csv(out / "fleet.csv")["structure"]) == list(frame["structure"])
    assert (out / "fleet.svg").stat().st_size > 1000
    summary = json.loads((out / "fleet-summary.json").read_text())
    assert summary["structures"] == 5 and summary["workers"] == 2
    assert summary["actions"] == {"compare": 4, "error": 1}  # the bad record: no action, an error
    assert "structures/min" in done.stdout
