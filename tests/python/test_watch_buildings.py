"""`Twin.watch` on a building other than the paper's rig: a five-storey twin under ground motion
(`twin init --storeys 5 --excitation base`, synth's equal floors) watched on a 60 s stream of
the same building whose second storey loses 30 % of its stiffness at 30 s, its columns under
other names mapped back by `columns=` (a dict, as `Record.read` takes it): no alert before the
change, a `failing` alert naming the stream's channels after it; a column for a floor the twin
lacks raises `WatchError` naming it.
"""

from __future__ import annotations

import json

import pytest

import shear_twin as st
from conftest import run_twin_ok

CHANGE_AT = 30.0


@pytest.fixture(scope="module")
def five_storeys(tmp_path_factory, twin_binary):  # noqa: F811
    folder = tmp_path_factory.mktemp("watch5")
    (folder / "nominal.json").write_text(json.dumps({"m": [5.2] * 5, "c": [3.0] * 5, "k": [4021.0] * 5}))
    (folder / "stationary.json").write_text(json.dumps({"ground_motion": {"strong_end": 1000}}))
    run_twin_ok(twin_binary, "init", "--storeys", "5", "--excitation", "base",
        "--nominal", str(folder / "nominal.json"), "--out", str(folder / "T.ssp"))
    run_twin_ok(twin_binary, "synth", "--scenario", str(folder / "stationary.json"), "--storeys", "5",
        "--excitation", "base", "--duration", "60", "--seed", "3", "--channels", "acc1,acc3,acc5",
        "--units", "acc=g", "--change", f"k2@{CHANGE_AT}:0.7", "--out", str(folder / "changed.csv"))
    return folder


def test_a_five_storey_stream_under_other_names_alerts_after_its_change(five_storeys, tmp_path):
    text = (five_storeys / "changed.csv").read_text()
    header = "time,ground_acc,acc1 (g),acc3 (g),acc5 (g)"
    assert text.startswith(header + "\n")
    stream = tmp_path / "renamed.csv"
    stream.write_text(text.replace(header, "t,ag,low (g),mid (g),top (g)", 1))
    columns = {"t": "time", "ag": "ground_acc", "low": "acc1", "mid": "acc3", "top": "acc5"}
    twin = st.Twin.open(str(five_storeys / "T.ssp"))
    seen = []
    summary = twin.watch(stream, tmp_path / "alerts.jsonl", columns=columns, on_alert=seen.append,
                         diagnosis=False)
    assert summary.channels == ["acc1", "acc3", "acc5"]
    assert summary.samples == 3072
    failing = [a for a in seen if a["kind"] == "failing"]
    assert failing, seen
    # No alert before the change; the first within 10 s of it (measured: 3.4 s, naming acc3).
    assert all(a["time"] > CHANGE_AT for a in seen if a["kind"] != "end"), seen
    assert failing[0]["time"] < CHANGE_AT + 10.0
    assert failing[0]["channels"] and set(failing[0]["channels"]) <= {"acc1", "acc3", "acc5"}
    assert summary.noise_source.startswith("prior")


def test_a_floor_the_twin_lacks_is_refused_naming_the_column(five_storeys, tmp_path):
    stream = tmp_path / "bad.csv"
    stream.write_text("time,ground_acc,acc1,acc6\n0,0,0,0\n0.01,0,0,0\n")
    twin = st.Twin.open(str(five_storeys / "T.ssp"))
    with pytest.raises(st.WatchError) as caught:
        twin.watch(stream, tmp_path / "a.jsonl", diagnosis=False)
    assert "column 'acc6' is for floor 6; the structure has floors 1 to 5" in str(caught.value)
    assert not (tmp_path / "a.jsonl").exists()
