"""The live page of `twin watch --serve`, read in a real browser (Debian's chromium, headless,
driven by selenium through chromium-driver).

A twin calibrated on a synthetic record of the paper rig's structure watches a 60 s stream of the
same structure whose second storey loses 15 % of its stiffness at 30 s (`twin synth --change
k2@30:0.85`), piped in
paced chunks so the page sees it arrive. The test reads the page's DOM: the plots' point
counters grow; the rolling NMSE after the change is above what it was before; the `failing`
alert, then the background diagnosis, appear; a second browser and a reloaded one see the same
alerts (the history); a POST with a wrong token is refused (403) and one without a token too
(401) while the watch goes on; a malformed body gets 400. No timing is asserted: every wait polls
with a generous limit. Everything talks to 127.0.0.1 only.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from test_fmpy_storeys import TARGET
from conftest import run_twin_ok

CHANGE_AT = 30.0
TOKEN = "page-test-token"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"


@pytest.fixture(scope="module")
def building(tmp_path_factory, twin_binary):  # noqa: F811
    """The paper rig's structure (`twin synth`'s default): a twin calibrated on a 20 s record
    with 0.003 m/s² of sensor noise, and a 60 s stream whose storey 2 loses 15 % of its
    stiffness at 30 s."""
    folder = tmp_path_factory.mktemp("page")
    run_twin_ok(twin_binary, "synth", "--seed", "1", "--noise-sd", "0.003", "--duration", "20",
        "--out", str(folder / "calibration.csv"))
    run_twin_ok(twin_binary, "calibrate", "--data", str(folder / "calibration.csv"), "--out", str(folder / "T.ssp"))
    run_twin_ok(twin_binary, "synth", "--seed", "2", "--noise-sd", "0.003", "--duration", "60",
        "--change", f"k2@{CHANGE_AT}:0.85", "--out", str(folder / "changed.csv"))
    return folder


def browser(tmp_path: Path):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", "--window-size=1400,1000",
                 f"--user-data-dir={tmp_path}"]:
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def wait_for(what: str, check, limit: float = 240.0, every: float = 0.2):
    """Poll `check` until it returns something true; fail naming `what` after `limit` s."""
    deadline = time.monotonic() + limit
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"waited {limit:.0f} s for {what}")
        time.sleep(every)


def post(url: str, body: str, token: str | None) -> tuple[int, dict]:
    headers = {"Content-Type": "application/json"}
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    request = urllib.request.Request(url, data=body.encode(), headers=headers, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def page_alerts(driver) -> list[tuple[str, str]]:
    return driver.execute_script(
        "return [...document.querySelectorAll('#alerts li')].map(li => [li.dataset.kind, li.dataset.seq]);")


def points_drawn(driver) -> list[int]:
    return driver.execute_script(
        "return [...document.querySelectorAll('canvas.plot')].map(c => Number(c.dataset.points));")


def nmse_shown(driver) -> tuple[float | None, list[float | None]]:
    """The stream time the state panel shows and the NMSE text of each channel."""
    return driver.execute_script("""
        const t = parseFloat(document.querySelector('#state [data-field="time"]').textContent);
        const v = [...document.querySelectorAll('.nmse-value')].map(e => e.dataset.nmse === '' ? null : Number(e.dataset.nmse));
        return [isFinite(t) ? t : null, v];""")


def test_the_live_page_shows_the_change_its_alert_and_diagnosis(building, twin_binary, tmp_path):  # noqa: F811
    pytest.importorskip("selenium")
    if not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()):
        pytest.fail("chromium and chromium-driver are needed: scripts/prerequisites.sh installs them", pytrace=False)
    lines = (building / "changed.csv").read_text().splitlines(keepends=True)
    alerts = tmp_path / "alerts.jsonl"
    watch = subprocess.Popen(
        [str(twin_binary), "watch", "--twin", str(building / "T.ssp"), "--source", "-",
         "--alerts", str(alerts), "--serve", "127.0.0.1:0", "--serve-linger", "600", "--token", TOKEN],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, TWIN_FMU_DIR=str(TARGET / "fmu")))
    drivers = []
    try:
        serving = watch.stderr.readline()
        match = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\n", serving)
        assert match, f"the first line on stderr: {serving!r}"
        url = match.group(1)
        stderr_rest: list[str] = []
        threading.Thread(target=lambda: stderr_rest.extend(watch.stderr), daemon=True).start()

        first = browser(tmp_path / "chrome-a")
        drivers.append(first)
        first.get(url)

        # The stream, paced: the header and 50 lines (about 1 s of stream) every 0.4 s.
        def feed():
            watch.stdin.write(lines[0])
            for k in range(1, len(lines), 50):
                watch.stdin.write("".join(lines[k:k + 50]))
                watch.stdin.flush()
                time.sleep(0.4)
            watch.stdin.close()
        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()

        channels = wait_for("the three channels' plots", lambda: first.execute_script(
            "return [...document.querySelectorAll('canvas.plot')].map(c => c.dataset.channel);") or None, limit=120)
        assert channels == ["acc1", "acc2", "acc3"]
        counts = wait_for("points drawn", lambda: (c := points_drawn(first)) and min(c) > 0 and c, limit=120)
        later = wait_for("more points drawn", lambda: (c := points_drawn(first)) and min(c) > max(counts) and c,
                         limit=120)
        assert min(later) > max(counts)

        # The NMSE shown per channel against the stream time, until the failing alert.
        seen: list[tuple[float, list[float | None]]] = []

        def failing_yet():
            t, values = nmse_shown(first)
            if t is not None:
                seen.append((t, values))
            return any(kind == "failing" for kind, _ in page_alerts(first))
        wait_for("the failing alert", failing_yet, limit=300, every=0.25)

        # Refused changes while the watch goes on.
        status, body = post(url + "api/ack", '{"seq": 1}', "wrong")
        assert status == 403 and "wrong token" in body["error"], body
        status, body = post(url + "api/ack", '{"seq": 1}', None)
        assert status == 401 and "no token" in body["error"], body
        status, body = post(url + "api/ack", '{"seq": ', TOKEN)
        assert status == 400 and body["error"].startswith("POST /api/ack: the body is not JSON"), body
        status, body = post(url + "api/accept", '{"diagnosis": -1}', TOKEN)
        assert status == 400 and "positive integer" in body["error"], body
        before_refusals = max(points_drawn(first))
        wait_for("the watch going on after the refused requests",
                 lambda: max(points_drawn(first)) > before_refusals, limit=120)
        assert watch.poll() is None

        # NMSE after the change (the last seen, once failing) above every value before it.
        before = [v for t, vs in seen if 15.0 < t < CHANGE_AT for v in vs if v is not None]
        assert before, seen[:20]
        _, now = nmse_shown(first)
        after = [v for v in now if v is not None]
        assert after and max(after) > max(before), (max(before), now)

        # A good acknowledgement of the failing alert.
        failing_seq = next(int(seq) for kind, seq in page_alerts(first) if kind == "failing")
        status, body = post(url + "api/ack", json.dumps({"seq": failing_seq, "note": "seen in the test"}), TOKEN)
        assert status == 200, body

        # The diagnosis lands (the stream's end waits for it).
        action = wait_for("the diagnosis", lambda: first.find_element("id", "diagnosis").get_attribute("data-action"),
                          limit=600, every=0.5)
        if action != "add_physics":
            status, body = post(url + "api/accept", "{}", TOKEN)
            assert status == 409 and "only add_physics adds physics" in body["error"], body
        kinds = [k for k, _ in reversed(page_alerts(first))]
        assert kinds.index("failing") < kinds.index("diagnosis"), kinds
        feeder.join(timeout=120)
        wait_for("the end alert", lambda: any(k == "end" for k, _ in page_alerts(first)), limit=600, every=0.5)
        assert watch.poll() is None, "the page lingers after the stream"

        # A second browser gets the same alerts from the history; so does a reload.
        everything = page_alerts(first)
        second = browser(tmp_path / "chrome-b")
        drivers.append(second)
        second.get(url)
        wait_for("the second browser's alerts", lambda: page_alerts(second) == everything, limit=120)
        assert second.find_element("id", "diagnosis").get_attribute("data-action") == action
        assert min(points_drawn(second)) > 0
        first.refresh()
        wait_for("the reloaded page's alerts", lambda: page_alerts(first) == everything, limit=120)
        assert min(points_drawn(first)) > 0

        # The alerts file has it all; the acknowledgement went beside it.
        written = [json.loads(line) for line in alerts.read_text().splitlines()]
        written_kinds = [a["kind"] for a in written]
        assert written_kinds.index("failing") < written_kinds.index("diagnosis"), written_kinds
        diagnosis = next(a for a in written if a["kind"] == "diagnosis")
        assert action == diagnosis.get("action", "error"), (action, diagnosis)
        assert written[-1]["kind"] == "end"
        acks = [json.loads(line) for line in (tmp_path / "alerts.acks.jsonl").read_text().splitlines()]
        assert acks and acks[0]["ack"] == failing_seq
    finally:
        for d in drivers:
            d.quit()
        if watch.poll() is None:
            watch.terminate()
        watch.wait(timeout=60)


def test_accepting_a_diagnosis_writes_a_new_twin_beside_the_old(twin_binary, tmp_path):  # noqa: F811
    """dataset3 (contact between floors 2 and 3) watched by the twin calibrated on dataset1,
    with a token: the background diagnosis is add_physics; `POST /api/accept` runs add-physics
    on its report and samples and the page's `accept` event names the new twin, written beside
    the old one, which is unchanged; a diagnosis that has not landed is refused (404)."""
    root = Path(__file__).resolve().parents[2]
    twin = tmp_path / "T.ssp"
    run_twin_ok(twin_binary, "calibrate", "--data", str(root / "data" / "dataset1.csv"), "--out", str(twin))
    original = twin.read_bytes()
    alerts = tmp_path / "alerts.jsonl"
    watch = subprocess.Popen(
        [str(twin_binary), "watch", "--twin", str(twin), "--source", str(root / "data" / "dataset3.csv"),
         "--alerts", str(alerts), "--serve", "127.0.0.1:0", "--serve-linger", "600", "--token", TOKEN],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, TWIN_FMU_DIR=str(TARGET / "fmu")))
    try:
        url = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\n", watch.stderr.readline()).group(1)

        def history():
            with urllib.request.urlopen(url + "api/history", timeout=30) as r:
                return json.loads(r.read())
        wait_for("the end alert", lambda: any(e.get("alert", {}).get("kind") == "end" for e in history()),
                 limit=600, every=0.5)
        diagnosis = next(e["alert"] for e in history() if e.get("alert", {}).get("kind") == "diagnosis")
        assert diagnosis["action"] == "add_physics", diagnosis
        status, body = post(url + "api/accept", '{"diagnosis": 2}', TOKEN)
        assert status == 404 and "no diagnosis 2" in body["error"], body
        status, body = post(url + "api/accept", "{}", TOKEN)
        assert status == 202 and body["status"] == "started", body
        out = Path(body["out"])
        assert out.parent == twin.parent and out.name == "T.accepted-1.ssp", out
        done = wait_for("the accepted twin", lambda: [e for e in history()
                                                      if e["type"] == "accept" and e["status"] != "started"],
                        limit=600, every=0.5)
        assert done[0]["status"] == "done", done
        assert "contact@2-3" in done[0]["printout"], done[0]["printout"]
        assert out.is_file() and twin.read_bytes() == original
        assert watch.poll() is None
    finally:
        if watch.poll() is None:
            watch.terminate()
        watch.wait(timeout=60)


def test_twin_serve_shows_a_finished_watch_and_a_fleet(twin_binary, tmp_path):  # noqa: F811
    """`twin serve --fleet` over a fleet report: one row per structure with its status, and the
    structure whose finished watch is beside the report has its own view, whose history is that
    watch's alerts; an unknown view is 404; a public address is refused without --public."""
    alerts = [
        {"seq": 1, "time": 30.4, "kind": "failing", "channels": ["acc2"], "floors": [2], "nmse": [1.0, 4.0]},
        {"time": 40.0, "kind": "diagnosis", "action": "recalibrate", "channels": ["acc1", "acc2"],
         "effects": [], "nmse_before": [1.0, 4.0], "nmse_after": [0.1, 0.2]},
        {"seq": 2, "time": 60.0, "kind": "end", "channels": ["acc1", "acc2"], "nmse": [0.5, 1.5],
         "tolerance": 0.5, "samples": 3072},
    ]
    (tmp_path / "s001.alerts.jsonl").write_text("".join(json.dumps(a) + "\n" for a in alerts))
    (tmp_path / "fleet.csv").write_text(
        "structure,record,action,effect,nmse_before,nmse_after,frequency_shift,modes_moved,seconds,worker,pid,error\n"
        "s000,s000.csv,none,,0.2,0.2,0.31,,1,local,1,\n"
        "s001,s001.csv,recalibrate,,4.0,0.2,-3.66,2,1,local,1,\n"
        "s002,s002.csv,,,,,,,0,local,1,cannot read s002.csv\n")
    refused = subprocess.run([str(twin_binary), "serve", "--fleet", str(tmp_path / "fleet.csv"), "--addr", "0.0.0.0:0"],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode != 0 and "add --public" in refused.stderr, refused.stderr
    serve = subprocess.Popen([str(twin_binary), "serve", "--fleet", str(tmp_path / "fleet.csv"),
                              "--addr", "127.0.0.1:0", "--seconds", "120"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\n", serve.stderr.readline()).group(1)
        with urllib.request.urlopen(url + "api/history", timeout=30) as r:
            fleet = json.loads(r.read())
        rows = next(e["rows"] for e in fleet if e["type"] == "fleet")
        assert [(r["name"], r["status"], r["view"]) for r in rows] == [
            ("s000", "ok", False), ("s001", "attention", True), ("s002", "error", False)]
        assert rows[1]["frequency_shift"] == -3.66 and rows[1]["nmse"] == 4.0
        with urllib.request.urlopen(url + "api/history?view=s001", timeout=30) as r:
            view = json.loads(r.read())
        assert view[0]["type"] == "meta" and view[0]["channels"] == ["acc1", "acc2"]
        assert [e["alert"]["kind"] for e in view if e["type"] == "alert"] == ["failing", "diagnosis", "end"]
        with pytest.raises(urllib.error.HTTPError) as missing:
            urllib.request.urlopen(url + "api/history?view=nobody", timeout=30)
        assert missing.value.code == 404
    finally:
        serve.terminate()
        serve.wait(timeout=60)


def test_twin_serve_shows_a_record_against_its_twin(building, twin_binary):  # noqa: F811
    """`twin serve --twin T --data D`: compare's series as points (measured, twin, the ±3σ band,
    the rolling NMSE, failing windows shaded) and the failing windows as alerts; its NMSE after
    the change above the NMSE before it."""
    serve = subprocess.Popen([str(twin_binary), "serve", "--twin", str(building / "T.ssp"),
                              "--data", str(building / "changed.csv"), "--addr", "127.0.0.1:0", "--seconds", "120"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                             env=dict(os.environ, TWIN_FMU_DIR=str(TARGET / "fmu")))
    try:
        line = serve.stderr.readline()
        url = re.fullmatch(r"serving (http://127\.0\.0\.1:\d+/)\n", line).group(1)
        with urllib.request.urlopen(url + "api/history", timeout=30) as r:
            history = json.loads(r.read())
    finally:
        serve.terminate()
        serve.wait(timeout=60)
    assert history[0]["type"] == "meta" and history[0]["mode"] == "record"
    assert history[0]["channels"] == ["acc1", "acc2", "acc3"]
    points = [e for e in history if e["type"] == "point"]
    assert len(points) == 3072, len(points)
    assert all(p["band"][0] > 0 for p in points)
    failing = [e["alert"] for e in history if e["type"] == "alert" and e["alert"]["kind"] == "failing"]
    assert failing and failing[0]["start"] > CHANGE_AT - 1.0, failing
    assert any(p["open"] for p in points) and not any(p["open"] for p in points if p["t"] < CHANGE_AT)
    worst = lambda p: max(v for v in p["nmse"] if v is not None)  # noqa: E731
    before = max(worst(p) for p in points if 15.0 < p["t"] < CHANGE_AT)
    after = max(worst(p) for p in points if p["t"] > CHANGE_AT + 5.0)
    assert after > before, (before, after)
