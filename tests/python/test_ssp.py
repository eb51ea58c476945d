"""The twin archive (`twin init`, SSP 1.0) in fmpy's SSP support: the archive validates against
the SSP schemas, and fmpy's `simulate_ssp` of a twin with non-default parameters agrees with
`twin compare --predictions` of the same archive.

How fmpy 0.3.32's `simulate_ssp` (fmpy/ssp/simulation.py) runs a system, and what that means here:

- it reads the ParameterBindings (`read_ssd` loads each bound .ssv) but never applies them: only
  the `parameter_set` argument is set, by names prefixed with the component's path
  ("physics.k2"), before initialization;
- at each time t (a running sum from start_time), it sets the system inputs from `input[name](t)`,
  then steps every component with the values its input connectors hold, then copies connections,
  and records the row at t: the component's input connector gets the system input only after the
  step, so the step from t_k sees input(t_{k-1}) (0 for the first step), and the outputs recorded
  at t_k are those read after the step, i.e. at t_{k+1};
- inputs are set as values, never with derivatives: the force is held over each step.

The orchestrator ramps the force between samples (first-order hold) and reads the outputs at t_k
with F_k applied. A ramp and a hold agree only where consecutive samples are equal, so the data
file here has a constant force F: the orchestrator's input is F on every step, from t_0. fmpy is
started one step early, at −h: its first step [−h, 0] sees the connector's initial 0 and leaves
the structure at rest, and from t_0 on each step sees input(t_{k−1}) = F. Then fmpy's row at
t_{k−1} is the orchestrator's row k, for k ≥ 1, with the same FMU, the same parameters and the
same arithmetic. A constant force is the step response: every mode of the frame is excited.
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd
from fmpy.ssp.simulation import simulate_ssp
from conftest import run_twin_ok

#: 1/51.2 s = 5/256 s: exact in binary, so the running sum fmpy keeps is exact too.
STEP = 1.0 / 51.2
SAMPLES = 1024
FORCE = 2.0
ACCELERATIONS = ("acc1", "acc2", "acc3")
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
#: The physics parameters of the non-default twin: a stiffer second storey, a damper ten times
#: the prior on the third, and another sub-step count (an Integer through both tools).
PHYSICS = {"k2": ("Real", "5200.0"), "c3": ("Real", "0.1"), "substeps": ("Integer", "16")}


pytestmark = pytest.mark.usefixtures("twin_fmus")


def physics_ssv(parameters: dict) -> bytes:
    ET.register_namespace("ssv", SSV_NS)
    root = ET.Element(f"{{{SSV_NS}}}ParameterSet", {"version": "1.0", "name": "physics"})
    container = ET.SubElement(root, f"{{{SSV_NS}}}Parameters")
    for name, (kind, value) in parameters.items():
        parameter = ET.SubElement(container, f"{{{SSV_NS}}}Parameter", {"name": name})
        ET.SubElement(parameter, f"{{{SSV_NS}}}{kind}", {"value": value})
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


@pytest.fixture(scope="module")
def archives(twin_binary, tmp_path_factory) -> dict:
    """The default twin from `twin init`, and a copy whose resources/physics.ssv sets PHYSICS."""
    directory = tmp_path_factory.mktemp("ssp")
    default = directory / "default.ssp"
    run_twin_ok(twin_binary, "init", "--out", str(default))
    changed = directory / "stiff.ssp"
    with zipfile.ZipFile(default) as source, zipfile.ZipFile(changed, "w", zipfile.ZIP_DEFLATED) as target:
        names = source.namelist()
        assert "resources/physics.ssv" in names, names
        for name in names:
            data = physics_ssv(PHYSICS) if name == "resources/physics.ssv" else source.read(name)
            target.writestr(name, data)
    return {"default": default, "stiff": changed}


@pytest.fixture(scope="module")
def step_data(tmp_path_factory) -> Path:
    """A measurement file with the constant force FORCE; its accelerations only feed the NMSE."""
    path = tmp_path_factory.mktemp("data") / "constant_force.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time", "force", "acc1", "acc2", "acc3"])
        for k in range(SAMPLES):
            writer.writerow([repr(k * STEP), repr(FORCE), repr(math.sin(0.1 * k)), repr(math.cos(0.07 * k)), repr(math.sin(0.05 * k))])
    return path


def orchestrator_predictions(twin_binary, data: Path, archive: Path | None, out: Path) -> np.ndarray:
    args = ["compare", "--data", str(data), "--predictions", str(out)]
    if archive is not None:
        args += ["--twin", str(archive)]
    run_twin_ok(twin_binary, *args)
    table = np.genfromtxt(out, delimiter=",", names=True)
    assert table.dtype.names == ("time", *ACCELERATIONS)
    assert len(table) == SAMPLES
    return table


def prefixed_parameter_set(archive: Path) -> ParameterSet:
    """The archive's physics parameters as fmpy's `simulate_ssp` wants them: read by fmpy from the
    ParameterBinding, renamed "physics.<name>"."""
    ssd = read_ssd(str(archive))
    (physics,) = [e for e in ssd.system.elements if e.name == "physics"]
    (binding,) = physics.parameterBindings
    assert binding.source == "resources/physics.ssv"
    (values,) = binding.parameterValues
    parameters = [Parameter(name=f"physics.{p.name}", type=p.type, value=p.value) for p in values.parameters]
    return ParameterSet(name="physics", parameters=parameters)


def fmpy_run(archive: Path, parameter_set: ParameterSet | None) -> np.ndarray:
    # Rows at −h, t_0, …, t_1022: stop just past t_1022.
    return simulate_ssp(
        str(archive),
        start_time=-STEP,
        stop_time=(SAMPLES - 2) * STEP + STEP / 2,
        step_size=STEP,
        parameter_set=parameter_set,
        input={"force": lambda t: FORCE},
    )


def max_relative_deviation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_the_twin_archives_validate_against_the_ssp_schemas(archives):
    for name, archive in archives.items():
        ssd = read_ssd(str(archive), validate=True)  # raises on a schema violation
        assert ssd.version == "1.0"
        components = [e.name for e in ssd.system.elements]
        assert components == ["physics"], f"{name}: {components}"
    parameters = prefixed_parameter_set(archives["stiff"]).parameters
    assert {p.name: (p.type, p.value) for p in parameters} == {f"physics.{n}": v for n, v in PHYSICS.items()}
    assert prefixed_parameter_set(archives["default"]).parameters == []


def test_fmpy_simulate_ssp_agrees_with_twin_compare(twin_binary, archives, step_data, tmp_path):
    ours = orchestrator_predictions(twin_binary, step_data, archives["stiff"], tmp_path / "stiff.csv")
    theirs = fmpy_run(archives["stiff"], prefixed_parameter_set(archives["stiff"]))

    assert len(theirs) == SAMPLES
    # fmpy labels each row with the time before its step.
    np.testing.assert_array_equal(theirs["time"], (np.arange(SAMPLES) - 1) * STEP)
    np.testing.assert_array_equal(theirs["force"], FORCE)
    # Its first row is the structure at rest after the step [−h, 0] with the force still 0.
    assert all(theirs[name][0] == 0.0 for name in ACCELERATIONS)
    # The orchestrator's row 0 has F applied to floor 1 at rest: F/m1 there, nothing above.
    assert ours["acc1"][0] == pytest.approx(FORCE / 5.2, rel=1e-15)
    assert ours["acc2"][0] == 0.0 and ours["acc3"][0] == 0.0

    # Row j ≥ 1 of fmpy is row j of the orchestrator: the same FMU, parameters and arithmetic.
    # Bound: the product's quality bar, 1e-9 of each floor's peak. Measured: bit-identical.
    for name in ACCELERATIONS:
        deviation = max_relative_deviation(theirs[name][1:], ours[name][1:])
        print(f"{name}: fmpy simulate_ssp against twin compare, max |Δ| / peak = {deviation:.3e}")
        assert deviation <= 1e-9, f"{name}: fmpy's SSP run deviates by {deviation:.3e} of the peak"


def test_fmpy_does_not_apply_the_parameter_bindings_itself(twin_binary, archives, step_data, tmp_path):
    """Without `parameter_set` fmpy runs the stiff archive at the FMU's start values: it equals the
    default twin, and is far from the stiff twin. So the agreement above rests on the parameters
    reaching both tools, and the k2/c3 change is large enough to tell."""
    default = orchestrator_predictions(twin_binary, step_data, None, tmp_path / "default.csv")
    stiff = orchestrator_predictions(twin_binary, step_data, archives["stiff"], tmp_path / "stiff.csv")
    unbound = fmpy_run(archives["stiff"], parameter_set=None)
    for name in ACCELERATIONS:
        assert max_relative_deviation(unbound[name][1:], default[name][1:]) <= 1e-9, name
        # Measured: 1.78, 1.84, 1.76 of the peak (floors 1..3).
        apart = max_relative_deviation(stiff[name][1:], default[name][1:])
        print(f"{name}: stiff twin against the default twin, max |Δ| / peak = {apart:.3f}")
        assert apart > 0.1, f"{name}: the parameter change moved the response by only {apart:.3e} of the peak"
