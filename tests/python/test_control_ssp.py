"""The controlled system (`twin control --ssp`: the shear FMU + the fmu_lqr controller FMU) in
fmpy 0.3.32's `simulate_ssp` and in `twin run`.

Which system each master runs (u_k: the command the controller computes in its step from the
sample at t_k; its output has no feedthrough, the shear's acc1 has one from force − control_force):

- fmpy's `simulate_ssp` steps every component with the values its input connectors got after the
  previous step, then copies every connection: the structure steps over [t_k, t_{k+1}] with
  u_{k−1}; the controller reads the accelerations the structure's last step left, acc(x_k, ·,
  u_{k−2}); the system input reaches both a step late (the first step sees 0), without
  derivatives; the row at t_k holds the values after the step (t_{k+1}'s);
- `twin run --algorithm jacobi` resolves the connections the same way (every component reads the
  outputs as the last step left them) but gives the system input at the point itself. With the
  input file's force 0 at t_0 and F from t_1 on (held: `--hold-inputs`), and fmpy started at t_0
  with a constant F, both run one system: fmpy's row at t_k is `twin run`'s row at t_{k+1}, to
  1e-9 of each output's peak, with the integrating estimator and with the Kalman observer (whose
  prediction uses the force's previous sample, so the same leading zero sample matters);
- `twin run`'s default Gauss–Seidel sets u_{k−1} on the structure before the controller reads
  acc1, which then includes the new command: another system (see orchestrator/tests/control_ssp.rs,
  which also shows the Jacobi run is `twin control`'s own closed loop to 1e-9).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd
from fmpy.ssp.simulation import simulate_ssp
from conftest import run_twin_ok

RECORD_STEP = 1.0 / 51.2
SUBSTEPS = 4
#: 1/204.8 s = 5/1024 s: exact in binary, so fmpy's running sum of times is exact.
STEP = RECORD_STEP / SUBSTEPS
POINTS = 1025
FORCE = 2.0
OUTPUTS = ("physics.acc1", "physics.acc2", "physics.acc3", "lqr.control_force")


pytestmark = pytest.mark.usefixtures("twin_fmus")


@pytest.fixture(scope="module")
def systems(twin_binary, tmp_path_factory) -> dict:
    """Per estimator: the q = 1e3 design's controlled system and the report, designed on a
    broadband record with the controller at 4 × 51.2 Hz."""
    directory = tmp_path_factory.mktemp("control_ssp")
    record = directory / "broadband.csv"
    with record.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time", "force", "acc1", "acc2", "acc3"])
        for k in range(513):
            t = k * RECORD_STEP
            force = sum(math.sin(2.0 * i * t + 0.3 * i) for i in range(1, 12))
            a = 0.01 * math.sin(40.0 * t)
            writer.writerow([repr(t), repr(force), repr(a), repr(a), repr(a)])
    out = {}
    for estimator in ("integrate", "kalman"):
        ssp = directory / f"{estimator}.ssp"
        report = directory / f"{estimator}.json"
        run_twin_ok(twin_binary, "control", "--data", str(record), "--q", "1e2", "1e3", "--r", "0.1",
                 "--substeps", str(SUBSTEPS), "--sensor-noise", "0", "--estimator", estimator,
                 "--report", str(report), "--ssp", str(ssp), "--ssp-q", "1e3")
        out[estimator] = (ssp, report)
    return out


def parameter_set(archive: Path, override: dict | None = None) -> ParameterSet:
    """Every component's bound parameters, renamed "<component>.<name>" (fmpy's `simulate_ssp`
    ignores the bindings)."""
    ssd = read_ssd(str(archive))
    parameters = []
    for element in ssd.system.elements:
        for binding in element.parameterBindings:
            for values in binding.parameterValues:
                for p in values.parameters:
                    parameters.append(Parameter(name=f"{element.name}.{p.name}", type=p.type, value=p.value))
    for name, value in (override or {}).items():
        parameters = [p for p in parameters if p.name != name]
        parameters.append(Parameter(name=name, type="Real", value=value))
    return ParameterSet(name="controlled", parameters=parameters)


def test_the_controlled_system_validates_and_carries_the_design(systems):
    for estimator, (ssp, report) in systems.items():
        ssd = read_ssd(str(ssp), validate=True)  # raises on a schema violation
        assert [e.name for e in ssd.system.elements] == ["physics", "lqr"]
        assert {c.name: c.kind for c in ssd.system.connectors} == {
            "force": "input", "acc1": "output", "acc2": "output", "acc3": "output", "control_force": "output"}
        links = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections}
        assert ("lqr", "control_force", "physics", "control_force") in links
        assert all(("physics", f"acc{i}", "lqr", f"acc{i}") in links for i in (1, 2, 3))
        assert {(None, "force", "physics", "force"), (None, "force", "lqr", "force")} <= links
        import json
        spec = json.loads(report.read_text())
        (design,) = [d for d in spec["designs"] if d["q"] == 1e3]
        values = {p.name: p.value for p in parameter_set(ssp).parameters}
        for i, g in enumerate(design["gain"]):
            assert float(values[f"lqr.gain{i + 1}"]) == g
        assert int(values["lqr.estimator"]) == (1 if estimator == "kalman" else 0)
        assert float(values["lqr.sample_interval"]) == 1.0 / spec["control_rate_hz"] == STEP


def test_twin_run_jacobi_and_fmpy_run_the_same_controlled_system(twin_binary, systems, tmp_path):
    force = tmp_path / "step.csv"
    with force.open("w", newline="") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["time", "force"])
        writer.writerow([0.0, 0.0])
        writer.writerow([repr(STEP), repr(FORCE)])
        writer.writerow([repr(POINTS * STEP), repr(FORCE)])
    for estimator, (ssp, _) in systems.items():
        out = tmp_path / f"{estimator}.csv"
        run_twin_ok(twin_binary, "run", str(ssp), "--input", str(force), "--hold-inputs", "--algorithm", "jacobi",
                 "--step", repr(STEP), "--stop", repr((POINTS - 1) * STEP), "--output", str(out))
        ours = np.genfromtxt(out, delimiter=",", names=True, deletechars="")
        assert len(ours) == POINTS
        theirs = simulate_ssp(str(ssp), start_time=0.0, stop_time=(POINTS - 1.5) * STEP, step_size=STEP,
                              parameter_set=parameter_set(ssp), input={"force": lambda t: FORCE})
        assert len(theirs) == POINTS - 1
        np.testing.assert_array_equal(theirs["time"], np.arange(POINTS - 1) * STEP)
        for name in OUTPUTS:
            a, b = theirs[name], ours[name][1:]
            peak = np.max(np.abs(b))
            assert peak > 0.0, name
            deviation = float(np.max(np.abs(a - b)) / peak)
            print(f"{estimator} {name}: fmpy simulate_ssp against twin run --algorithm jacobi: {deviation:.3e} of the peak")
            assert deviation <= 1e-9, f"{estimator} {name}: {deviation:.3e} of the peak"


def test_the_controller_fmu_refuses_a_step_other_than_its_interval(systems, capsys):
    ssp, _ = systems["integrate"]
    with pytest.raises(Exception) as refused:
        simulate_ssp(str(ssp), start_time=0.0, stop_time=10 * STEP, step_size=2 * STEP,
                     parameter_set=parameter_set(ssp), input={"force": lambda t: FORCE})
    assert "fmi2DoStep" in str(refused.value) or "fmi2Error" in str(refused.value), refused.value
    logged = capsys.readouterr()
    assert "sample_interval" in logged.out + logged.err, "the FMU logs why it refused the step"
    # The process is still here (no abort), and the same archive runs at the right step.
    result = simulate_ssp(str(ssp), start_time=0.0, stop_time=10 * STEP, step_size=STEP,
                          parameter_set=parameter_set(ssp), input={"force": lambda t: FORCE})
    assert len(result) == 10


def test_the_control_attenuates_the_first_resonance_in_fmpy(systems):
    import json
    for estimator, (ssp, report) in systems.items():
        f1 = json.loads(report.read_text())["resonances_hz"][0]
        drive = {"force": lambda t: math.sin(2.0 * math.pi * f1 * t)}
        stop = 4096 * STEP

        def rms_top(parameters):
            r = simulate_ssp(str(ssp), start_time=0.0, stop_time=stop, step_size=STEP,
                             parameter_set=parameters, input=drive)
            second_half = r["physics.acc3"][len(r) // 2:]
            return float(np.sqrt(np.mean(second_half ** 2)))

        controlled = rms_top(parameter_set(ssp))
        passive = rms_top(parameter_set(ssp, {f"lqr.gain{i}": "0" for i in range(1, 7)}))
        db = 20 * math.log10(passive / controlled)
        print(f"{estimator}: floor 3 at {f1:.2f} Hz, passive RMS {passive:.4g}, controlled {controlled:.4g}: {db:.1f} dB")
        assert db > 20.0, f"{estimator}: only {db:.1f} dB at the first resonance"
