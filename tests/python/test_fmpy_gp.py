"""The GP corrector FMU under fmpy 0.3.32 and fmu-manipulation-toolbox 2.0: validation, the FMU
driven step by step through `fmpy.fmi2.FMU2Slave` (learning, FMU states, a bad training file),
a bundled training set checked against an independent numpy GP, and the corrector coupled to the
shear FMU in the toolbox's FMU Container.

The FMU is `target/fmu/fmu_gp_corrector.fmu` (built by scripts/build-fmus.sh), or the file named
by the environment variable GP_FMU. The container's schedules (parallel: a Jacobi step with links
delayed by one step; sequential: a Gauss-Seidel sweep in configuration order) are described in
test_third_party.py; here they decide which shear sample the corrector sees. The container runtime
prints "[ERROR] Solver configure...." at instantiation whatever it embeds (also explained there):
the toolbox's message about its own solver, nothing about these FMUs.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu
from fmu_manipulation_toolbox.assembly import Assembly

from shear_drive import ACCELERATIONS, STEP, ShearFmu, assert_within, instantiate

REPO_ROOT = Path(__file__).resolve().parents[2]
TOOLBOX_LOGGER = "fmu_manipulation_toolbox"
FLOORS = (1, 2, 3)
PHYSICS = tuple(f"physics_acc{i}" for i in FLOORS)
MEASURED = tuple(f"measured_acc{i}" for i in FLOORS)
CORRECTED = tuple(f"acc{i}" for i in FLOORS)
LATENT = tuple(f"latent_var{i}" for i in FLOORS)
SD = tuple(f"sd{i}" for i in FLOORS)
OUTPUTS = CORRECTED + LATENT + SD


@pytest.fixture(scope="module")
def gp_fmu_path() -> Path:
    path = Path(os.environ.get("GP_FMU", REPO_ROOT / "target" / "fmu" / "fmu_gp_corrector.fmu"))
    if not path.is_file():
        pytest.fail(f"the GP corrector FMU {path} does not exist: run scripts/build-fmus.sh", pytrace=False)
    return path


@pytest.fixture(scope="module")
def gp_fmu(gp_fmu_path, tmp_path_factory) -> ShearFmu:
    """The archive, its model description and its unpacked folder (ShearFmu holds any FMU)."""
    return ShearFmu.open(gp_fmu_path, tmp_path_factory.mktemp("fmu_gp_corrector"))


# ------------------------------------------------------------------------------------------------
# Data: a smooth seeded record, the lag vector as the corrector's documentation defines it, and a
# Matérn 3/2 ARD GP written here from the equations, independent of the Rust code.


def physics_record(seed: int, n: int) -> np.ndarray:
    """n samples of (physics_acc1..3, force) at the example data's scale."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * STEP
    columns = []
    for c, amplitude in enumerate((0.1, 0.1, 0.1, 0.25)):
        phase = rng.uniform(0.0, 6.0)
        columns.append(amplitude * np.sin(2 * np.pi * (3.0 + c) * t + phase) + rng.uniform(-0.01, 0.01, n))
    return np.stack(columns, axis=1)


def measured_of(record: np.ndarray) -> np.ndarray:
    """'Measured' accelerations: physics plus a smooth discrepancy per floor."""
    floors = np.arange(3)
    return record[:, :3] + 0.02 * np.sin(3.0 * record[:, 3:4] + (floors + 1.0) * record[:, :3]) + 0.005 * floors


def lag_vectors(record: np.ndarray, lags: int) -> np.ndarray:
    """Per sample: channel by channel (physics_acc1, 2, 3, force), oldest first, the current and
    `lags` previous samples; before the record reaches back that far, its first sample."""
    rows = []
    for k in range(len(record)):
        indices = [max(k - lag, 0) for lag in range(lags, -1, -1)]
        rows.append(np.concatenate([record[indices, c] for c in range(4)]))
    return np.array(rows)


def matern32(a: np.ndarray, b: np.ndarray, length_scales: np.ndarray, signal_variance: float) -> np.ndarray:
    scaled = (a[:, None, :] - b[None, :, :]) / length_scales
    r = np.sqrt(np.sum(scaled**2, axis=-1))
    return signal_variance * (1.0 + np.sqrt(3.0) * r) * np.exp(-np.sqrt(3.0) * r)


def gp_predict(x_train, y_train, hyper: dict, x_test):
    """Mean and latent variance of a zero-mean GP: k*ᵀK⁻¹y and σ_f² − k*ᵀK⁻¹k*."""
    ls = np.asarray(hyper["length_scales"])
    sf2, sn2 = hyper["signal_variance"], hyper["noise_variance"]
    k = matern32(x_train, x_train, ls, sf2) + sn2 * np.eye(len(x_train))
    factor = np.linalg.cholesky(k)
    alpha = np.linalg.solve(factor.T, np.linalg.solve(factor, y_train))
    k_star = matern32(x_test, x_train, ls, sf2)
    v = np.linalg.solve(factor, k_star.T)
    return k_star @ alpha, sf2 - np.sum(v**2, axis=0)


def training_set(lags: int, n: int, seed: int) -> dict:
    """A training file (discrepancy form) with hyperparameters, as the crate documents it."""
    record = physics_record(seed, n)
    x = lag_vectors(record, lags)
    y = measured_of(record) - record[:, :3]
    d = x.shape[1]
    hyperparameters = [
        {
            "length_scales": [0.3 + 0.05 * ((i + f) % 7) for i in range(d)],
            "signal_variance": 4e-4 * (f + 1),
            "noise_variance": 1e-6,
        }
        for f in range(3)
    ]
    return {
        "lags": lags,
        "target": "discrepancy",
        "inputs": x.tolist(),
        "targets": y.tolist(),
        "hyperparameters": hyperparameters,
    }


def with_training_file(fmu_path: Path, training: dict, out: Path) -> Path:
    """A copy of the FMU with `training` as resources/training.json."""
    with zipfile.ZipFile(fmu_path) as source, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            if item.filename != "resources/training.json":
                target.writestr(item, source.read(item.filename))
        target.writestr("resources/training.json", json.dumps(training))
    return out


# ------------------------------------------------------------------------------------------------
# Driving the corrector through FMU2Slave


def open_corrector(fmu: ShearFmu, integers: dict | None = None, strings: dict | None = None, name="corrector"):
    """Instantiate → set up at t = 0 → set parameters → initialize."""
    slave = FMU2Slave(
        guid=fmu.model_description.guid,
        unzipDirectory=str(fmu.unzip_dir),
        modelIdentifier=fmu.model_identifier,
        instanceName=name,
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    for variable, value in (integers or {}).items():
        slave.setInteger([fmu.vr(variable)], [int(value)])
    for variable, value in (strings or {}).items():
        slave.setString([fmu.vr(variable)], [value])
    slave.exitInitializationMode()
    return slave


def set_sample(slave, fmu: ShearFmu, sample, measured=(0.0, 0.0, 0.0), learn=False) -> None:
    names = PHYSICS + ("force",) + MEASURED
    slave.setReal([fmu.vr(n) for n in names], [float(v) for v in (*sample, *measured)])
    slave.setBoolean([fmu.vr("learn")], [bool(learn)])


def read_outputs(slave, fmu: ShearFmu) -> np.ndarray:
    """Rows acc, latent_var, sd; columns floors 1..3."""
    return np.array(slave.getReal([fmu.vr(n) for n in OUTPUTS])).reshape(3, 3)


def training_points(slave, fmu: ShearFmu) -> int:
    return slave.getInteger([fmu.vr("training_points")])[0]


def close(slave) -> None:
    slave.terminate()
    slave.freeInstance()


# ------------------------------------------------------------------------------------------------


def test_validate_fmu_reports_no_problem(gp_fmu_path):
    problems = validate_fmu(str(gp_fmu_path))
    assert problems == [], "fmpy.validation.validate_fmu:\n" + "\n".join(problems)


def test_fmutool_check_accepts_the_fmu(gp_fmu_path):
    fmutool = Path(sys.executable).with_name("fmutool")
    completed = subprocess.run(
        [str(fmutool), "-input", str(gp_fmu_path), "-check"], capture_output=True, text=True, timeout=120
    )
    output = completed.stdout + completed.stderr
    assert completed.returncode == 0, output
    assert "This FMU seems to be compliant with FMI-2.0." in output, output
    assert "No semantic error against the FMI-2 standard." in output, output


def test_untrained_corrector_passes_physics_through(gp_fmu):
    slave = open_corrector(gp_fmu)
    try:
        record = physics_record(1, 20)
        for k, sample in enumerate(record):
            set_sample(slave, gp_fmu, sample)
            out = read_outputs(slave, gp_fmu)
            assert np.array_equal(out[0], sample[:3]), f"step {k}: corrected {out[0]} vs physics {sample[:3]}"
            np.testing.assert_allclose(out[1], 1e-2, rtol=1e-14)
            np.testing.assert_allclose(out[2], np.sqrt(1e-2 + 1e-4), rtol=1e-14)
            slave.doStep(k * STEP, STEP)
        assert training_points(slave, gp_fmu) == 0
    finally:
        close(slave)


def test_learning_through_fmpy_lowers_the_latent_variance_and_fmu_states_keep_the_points(gp_fmu):
    # Without lags the input vector is the current sample alone: the same before and after a step.
    slave = open_corrector(gp_fmu, integers={"lags": 0, "refit_every": 0})
    try:
        sample = np.array([0.05, -0.02, 0.08, 0.3])
        truth = measured_of(sample[None, :])[0]
        set_sample(slave, gp_fmu, sample, truth, learn=True)
        before = read_outputs(slave, gp_fmu)
        slave.doStep(0.0, STEP)
        after = read_outputs(slave, gp_fmu)
        assert training_points(slave, gp_fmu) == 1
        assert np.all(after[1] < 0.05 * before[1]), f"latent variance {before[1]} → {after[1]}"
        np.testing.assert_allclose(after[0] - sample[:3], truth - sample[:3], rtol=0.02)

        state = slave.getFMUstate()
        serialized = slave.serializeFMUstate(state)
        record = physics_record(2, 6)
        for k, other in enumerate(record, start=1):
            set_sample(slave, gp_fmu, other, measured_of(other[None, :])[0], learn=True)
            slave.doStep(k * STEP, STEP)
        assert training_points(slave, gp_fmu) == 7
        continued = read_outputs(slave, gp_fmu)

        slave.setFMUstate(state)
        assert training_points(slave, gp_fmu) == 1
        set_sample(slave, gp_fmu, sample)
        assert np.array_equal(read_outputs(slave, gp_fmu), after)
        slave.freeFMUstate(state)
    finally:
        close(slave)

    # The serialized state, in a fresh instance, holds the learned point and continues alike.
    fresh = open_corrector(gp_fmu, integers={"lags": 0, "refit_every": 0}, name="fresh")
    try:
        assert training_points(fresh, gp_fmu) == 0
        restored = fresh.deSerializeFMUstate(serialized)
        fresh.setFMUstate(restored)
        assert training_points(fresh, gp_fmu) == 1
        for k, other in enumerate(record, start=1):
            set_sample(fresh, gp_fmu, other, measured_of(other[None, :])[0], learn=True)
            fresh.doStep(k * STEP, STEP)
        np.testing.assert_allclose(read_outputs(fresh, gp_fmu), continued, rtol=1e-9, atol=1e-15)
        fresh.freeFMUstate(restored)
    finally:
        close(fresh)


def test_a_bad_training_path_is_refused_naming_the_file(gp_fmu, tmp_path, capfd):
    bad = tmp_path / "broken.json"
    bad.write_text('{"lags": 9, "target": "discrepancy", "inputs": [[1.0]], "targets": [[0, 0, 0]]}')
    slave = FMU2Slave(
        guid=gp_fmu.model_description.guid,
        unzipDirectory=str(gp_fmu.unzip_dir),
        modelIdentifier=gp_fmu.model_identifier,
        instanceName="bad",
    )
    slave.instantiate()
    try:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setString([gp_fmu.vr("training_path")], [str(bad)])
        with pytest.raises(FMICallException):
            slave.exitInitializationMode()
        logged = capfd.readouterr().out
        assert str(bad) in logged and "inputs[0] has 1 values, expected 40" in logged, logged
        # Refused, not failed: with the path cleared the instance initializes.
        slave.setString([gp_fmu.vr("training_path")], [""])
        slave.exitInitializationMode()
        slave.doStep(0.0, STEP)
    finally:
        close(slave)


def test_bundled_training_file_predicts_as_an_independent_gp(gp_fmu_path, tmp_path):
    lags = 2
    training = training_set(lags, 40, seed=5)
    trained = ShearFmu.open(
        with_training_file(gp_fmu_path, training, tmp_path / "trained.fmu"), tmp_path / "trained"
    )
    assert validate_fmu(str(trained.path)) == []
    slave = open_corrector(trained, integers={"lags": lags})
    try:
        assert training_points(slave, trained) == 40
        record = physics_record(6, 25)
        rows = []
        for k, sample in enumerate(record):
            set_sample(slave, trained, sample)
            rows.append(read_outputs(slave, trained))
            slave.doStep(k * STEP, STEP)
    finally:
        close(slave)
    rows = np.array(rows)

    x_train = np.array(training["inputs"])
    x_test = lag_vectors(record, lags)
    for f in range(3):
        y = np.array(training["targets"])[:, f]
        hyper = training["hyperparameters"][f]
        mean, latent = gp_predict(x_train, y, hyper, x_test)
        np.testing.assert_allclose(rows[:, 0, f], record[:, f] + mean, rtol=0, atol=1e-9 * np.max(np.abs(mean)))
        np.testing.assert_allclose(rows[:, 1, f], latent, rtol=0, atol=1e-9 * hyper["signal_variance"])
        np.testing.assert_allclose(rows[:, 2, f], np.sqrt(latent + hyper["noise_variance"]), rtol=1e-8)
    # The correction is there: the discrepancy it learned is of the order of 0.02 m/s².
    assert np.max(np.abs(rows[:, 0, :] - record[:, :3])) > 1e-3


# ------------------------------------------------------------------------------------------------
# The corrector behind the shear FMU in fmu-manipulation-toolbox's FMU Container


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__(level=logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record):
        self.records.append(record)


SHEAR_UNUSED = tuple(f"{q}{i}" for q in ("disp", "vel", "drift") for i in FLOORS) + tuple(
    f"d_acc{i}_d_{p}{j}" for i in FLOORS for p in "mck" for j in FLOORS
)
CONTAINER_OUTPUTS = (
    tuple(f"shear_{n}" for n in ACCELERATIONS) + tuple(f"gp_{n}" for n in OUTPUTS) + ("gp_training_points",)
)


def _container_description(name: str, sequential: bool) -> dict:
    """shear.fmu's accelerations feed the corrector's physics inputs; the container input `force`
    fans out to both FMUs; the corrector's measured accelerations and learn flag are container
    inputs (at their start values, 0 and false, unless the run sets them)."""
    return {
        "name": name,
        "step_size": STEP,
        "sequential": sequential,
        "auto_link": False,
        "auto_input": False,
        "auto_output": False,
        "fmu": ["shear.fmu", "corrector.fmu"],
        "input": [
            ["force", "shear.fmu", "force"],
            ["force", "corrector.fmu", "force"],
            ["control_force", "shear.fmu", "control_force"],
            *[[m, "corrector.fmu", m] for m in MEASURED],
            ["learn", "corrector.fmu", "learn"],
        ],
        "link": [["shear.fmu", a, "corrector.fmu", p] for a, p in zip(ACCELERATIONS, PHYSICS)],
        "output": [["shear.fmu", a, f"shear_{a}"] for a in ACCELERATIONS]
        + [["corrector.fmu", n, f"gp_{n}"] for n in OUTPUTS + ("training_points",)],
        "drop": [["shear.fmu", n] for n in SHEAR_UNUSED],
    }


def _build_containers(directory: Path, corrector_fmu: Path, shear_fmu: Path, tag: str) -> dict:
    shutil.copy(shear_fmu, directory / "shear.fmu")
    shutil.copy(corrector_fmu, directory / "corrector.fmu")
    built = {}
    for schedule, sequential in (("parallel", False), ("sequential", True)):
        name = f"{tag}_{schedule}"
        (directory / f"{name}.json").write_text(json.dumps(_container_description(f"{name}.fmu", sequential)))
        collector = _Collect()
        logger = logging.getLogger(TOOLBOX_LOGGER)
        logger.addHandler(collector)
        try:
            Assembly(f"{name}.json", fmu_directory=directory).make_fmu()
        finally:
            logger.removeHandler(collector)
        built[schedule] = (directory / f"{name}.fmu", [f"{r.levelname}: {r.getMessage()}" for r in collector.records])
    return built


def _run_container(path: Path, force: np.ndarray, measured=None, learn=None) -> np.ndarray:
    """fmpy.simulate_fmu on a container: the signals of t_k are applied before the step from t_k."""
    columns = [(c, np.float64) for c in ("time", "force", "control_force") + MEASURED] + [("learn", np.bool_)]
    signal = np.zeros(len(force), dtype=columns)
    signal["time"] = np.arange(len(force)) * STEP
    signal["force"] = force
    if measured is not None:
        for f, name in enumerate(MEASURED):
            signal[name] = measured[:, f]
    if learn is not None:
        signal["learn"] = learn
    result = fmpy.simulate_fmu(
        str(path), input=signal, output=list(CONTAINER_OUTPUTS), output_interval=STEP, stop_time=signal["time"][-1]
    )
    return np.stack([result[n] for n in CONTAINER_OUTPUTS], axis=1)


def _emulate(
    shear_fmu: ShearFmu, corrector: ShearFmu, force: np.ndarray, sequential: bool, measured=None, learn=None
) -> np.ndarray:
    """The container's schedule replayed on FMU2Slave instances of the same binaries; columns as
    CONTAINER_OUTPUTS."""
    measured = np.zeros((len(force), 3)) if measured is None else measured
    learn = np.zeros(len(force), dtype=bool) if learn is None else learn
    measured_vrs = [corrector.vr(n) for n in MEASURED]
    learn_vr = [corrector.vr("learn")]
    points_vr = [corrector.vr("training_points")]

    def corrector_outputs():
        return gp.getReal(outputs) + [float(gp.getInteger(points_vr)[0])]

    def corrector_inputs(k: int):
        gp.setReal(physics + corrector_force + measured_vrs, link + [float(force[k])] + list(measured[k]))
        gp.setBoolean(learn_vr, [bool(learn[k])])

    acc = [shear_fmu.vr(n) for n in ACCELERATIONS]
    physics = [corrector.vr(n) for n in PHYSICS]
    force_vr = [shear_fmu.vr("force")]
    corrector_force = [corrector.vr("force")]
    outputs = [corrector.vr(n) for n in OUTPUTS]
    shear = instantiate(shear_fmu, {}, force[0], "shear")
    link = shear.getReal(acc)
    gp = FMU2Slave(
        guid=corrector.model_description.guid,
        unzipDirectory=str(corrector.unzip_dir),
        modelIdentifier=corrector.model_identifier,
        instanceName="corrector",
    )
    gp.instantiate()
    gp.setupExperiment(startTime=0.0)
    gp.enterInitializationMode()
    corrector_inputs(0)
    gp.exitInitializationMode()
    rows = [link + corrector_outputs()]
    try:
        for k in range(len(force) - 1):
            if sequential:
                shear.setReal(force_vr, [force[k]])
                shear.doStep(k * STEP, STEP)
                link = shear.getReal(acc)
                corrector_inputs(k)
                gp.doStep(k * STEP, STEP)
            else:
                shear.setReal(force_vr, [force[k]])
                corrector_inputs(k)
                shear.doStep(k * STEP, STEP)
                gp.doStep(k * STEP, STEP)
                link = shear.getReal(acc)
            rows.append(link + corrector_outputs())
    finally:
        for slave in (shear, gp):
            close(slave)
    return np.array(rows)


@pytest.fixture(scope="module")
def container_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("gp_container")


@pytest.fixture(scope="module")
def untrained_containers(container_dir, gp_fmu_path, fmu_path):
    directory = container_dir / "untrained"
    directory.mkdir()
    return _build_containers(directory, gp_fmu_path, fmu_path, "untrained")


@pytest.fixture(scope="module")
def trained(container_dir, gp_fmu_path, fmu_path):
    """A corrector with a bundled training set of 9 lags, its containers and its unpacked copy."""
    directory = container_dir / "trained"
    directory.mkdir()
    corrector = with_training_file(gp_fmu_path, training_set(9, 60, seed=9), directory / "corrector_trained.fmu")
    containers = _build_containers(directory, corrector, fmu_path, "trained")
    return containers, ShearFmu.open(corrector, directory / "unpacked")


@pytest.mark.parametrize("schedule", ["parallel", "sequential"])
def test_containers_build_without_complaint(untrained_containers, trained, schedule):
    for built in (untrained_containers, trained[0]):
        path, complaints = built[schedule]
        assert path.is_file()
        assert complaints == [], "\n".join(complaints)


def test_untrained_corrector_in_a_container_passes_the_shear_accelerations_through(untrained_containers, record):
    force = record.force[:300]
    for schedule in ("sequential", "parallel"):
        rows = _run_container(untrained_containers[schedule][0], force)
        shear, corrected = rows[:, 0:3], rows[:, 3:6]
        assert np.max(np.abs(shear)) > 0.05, "the structure moves"
        if schedule == "sequential":
            # The corrector steps after the shear FMU and reads its accelerations of the same point.
            assert np.array_equal(corrected, shear), f"largest difference {np.max(np.abs(corrected - shear))}"
        else:
            # Links are read at the end of the previous step: the corrector is one sample behind.
            assert np.array_equal(corrected[1:], shear[:-1]), f"largest difference {np.max(np.abs(corrected[1:] - shear[:-1]))}"
        np.testing.assert_allclose(rows[:, 6:9], 1e-2, rtol=1e-14)


@pytest.mark.parametrize("schedule", ["parallel", "sequential"])
def test_trained_corrector_in_a_container_matches_the_schedule_replayed_with_fmpy(trained, shear_fmu, record, schedule):
    containers, corrector = trained
    force = record.force[:300]
    rows = _run_container(containers[schedule][0], force)
    expected = _emulate(shear_fmu, corrector, force, schedule == "sequential")
    # Same binaries, same calls in the same order, a step exact in binary: equal but for the last
    # bits of the step size the container computes.
    assert_within(rows, expected, 1e-12, f"{schedule} container against its replay")
    correction = rows[:, 3:6] - (rows[:, 0:3] if schedule == "sequential" else np.vstack([rows[:1, 0:3], rows[:-1, 0:3]]))
    assert np.max(np.abs(correction[1:])) > 1e-3, "the bundled training set corrects the physics"


def test_corrector_learning_in_a_container_matches_the_schedule_replayed_with_fmpy(
    untrained_containers, gp_fmu, shear_fmu, record
):
    """dataset1's accelerations as the measurements, learn at every 8th of the first 240 samples:
    30 points, so the default schedule refits the hyperparameters once (after 25), inside the
    container."""
    data = np.genfromtxt(REPO_ROOT / "data" / "dataset1.csv", delimiter=",", names=True)
    n = 300
    force = record.force[:n]
    measured = np.stack([data[name][:n] for name in ACCELERATIONS], axis=1)
    learn = (np.arange(n) % 8 == 0) & (np.arange(n) < 240)
    rows = _run_container(untrained_containers["sequential"][0], force, measured, learn)
    expected = _emulate(shear_fmu, gp_fmu, force, True, measured, learn)
    assert rows[-1, -1] == 30 and expected[-1, -1] == 30, "training points at the end"
    assert_within(rows, expected, 1e-12, "learning container against its replay")
    # Where it learned, the corrector's latent variance fell far below the prior's 1e-2.
    assert np.max(rows[-1, 6:9]) < 1e-2
