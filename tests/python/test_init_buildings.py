"""``shear_twin.init`` for any shear building, as ``twin init`` makes it: a five-storey twin under
ground motion from an engineer's nominal (a dict or a file) predicts ``twin synth``'s record of
that building to the sensor noise, calibrates on it and diagnoses another record of it as
``none``; a nominal of the wrong length, an unknown excitation and a priors key the building
lacks are refused before anything is written, naming what is wrong.

The binary is target/release/twin (or TWIN_BINARY), the FMUs target/fmu (or TWIN_FMU_DIR), as
scripts/build-fmus.sh leaves them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import shear_twin as st
from conftest import run_twin_ok

ROOT = Path(__file__).resolve().parents[2]
BINARY = Path(os.environ.get("TWIN_BINARY", ROOT / "target" / "release" / "twin"))
FMU_DIR = Path(os.environ.get("TWIN_FMU_DIR", ROOT / "target" / "fmu"))

NOMINAL = {"m": [5.2, 5.0, 4.8, 4.6, 4.4], "c": [3.0, 2.5, 2.5, 2.0, 2.0],
           "k": [5200.0, 4800.0, 4400.0, 4000.0, 3600.0]}
#: The twin made from the building's own nominal against a record of it: measured 0.085 /
#: 0.085 / 0.075 % (the synthetic sensors' noise, 3 % of each channel's RMS); 0.3 % is 3.5x.
NMSE_OF_THE_SAME_BUILDING = 0.3


def synth(folder: Path, name: str, seed: int) -> Path:
    nominal = folder / "nominal.json"
    nominal.write_text(json.dumps(NOMINAL))
    record = folder / name
    run_twin_ok(BINARY, "synth", "--storeys", "5", "--excitation", "base", "--nominal", str(nominal),
                "--channels", "acc1,acc3,acc5", "--units", "acc=g", "--duration", "20", "--seed", str(seed),
                "--out", str(record), fmu_dir=FMU_DIR, timeout=300)
    return record


def test_a_five_storey_twin_from_a_nominal_predicts_calibrates_and_diagnoses(tmp_path):
    if not BINARY.is_file():
        pytest.fail(f"{BINARY} does not exist: run scripts/build-fmus.sh", pytrace=False)
    out = tmp_path / "five.ssp"
    twin = st.init(out, storeys=5, excitation="base", nominal=NOMINAL)
    assert out.is_file()
    # The same twin from the nominal as a file, and opened from the archive.
    (tmp_path / "n.json").write_text(json.dumps(NOMINAL))
    again = st.init(excitation="base", nominal=tmp_path / "n.json")
    opened = st.Twin.open(out)

    first = st.Record.read(synth(tmp_path, "r1.csv", 1))
    assert first.channels == ["ground_acc", "acc1", "acc3", "acc5"]
    for t in (twin, again, opened):
        comparison = t.compare(first)
        assert comparison["channels"] == ["acc1", "acc3", "acc5"]
        assert max(comparison["nmse"]) < NMSE_OF_THE_SAME_BUILDING, comparison["nmse"]

    calibrated, report = twin.calibrate(first, starts=2)
    assert sorted(calibrated.noise_variance) == ["acc1", "acc3", "acc5"]
    assert len(report["parameters"]) == 15
    diagnosis = calibrated.diagnose(st.Record.read(synth(tmp_path, "r2.csv", 2)))
    assert diagnosis["action"] == "none", diagnosis["reason"]
    assert diagnosis["channels"] == ["acc1", "acc3", "acc5"]


def test_bad_requests_are_refused_naming_what_is_wrong(tmp_path):
    with pytest.raises(st.ShearTwinError, match='"m" has 5 values but --storeys is 4'):
        st.init(tmp_path / "x.ssp", storeys=4, nominal=NOMINAL)
    with pytest.raises(st.ShearTwinError, match='excitation="sideways"'):
        st.init(storeys=2, excitation="sideways")
    with pytest.raises(st.ShearTwinError, match="k7"):
        st.init(storeys=5, excitation="base", nominal=NOMINAL,
                priors={"k7": {"relative_sd": 0.1}})
    with pytest.raises(st.ShearTwinError, match="nominal="):
        st.init(nominal={"m": [5.0], "c": [1.0]})
    assert not (tmp_path / "x.ssp").exists()
