"""The GP corrector on a building other than the paper's rig: a five-storey twin under ground
motion (`twin init --storeys 5 --excitation base --nominal N.json`), accelerometers on floors 1,
3 and 5 reading in g, records from `twin synth` of the same nominal building with a cubic spring
hidden in storey 3 (k3 = 1e7 N/m³) that the twin's physics lacks (without it the physics is
within 0.09 % NMSE of the record: sensor noise).

- `twin train` puts one GP per measured channel behind the physics; on the training record each
  channel's NMSE falls to under a tenth of the physics alone's, and on a record it never saw
  (another ground motion) it still falls, by less: a GP of 461 points learns the discrepancy of
  one record's excursions (an effect this size belongs in the physics: `diagnose`,
  `add-physics`);
- `twin learn` (uniform mode) streams both records, and the first ends below the physics alone;
- the trained twin's corrector FMU, laid out for these channels (physics_acc1/3/5, ground_acc,
  acc1/3/5, latent_var1/3/5, sd1/3/5 and no force), passes fmpy's validate_fmu.

The binary is target/release/twin (or TWIN_BINARY), the FMUs target/fmu (or TWIN_FMU_DIR), as
scripts/build-fmus.sh leaves them.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from conftest import run_twin_ok

ROOT = Path(__file__).resolve().parents[2]
BINARY = Path(os.environ.get("TWIN_BINARY", ROOT / "target" / "release" / "twin"))
FMU_DIR = Path(os.environ.get("TWIN_FMU_DIR", ROOT / "target" / "fmu"))
CHANNELS = ["acc1", "acc3", "acc5"]

NOMINAL = {"m": [5.2] * 5, "c": [0.5] * 5, "k": [4021.0] * 5}
EFFECT = "cubic@3:stiffness=1e7"

#: The corrected NMSE's largest share of the physics alone's, per channel, on the training
#: record. Measured: 4.30 / 3.85 / 1.31 % against 48.9 / 41.8 / 16.8 % (0.088, 0.092, 0.078);
#: a fifth leaves a margin above 2.
SHARE_TRAINED = 0.2
#: The same on the unseen record. Measured: 38.4 / 47.1 / 21.3 % against 55.7 / 57.7 / 32.6 %
#: (0.69, 0.82, 0.65); 0.95 leaves 16 % on the worst channel.
SHARE_UNSEEN = 0.95
#: learn (uniform) on the first record. Measured: 38.6 / 32.7 / 11.4 % against 48.9 / 41.8 /
#: 16.8 % (0.79, 0.78, 0.68); on the second record acc3 ends above the physics (68.7 against
#: 57.7 %), which is why only the first is held to this.
SHARE_LEARNED = 0.9


@pytest.fixture(scope="module")
def building(tmp_path_factory):
    """The five-storey twin and two records of the building with the hidden cubic spring."""
    for needed in (BINARY, FMU_DIR / "fmu_gp_corrector.fmu"):
        if not needed.is_file():
            pytest.fail(f"{needed} does not exist: run scripts/build-fmus.sh", pytrace=False)
    folder = tmp_path_factory.mktemp("five")
    model, nominal = folder / "five.ssp", folder / "nominal.json"
    nominal.write_text(json.dumps(NOMINAL))
    run_twin_ok(BINARY, "init", "--storeys", "5", "--excitation", "base", "--nominal", str(nominal), "--out", str(model))
    records = []
    for seed in (1, 2):
        record = folder / f"r{seed}.csv"
        run_twin_ok(BINARY, "synth", "--storeys", "5", "--excitation", "base", "--nominal", str(nominal),
             "--channels", ",".join(CHANNELS), "--units", "acc=g", "--effect", EFFECT,
             "--duration", "20", "--seed", str(seed), "--out", str(record))
        records.append(record)
    assert records[0].read_text().splitlines()[0] == "time,ground_acc,acc1 (g),acc3 (g),acc5 (g)"
    return folder, model, records


def compare_nmse(model: Path, record: Path, folder: Path, name: str) -> list[float]:
    report = folder / f"{name}.json"
    run_twin_ok(BINARY, "compare", "--twin", str(model), "--data", str(record), "--report", str(report))
    got = json.loads(report.read_text())
    assert got["channels"] == CHANNELS
    return got["nmse"]


def test_train_corrects_every_channel_of_a_five_storey_building(building):
    folder, model, (first, second) = building
    trained, report = folder / "trained.ssp", folder / "train.json"
    run_twin_ok(BINARY, "train", "--twin", str(model), "--data", str(first), "--stride", "2", "--out", str(trained),
         "--report", str(report))
    got = json.loads(report.read_text())
    assert got["channels"] == CHANNELS
    # One GP per channel, each on its own acceleration, its two neighbours and the ground's:
    # 4 (q + 1) = 40 inputs at the default 9 lags.
    assert got["training"]["inputs"] == 40
    assert len(got["training"]["hyperparameters"]) == 3
    physics, corrected = got["nmse_physics"], got["nmse"]
    print("training record: physics", physics, "corrected", corrected)
    assert min(physics) > 10, physics  # the hidden spring: the physics alone is far off
    for c, p, n in zip(CHANNELS, physics, corrected):
        assert n < SHARE_TRAINED * p, f"{c}: corrected {n} % against the physics' {p} %"
    # A record it never saw: the same building, another ground motion.
    unseen_physics = compare_nmse(model, second, folder, "physics2")
    unseen = compare_nmse(trained, second, folder, "corrected2")
    print("unseen record: physics", unseen_physics, "corrected", unseen)
    for c, p, n in zip(CHANNELS, unseen_physics, unseen):
        assert n < SHARE_UNSEEN * p, f"{c}: corrected {n} % against the physics' {p} % on {second.name}"


def test_the_trained_corrector_fmu_is_laid_out_for_the_channels_and_validates(building):
    folder, model, (first, _) = building
    trained = folder / "trained-fmu.ssp"
    run_twin_ok(BINARY, "train", "--twin", str(model), "--data", str(first), "--lags", "2", "--stride", "8",
         "--out", str(trained))
    with zipfile.ZipFile(trained) as ssp:
        inner = [n for n in ssp.namelist() if n.endswith("fmu_gp_corrector.fmu")]
        assert len(inner) == 1, ssp.namelist()
        fmu = folder / "corrector.fmu"
        fmu.write_bytes(ssp.read(inner[0]))
    problems = validate_fmu(str(fmu))
    assert problems == [], problems
    names = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    for c in CHANNELS:
        i = c[3:]
        for name in (f"physics_{c}", f"measured_{c}", c, f"latent_var{i}", f"sd{i}"):
            assert name in names, name
    assert "ground_acc" in names and "force" not in names
    assert "acc2" not in names and "physics_acc2" not in names
    assert names["latent_var5"].unit == "m2/s4"


def test_learn_streams_the_records_of_a_five_storey_building(building):
    folder, model, records = building
    report = folder / "learn.json"
    run_twin_ok(BINARY, "learn", "--twin", str(model), "--data", *map(str, records), "--mode", "uniform",
         "--report", str(report), "--out", str(folder / "learned.ssp"))
    got = json.loads(report.read_text())
    (mode,) = got["modes"]
    for r in mode["records"]:
        print(r["record"], "physics", r["nmse_physics"], "final", r["final_nmse"], r["queries"])
        assert len(r["final_nmse"]) == len(r["threshold_at_end"]) == 3
        assert r["queries"] > 0
    first = mode["records"][0]
    for c, p, n in zip(CHANNELS, first["nmse_physics"], first["final_nmse"]):
        assert n < SHARE_LEARNED * p, f"{first['record']} {c}: learned {n} % against the physics' {p} %"
    assert (folder / "learned.ssp").is_file()
