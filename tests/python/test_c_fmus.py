"""The hand-written C FMUs of tests/c-fmus/ under fmpy, and scripts/fmpy_run.py, the fmpy reference
that `twin run` is compared with.

The FMUs are `target/c-fmus/<Name>.fmu` (or under $CARGO_TARGET_DIR), built by scripts/make-c-fmus.sh.
Each must pass fmpy's validation, simulate under `fmpy.simulate_fmu` with physically right results,
and behave at the C interface as tests/c-fmus/README.md says (GUID check, refused calls, FMU states,
the resource URI).
"""

from __future__ import annotations

import csv
import ctypes
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fmpy
import fmpy.fmi1
import fmpy.fmi2 as fmi2
from fmpy.fmi1 import FMICallException
from fmpy.logging import addLoggerProxy
from fmpy.validation import validate_fmu

from conftest import REPO_ROOT

NAMES = ["BouncingBall", "Discrete", "Table", "Stopper", "NoInterp", "Interp"]
C_FMUS = REPO_ROOT / "tests" / "c-fmus"
INPUTS = C_FMUS / "inputs"
FMPY_RUN = REPO_ROOT / "scripts" / "fmpy_run.py"


def fmu_file(name: str) -> Path:
    path = REPO_ROOT / os.environ.get("CARGO_TARGET_DIR", "target") / "c-fmus" / f"{name}.fmu"
    if not path.is_file():
        pytest.fail(f"the C test FMU {path} does not exist: run scripts/make-c-fmus.sh", pytrace=False)
    return path


def read_csv_input(path: Path, dtypes: dict) -> np.ndarray:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    names = rows[0]
    dtype = [(n, dtypes.get(n, np.float64)) for n in names]
    return np.array([tuple(float(x) if dtypes.get(n, np.float64) == np.float64 else int(x)
                           for n, x in zip(names, row)) for row in rows[1:]], dtype=dtype)


# fmpy formats an FMU's variadic log message in a native proxy that forwards to one
# process-wide logger: the last callbacks handed to `addLoggerProxy`. fmpy registers its own
# default callbacks when imported; registering per Slave would leave the proxy pointing at a
# freed callback once the Slave is gone, and every later FMU's messages would go there. So one
# module-level set of callbacks is registered once: its logger prints as fmpy's default does and
# also hands the message to the Slave being driven, if any.
_current: list = []


def _forward(env, instance, status, category, message):
    fmpy.fmi1.printLogMessage(env, instance, status, category, message)
    if _current:
        _current[-1]._log(env, instance, status, category, message)


_CALLBACKS = fmi2.fmi2CallbackFunctions()
_CALLBACKS.logger = fmi2.fmi2CallbackLoggerTYPE(_forward)
_CALLBACKS.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
_CALLBACKS.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
addLoggerProxy(ctypes.byref(_CALLBACKS))


class Slave:
    """One instance of an FMU driven through fmpy's FMU2Slave, its log messages collected."""

    def __init__(self, fmu: Path, tmp_path: Path, guid: str | None = None, resource_uri: str | None = None,
                 instantiate: bool = True):
        self.md = fmpy.read_model_description(fmu)
        self.unzipdir = fmpy.extract(fmu, unzipdir=tmp_path / "unzipped")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[tuple[int, str, str]] = []
        self.fmu = fmi2.FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                                  modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="test")
        self.callbacks = _CALLBACKS
        _current.append(self)
        if instantiate:
            self.component = self.raw_instantiate(guid or self.md.guid, resource_uri)
            assert self.component, self.messages
            self.fmu.component = self.component

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def raw_instantiate(self, guid: str, resource_uri: str | None = None):
        uri = resource_uri if resource_uri is not None else Path(self.unzipdir, "resources").as_uri()
        return self.fmu.fmi2Instantiate(b"test", fmi2.fmi2CoSimulation, guid.encode(), uri.encode(),
                                        ctypes.byref(self.callbacks), fmi2.fmi2False, fmi2.fmi2False)

    def start(self, start_time=0.0, **start_values):
        self.fmu.setupExperiment(startTime=start_time)
        self.fmu.enterInitializationMode()
        for name, value in start_values.items():
            self.set(name, value)
        self.fmu.exitInitializationMode()

    def set(self, name, value):
        v = next(v for v in self.md.modelVariables if v.name == name)
        {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger, "Enumeration": self.fmu.setInteger,
         "Boolean": self.fmu.setBoolean}.get(v.type, self.fmu.setString)(
            [v.valueReference], [value])

    def get(self, name):
        v = next(v for v in self.md.modelVariables if v.name == name)
        if v.type == "String":
            return self.fmu.getString([v.valueReference])[0].decode()
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Enumeration": self.fmu.getInteger,
                  "Boolean": self.fmu.getBoolean}[v.type]
        return getter([v.valueReference])[0]

    def status_of(self, call, *args):
        """The fmi2Status a call returned (fmpy raises for anything but OK/warning)."""
        try:
            call(*args)
            return fmi2.fmi2OK
        except FMICallException as e:
            return e.status

    def errors(self):
        return [m for s, _, m in self.messages if s >= fmi2.fmi2Error]

    def close(self):
        if self in _current:
            _current.remove(self)
        if getattr(self.fmu, "component", None):
            self.fmu.freeInstance()
        else:
            self.fmu.freeLibrary()


@pytest.fixture
def slave(tmp_path):
    opened = []

    def open_(name, **kwargs):
        s = Slave(fmu_file(name), tmp_path / f"{name}{len(opened)}", **kwargs)
        opened.append(s)
        return s

    yield open_
    for s in opened:
        s.close()


def run_reference(tmp_path: Path, name: str, *args: str) -> tuple[list[str], list[list[str]]]:
    out = tmp_path / f"{name}.csv"
    subprocess.run([sys.executable, str(FMPY_RUN), str(fmu_file(name)), "--output", str(out), *args], check=True)
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


# ---- every FMU ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_fmpy_finds_no_problem(name):
    assert validate_fmu(str(fmu_file(name))) == []
    md = fmpy.read_model_description(fmu_file(name))
    assert md.modelExchange is None and md.coSimulation.modelIdentifier == name
    assert md.coSimulation.canGetAndSetFMUstate


@pytest.mark.parametrize("name", NAMES)
def test_exports_every_fmi2_function(name, tmp_path):
    header = (Path(fmpy.__file__).parent / "c-code" / "fmi2Functions.h").read_text()
    functions = re.findall(r"FMI2_Export\s+fmi2\w+TYPE\s+(fmi2\w+);", header)
    assert len(functions) == 44
    unzipdir = fmpy.extract(fmu_file(name), unzipdir=tmp_path / "x")
    library = ctypes.CDLL(str(Path(unzipdir, "binaries", "linux64", f"{name}.so")))
    assert [f for f in functions if not hasattr(library, f)] == []


@pytest.mark.parametrize("name", NAMES)
def test_a_wrong_guid_is_refused_and_logged(name, slave):
    s = slave(name, instantiate=False)
    assert not s.raw_instantiate("{00000000-0000-0000-0000-000000000000}")
    assert any("{00000000-0000-0000-0000-000000000000}" in m and s.md.guid in m for m in s.errors()), s.messages


@pytest.mark.parametrize("name", NAMES)
def test_refused_calls_return_an_error_and_change_nothing(name, slave):
    s = slave(name)
    fmu = s.fmu
    assert s.status_of(fmu.doStep, 0.0, 0.1) == fmi2.fmi2Error  # before initialization
    s.start()
    assert s.status_of(fmu.getReal, [9999]) == fmi2.fmi2Error
    output = next(v for v in s.md.modelVariables if v.causality == "output")
    set_output = {"Real": fmu.setReal, "Integer": fmu.setInteger, "Enumeration": fmu.setInteger,
                  "Boolean": fmu.setBoolean}[output.type]
    assert s.status_of(set_output, [output.valueReference], [1]) == fmi2.fmi2Error
    assert s.status_of(fmu.doStep, 5.0, 0.1) == fmi2.fmi2Error  # not the FMU's time
    assert s.status_of(fmu.doStep, 0.0, -0.1) == fmi2.fmi2Error
    assert s.status_of(fmu.fmi2GetReal, None, None, 1, None) == fmi2.fmi2Error
    assert s.status_of(fmu.fmi2DoStep, None, 0.0, 0.1, fmi2.fmi2True) == fmi2.fmi2Error
    assert s.status_of(fmu.fmi2GetReal, s.component, None, 1, None) == fmi2.fmi2Error
    enter_event_mode = fmu.dll.fmi2EnterEventMode  # Model Exchange: exported, refused
    enter_event_mode.restype, enter_event_mode.argtypes = ctypes.c_int, [ctypes.c_void_p]
    assert enter_event_mode(s.component) == fmi2.fmi2Error
    assert len(s.errors()) >= 6
    fmu.doStep(0.0, 0.1)  # still in step mode, at time 0


@pytest.mark.parametrize("name", NAMES)
def test_an_fmu_state_restores_and_serializes(name, slave):
    s = slave(name)
    s.start()
    outputs = [v.name for v in s.md.modelVariables if v.causality == "output"]
    h = 0.05
    t = 0.0
    for _ in range(4):
        s.fmu.doStep(t, h)
        t += h
    state = s.fmu.getFMUstate()
    serialized = s.fmu.serializeFMUstate(state)
    later = []
    for _ in range(4):
        s.fmu.doStep(t + h * len(later), h)
        later.append([s.get(n) for n in outputs])
    for restored in (state, s.fmu.deSerializeFMUstate(serialized)):
        s.fmu.setFMUstate(restored)
        again = []
        for k in range(4):
            s.fmu.doStep(t + h * k, h)
            again.append([s.get(n) for n in outputs])
        assert again == later
        s.fmu.freeFMUstate(restored)


@pytest.mark.parametrize("name", NAMES)
def test_reset_gives_the_same_run(name, slave):
    s = slave(name)
    outputs = [v.name for v in s.md.modelVariables if v.causality == "output"]
    runs = []
    for _ in range(2):
        s.start()
        values = []
        for k in range(5):
            s.fmu.doStep(0.05 * k, 0.05)
            values.append([s.get(n) for n in outputs])
        s.fmu.terminate()
        s.fmu.reset()
        runs.append(values)
    assert runs[0] == runs[1]


# ---- BouncingBall -----------------------------------------------------------------------------------

def bouncing_ball_exact(times, h0=1.0, g=9.81, e=0.7, v_rest=0.1):
    """The analytic trajectory: (h, v, bounces) at each time."""
    impacts, v_after = [], []
    t_hit = math.sqrt(2 * h0 / g)
    v = math.sqrt(2 * g * h0)
    while True:
        impacts.append(t_hit)
        v *= e
        if v < v_rest:
            v_after.append(0.0)
            break
        v_after.append(v)
        t_hit += 2 * v / g
    result = []
    for t in times:
        k = sum(1 for ti in impacts if ti <= t)
        if k == 0:
            result.append((h0 - g * t * t / 2, -g * t, 0))
        elif k == len(impacts):
            result.append((0.0, 0.0, k))
        else:
            tau = t - impacts[k - 1]
            result.append((v_after[k - 1] * tau - g * tau * tau / 2, v_after[k - 1] - g * tau, k))
    return impacts, np.array(result)


def test_bouncing_ball_bounces_as_the_exact_solution(tmp_path):
    r = fmpy.simulate_fmu(fmu_file("BouncingBall"))
    assert r["time"][-1] == pytest.approx(3.0) and len(r) == 301
    impacts, exact = bouncing_ball_exact(r["time"])
    assert len(impacts) == 11 and r["bounces"][-1] == 11
    assert np.all(np.diff(r["bounces"]) >= 0) and np.all(r["h"] >= 0)
    # rows within 1e-6 s of an impact are left out: there the count depends on rounding
    away = np.array([min(abs(t - ti) for ti in impacts) > 1e-6 for t in r["time"]])
    np.testing.assert_array_equal(r["bounces"][away], exact[away, 2])
    np.testing.assert_allclose(r["h"][away], exact[away, 0], atol=1e-9)
    np.testing.assert_allclose(r["v"][away], exact[away, 1], atol=1e-9)
    assert r["h"][-1] == 0 and r["v"][-1] == 0  # at rest


def test_bouncing_ball_takes_any_communication_step():
    fine = fmpy.simulate_fmu(fmu_file("BouncingBall"), output_interval=0.01)
    coarse = fmpy.simulate_fmu(fmu_file("BouncingBall"), output_interval=0.25)
    for row in coarse:
        k = int(round(row["time"] / 0.01))
        assert row["bounces"] == fine["bounces"][k]
        assert row["h"] == pytest.approx(fine["h"][k], abs=1e-9)


def test_bouncing_ball_parameters():
    r = fmpy.simulate_fmu(fmu_file("BouncingBall"), start_values={"g": 1.62, "e": 0.5, "h": 2.0}, stop_time=5)
    impacts, exact = bouncing_ball_exact(r["time"], h0=2.0, g=1.62, e=0.5)
    away = np.array([min(abs(t - ti) for ti in impacts) > 1e-6 for t in r["time"]])
    np.testing.assert_allclose(r["h"][away], exact[away, 0], atol=1e-9)


def test_bouncing_ball_refuses_a_negative_restitution(slave):
    s = slave("BouncingBall")
    s.fmu.setupExperiment(startTime=0)
    s.fmu.enterInitializationMode()
    s.set("e", -0.5)
    assert s.status_of(s.fmu.exitInitializationMode) == fmi2.fmi2Error
    assert any("restitution" in m for m in s.errors())


# ---- Discrete -----------------------------------------------------------------------------------------

def test_discrete_counts_every_step():
    r = fmpy.simulate_fmu(fmu_file("Discrete"))
    np.testing.assert_array_equal(r["counter"], np.arange(11))
    np.testing.assert_array_equal(r["odd"], np.arange(11) % 2 == 1)
    np.testing.assert_array_equal(r["phase"], [1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3])
    np.testing.assert_array_equal(r["time_seen"], r["time"])


def test_discrete_follows_its_inputs_and_steps_at_their_changes():
    """increment and enable change at 0.3 (a grid point), 0.45 and 0.85 (between grid points,
    where fmpy cuts the step: one more row, and one more count) and 0.7."""
    signals = read_csv_input(INPUTS / "Discrete.csv", {"increment": np.int32, "enable": np.bool_})
    r = fmpy.simulate_fmu(fmu_file("Discrete"), input=signals)
    np.testing.assert_allclose(r["time"], [0, .1, .2, .3, .4, .45, .5, .6, .7, .8, .85, .9, 1], atol=1e-12)
    np.testing.assert_array_equal(r["counter"], [0, 1, 2, 3, 5, 7, 7, 7, 7, 10, 13, 11, 9])
    np.testing.assert_array_equal(r["odd"], r["counter"] % 2 == 1)
    np.testing.assert_array_equal(r["phase"], np.where(r["counter"] < 3, 1, np.where(r["counter"] < 7, 2, 3)))


def test_discrete_label_and_prefix(slave):
    s = slave("Discrete")
    s.fmu.setupExperiment(startTime=0)
    s.set("prefix", "n")
    s.fmu.enterInitializationMode()
    s.fmu.exitInitializationMode()
    assert s.get("label") == "n=0"
    for k in range(7):
        s.fmu.doStep(0.1 * k, 0.1)
    assert s.get("label") == "n=7" and s.get("phase") == 3
    assert s.status_of(s.set, "prefix", "m") == fmi2.fmi2Error  # fixed: not in step mode
    assert s.status_of(s.set, "prefix", "x" * 256) == fmi2.fmi2Error


# ---- Table --------------------------------------------------------------------------------------------

def table_resource():
    data = np.loadtxt(C_FMUS / "Table" / "resources" / "table.csv", delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1]


def test_table_interpolates_its_resource_file():
    t, y = table_resource()
    signals = read_csv_input(INPUTS / "Table.csv", {})
    r = fmpy.simulate_fmu(fmu_file("Table"), input=signals)
    assert len(r) == 41
    np.testing.assert_allclose(r["y"], np.interp(r["time"], t, y), atol=1e-12)
    # fmpy sets the inputs before each step and records after it: u of the previous row
    u_applied = np.interp(np.concatenate([[0.0], r["time"][:-1]]), signals["time"], signals["u"])
    np.testing.assert_allclose(r["y_plus_u"], r["y"] + u_applied, atol=1e-12)


@pytest.mark.parametrize("directory", ["with space", "per%25cent", "hash#sign", "ünï cödé", "a%20b"])
def test_table_finds_its_resources_through_a_percent_encoded_uri(directory, tmp_path):
    unzipdir = tmp_path / directory / "fmu"
    fmpy.extract(fmu_file("Table"), unzipdir=unzipdir)
    t, y = table_resource()
    r = fmpy.simulate_fmu(str(unzipdir))  # fmpy passes Path(...).as_uri(): every such byte %XX
    np.testing.assert_allclose(r["y"], np.interp(r["time"], t, y), atol=1e-12)


def test_table_accepts_every_form_of_file_uri(slave, tmp_path):
    s = slave("Table", instantiate=False)
    resources = Path(s.unzipdir, "resources").resolve()
    moved = tmp_path / "dir #%ü" / "resources"
    shutil.copytree(resources, moved)
    raw = str(moved)
    encoded = moved.as_uri()[len("file://"):]
    lower = re.sub(r"%[0-9A-F]{2}", lambda m: m.group(0).lower(), encoded)
    for uri in [f"file://{encoded}", f"file:{encoded}", f"file://localhost{encoded}", f"FILE://LOCALHOST{lower}/",
                f"file://{encoded}?query#fragment"]:
        component = s.raw_instantiate(s.md.guid, uri)
        assert component, (uri, s.messages)
        s.fmu.fmi2FreeInstance(component)
    assert "#" in raw and "%" in raw


def test_table_reports_the_path_it_could_not_open(slave, tmp_path):
    s = slave("Table", instantiate=False)
    missing = tmp_path / "no such dir %41"
    assert not s.raw_instantiate(s.md.guid, missing.as_uri())
    assert any(str(missing / "table.csv") in m for m in s.errors()), s.messages
    for bad in ["file:///bad%zz", "file://otherhost/x", "http://example.com/resources", "file:relative/path",
                "file:///%00"]:
        assert not s.raw_instantiate(s.md.guid, bad)
    assert len(s.errors()) == 6, s.messages


# ---- Stopper ------------------------------------------------------------------------------------------

def test_stopper_ends_the_simulation_at_stop_at():
    r = fmpy.simulate_fmu(fmu_file("Stopper"))
    assert r["time"][-1] == 0.42 and len(r) == 43  # 0, 0.01, ..., 0.41, then stop_at
    np.testing.assert_allclose(r["x"], r["time"], atol=1e-12)
    r = fmpy.simulate_fmu(fmu_file("Stopper"), start_values={"stop_at": 0.425})
    assert r["time"][-1] == 0.425 and r["x"][-1] == pytest.approx(0.425) and len(r) == 44


def test_stopper_with_an_input():
    signals = read_csv_input(INPUTS / "Stopper.csv", {})
    r = fmpy.simulate_fmu(fmu_file("Stopper"), input=signals)
    assert r["time"][-1] == 0.42
    # u held over each step at its value at the step's start
    starts = r["time"][:-1]
    u = np.array([np.interp(t, signals["time"][2:], signals["u"][2:]) if t >= 0.2 - 1e-12 else 1.0 for t in starts])
    np.testing.assert_allclose(r["x"][1:], np.cumsum(u * np.diff(r["time"])), atol=1e-12)


def test_stopper_at_the_c_interface(slave):
    s = slave("Stopper")
    s.start()
    t = 0.0
    status = fmi2.fmi2OK
    while status == fmi2.fmi2OK:
        status = s.status_of(s.fmu.doStep, t, 0.1)
        t += 0.1
    assert status == fmi2.fmi2Discard
    assert s.fmu.getBooleanStatus(fmi2.fmi2Terminated)
    assert s.fmu.getRealStatus(fmi2.fmi2LastSuccessfulTime) == 0.42
    assert s.get("x") == pytest.approx(0.42)
    assert s.status_of(s.fmu.doStep, 0.42, 0.1) == fmi2.fmi2Error
    s.fmu.terminate()


# ---- NoInterp and Interp ------------------------------------------------------------------------------

def test_no_interp_runs_under_simulate_fmu_defaults():
    r = fmpy.simulate_fmu(fmu_file("NoInterp"))
    assert len(r) == 11 and np.all(r["y"] == 0) and np.all(r["integral"] == 0)
    signals = read_csv_input(INPUTS / "NoInterp.csv", {})
    r = fmpy.simulate_fmu(fmu_file("NoInterp"), input=signals)
    starts = np.concatenate([[0.0], r["time"][:-1]])
    u = np.interp(starts, signals["time"], signals["u"])
    np.testing.assert_allclose(r["y"], 3 * u, atol=1e-12)
    np.testing.assert_allclose(r["integral"][1:], np.cumsum(u[1:] * np.diff(r["time"])), atol=1e-12)
    with pytest.raises(Exception, match="cannot interpolate inputs"):
        fmpy.simulate_fmu(fmu_file("NoInterp"), input=signals, set_input_derivatives=True)


def test_no_interp_refuses_input_derivatives(slave):
    s = slave("NoInterp")
    s.start()
    vr = (fmi2.fmi2ValueReference * 1)(s.vr["u"])
    order = (fmi2.fmi2Integer * 1)(1)
    value = (fmi2.fmi2Real * 1)(2.0)
    assert s.status_of(s.fmu.fmi2SetRealInputDerivatives, s.component, vr, 1, order, value) == fmi2.fmi2Error
    assert "fmi2SetRealInputDerivatives called although canInterpolateInputs is false" in s.errors()


def test_interp_integrates_a_ramp_exactly(fmpy_input_derivatives_fixed):
    """u = 1 + 2t: the table starts before the start time, since fmpy sends a zero derivative at
    its first row (and the slope of the segment on the left at any other row it lands on)."""
    signals = np.array([(-1.0, -1.0), (2.0, 5.0)], dtype=[("time", np.float64), ("u", np.float64)])
    r = fmpy.simulate_fmu(fmu_file("Interp"), input=signals, set_input_derivatives=True)
    np.testing.assert_allclose(r["integral"], r["time"] + r["time"] ** 2, atol=1e-12)
    np.testing.assert_allclose(r["y"], 3 * (1 + 2 * r["time"]), atol=1e-12)
    held = fmpy.simulate_fmu(fmu_file("Interp"), input=signals)  # no derivatives: u held, as NoInterp
    assert held["integral"][-1] == pytest.approx(sum(0.1 * (1 + 2 * 0.1 * k) for k in range(10)))


def test_interp_integrates_a_piecewise_linear_input_exactly(fmpy_input_derivatives_fixed):
    """The corners of tests/c-fmus/inputs/Interp.csv are repeated rows: fmpy ends a step there and
    sends the slope on the right."""
    signals = read_csv_input(INPUTS / "Interp.csv", {})
    r = fmpy.simulate_fmu(fmu_file("Interp"), input=signals, set_input_derivatives=True)

    def exact(t):  # the trapezoid rule is exact between the corners
        points = np.unique(np.concatenate([[0.0, t], signals["time"][(signals["time"] > 0) & (signals["time"] < t)]]))
        values = np.interp(points, signals["time"], signals["u"])
        return float(np.sum(np.diff(points) * (values[1:] + values[:-1]) / 2))

    np.testing.assert_allclose(r["integral"], [exact(t) for t in r["time"]], atol=1e-12)
    assert r["integral"][-1] == pytest.approx(0.1225 + 0.1125 + 0.24, abs=1e-12)


# ---- scripts/fmpy_run.py -----------------------------------------------------------------------------

@pytest.mark.parametrize("name, args", [
    ("BouncingBall", []),
    ("Discrete", ["--input", str(INPUTS / "Discrete.csv"), "--set", "prefix=n"]),
    ("Table", ["--input", str(INPUTS / "Table.csv")]),
    ("Stopper", ["--input", str(INPUTS / "Stopper.csv"), "--set", "stop_at=0.333"]),
    ("NoInterp", ["--input", str(INPUTS / "NoInterp.csv"), "--step", "0.05", "--stop", "0.8"]),
    ("Interp", ["--input", str(INPUTS / "Interp.csv"), "--set-input-derivatives"]),
])
def test_fmpy_run_writes_what_simulate_fmu_returns(name, args, tmp_path):
    header, rows = run_reference(tmp_path, name, *args)
    md = fmpy.read_model_description(fmu_file(name))
    outputs = [v for v in md.modelVariables if v.causality == "output" and v.type != "String"]
    assert header == ["time"] + [v.name for v in outputs]
    signals = None
    if "--input" in args:
        dtypes = {v.name: {"Integer": np.int32, "Boolean": np.bool_}.get(v.type, np.float64)
                  for v in md.modelVariables}
        signals = read_csv_input(Path(args[args.index("--input") + 1]), dtypes)
    starts = {"prefix": "n"} if name == "Discrete" else {"stop_at": 0.333} if name == "Stopper" else {}
    step = 0.05 if name == "NoInterp" else float(md.defaultExperiment.stepSize)
    derivatives = "--set-input-derivatives" in args
    if derivatives:  # the same sizing of fmpy 0.3.32's derivative buffer as fmpy_run.py does
        original = fmpy.simulation.Input.__init__

        def init(self, *a, **k):
            original(self, *a, **k)
            self.continuous = [i._replace(derivatives=(i.derivatives._type_ * len(i.values))())
                               for i in getattr(self, "continuous", [])]
        fmpy.simulation.Input.__init__ = init
    try:
        r = fmpy.simulate_fmu(fmu_file(name), stop_time=0.8 if name == "NoInterp" else None, output_interval=step,
                              step_size=step, input=signals, start_values=starts,
                              output=[v.name for v in outputs], set_input_derivatives=derivatives)
    finally:
        if derivatives:
            fmpy.simulation.Input.__init__ = original
    assert len(rows) == len(r)
    for row, expected in zip(rows, r):
        assert float(row[0]) == expected["time"]
        for cell, v in zip(row[1:], outputs):
            if v.type == "Real":
                assert float(cell) == expected[v.name]  # %.17g reads back bit for bit
            elif v.type == "Boolean":
                assert cell == ("1" if expected[v.name] else "0")
            else:
                assert cell == str(int(expected[v.name]))
    if name == "Stopper":
        assert rows[-1][0] == "0.33300000000000002"


def test_fmpy_run_rejects_an_unknown_input_column(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,nope\n0,1\n")
    done = subprocess.run([sys.executable, str(FMPY_RUN), str(fmu_file("Table")), "--output", str(tmp_path / "o.csv"),
                           "--input", str(bad)], capture_output=True, text=True)
    assert done.returncode != 0 and "'nope' is not an input" in done.stderr
