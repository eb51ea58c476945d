"""The shear FMU in fmu-manipulation-toolbox 2.0: its checker, and its FMU Container holding two
shear FMUs, run under fmpy.

How the container runs its FMUs, from the installed toolbox: `container/builder.py` writes
`resources/container.txt` (flags <MT> <Profiling> <Sequential>, the internal step, the routing
tables) for a C runtime shipped as a binary (`resources/linux64/container.so`). The toolbox's own
descriptions of the default schedule disagree (`help.py`: "-sequential … disabling parallelism";
`assistant/models.py`: "Sequential scheduling instead of the default Gauss-Seidel sweep"), while
`FMUContainer.check_sequential_order` says of the sequential mode that each Co-Simulation FMU steps
"with the outputs just computed by the previous ones", and one placed before an FMU it depends on
"gets the outputs of the previous step". The runtime, exercised below, does:

- default (parallel, mono-thread): at each internal step, set every embedded FMU's inputs from the
  container's buffers (container inputs, and link values read at the end of the previous step),
  then doStep every FMU, then read every FMU's outputs into the buffers: a Jacobi step, links
  delayed by one step;
- sequential: for each FMU in configuration order, set its inputs, doStep, read its outputs: a
  Gauss-Seidel sweep, a link to a later FMU carries the value just computed;
- either way an embedded FMU's input is held constant over the step (the container declares no
  canInterpolateInputs and passes no input derivatives on), and at initialization the FMUs are
  initialized in link order (`FMUContainer.initialization_order`), the link value propagated.

The runtime prints "[ERROR] Solver configure...." when a container is instantiated, whatever it
embeds (a container of a one-output pythonfmu FMU prints it too): the toolbox's own message about
its Model-Exchange solver, nothing about the shear FMU.

The tests emulate both schedules with `fmpy.fmi2.FMU2Slave` on the same shear binary and require
the container's outputs to match the emulation of its schedule, and not the other one.
"""

from __future__ import annotations

import json
import logging
import re
import shutil
import subprocess
import sys
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmu_manipulation_toolbox.assembly import Assembly

from shear_drive import ACCELERATIONS, STEP, assert_within, instantiate

TOOLBOX_LOGGER = "fmu_manipulation_toolbox"

#: Shear FMU "a" is the structure at the prior means, driven by the container input `force`; its
#: floor-3 acceleration drives the force input of "b", a different structure with the bumper
#: between its floors 2 and 3 (so Real, Boolean and Integer start values all go through).
DRIVEN_PARAMETERS = {
    "k1": 3500.0,
    "m2": 6.0,
    "c3": 0.05,
    "contact23_enabled": True,
    "contact23_gap": 2e-5,
    "contact23_stiffness": 9000.0,
    "contact23_side": 1,
}


def _ansi_free(text: str) -> str:
    return re.sub(r"\x1b\[[0-9;]*m", "", text)


def test_fmutool_check_accepts_the_fmu(fmu_path):
    fmutool = Path(sys.executable).with_name("fmutool")
    completed = subprocess.run(
        [str(fmutool), "-input", str(fmu_path), "-check"], capture_output=True, text=True, timeout=120
    )
    output = _ansi_free(completed.stdout + completed.stderr)
    assert completed.returncode == 0, f"fmutool -check exited with {completed.returncode}:\n{output}"
    assert "This FMU seems to be compliant with FMI-2.0." in output, output
    assert "No semantic error against the FMI-2 standard." in output, output
    problems = [line for line in output.splitlines() if line.startswith(("ERROR", "CRITICAL", "WARNING"))]
    assert problems == [], "\n".join(problems)


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__(level=logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record):
        self.records.append(record)


def _description(name: str, sequential: bool) -> dict:
    """The container: two instances of fmu_shear.fmu, every port exposed or linked explicitly."""
    unused = ("disp1", "disp2", "disp3", "vel1", "vel2", "vel3", "drift1", "drift2", "drift3") + tuple(
        f"d_acc{i}_d_{p}{j}" for i in (1, 2, 3) for p in "mck" for j in (1, 2, 3)
    )
    return {
        "name": name,
        "step_size": STEP,
        "sequential": sequential,
        "auto_link": False,
        "auto_input": False,
        "auto_output": False,
        "fmu": ["shear_a.fmu", "shear_b.fmu"],
        "path": {"shear_a.fmu": "fmu_shear.fmu", "shear_b.fmu": "fmu_shear.fmu"},
        "input": [
            ["force", "shear_a.fmu", "force"],
            ["control_force_a", "shear_a.fmu", "control_force"],
            ["control_force_b", "shear_b.fmu", "control_force"],
        ],
        "link": [["shear_a.fmu", "acc3", "shear_b.fmu", "force"]],
        "output": [[f"shear_{x}.fmu", name, f"{x}_{name}"] for x in "ab" for name in ACCELERATIONS],
        "start": [["shear_b.fmu", name, _start_text(value)] for name, value in DRIVEN_PARAMETERS.items()],
        "drop": [[f"shear_{x}.fmu", name] for x in "ab" for name in unused],
    }


def _start_text(value) -> str:
    return ("true" if value else "false") if isinstance(value, bool) else repr(value)


CONTAINER_OUTPUTS = [f"{x}_{name}" for x in "ab" for name in ACCELERATIONS]


@pytest.fixture(scope="module")
def containers(fmu_path, tmp_path_factory):
    """Build both containers with the toolbox's Python API (what `fmucontainer -container x.json`
    runs), collecting what the builder logs at WARNING and above."""
    directory = tmp_path_factory.mktemp("container")
    shutil.copy(fmu_path, directory / "fmu_shear.fmu")
    built = {}
    for name, sequential in (("pair_parallel", False), ("pair_sequential", True)):
        (directory / f"{name}.json").write_text(json.dumps(_description(f"{name}.fmu", sequential)))
        collector = _Collect()
        logger = logging.getLogger(TOOLBOX_LOGGER)
        logger.addHandler(collector)
        try:
            Assembly(f"{name}.json", fmu_directory=directory).make_fmu()
        finally:
            logger.removeHandler(collector)
        built[name] = (directory / f"{name}.fmu", [f"{r.levelname}: {r.getMessage()}" for r in collector.records])
    return built


@pytest.mark.parametrize("name", ["pair_parallel", "pair_sequential"])
def test_container_builds_without_complaint(containers, name):
    path, complaints = containers[name]
    assert path.is_file()
    assert complaints == [], "\n".join(complaints)


def _emulate(shear_fmu, force: np.ndarray, sequential: bool, driven_parameters: dict = DRIVEN_PARAMETERS) -> np.ndarray:
    """The container's schedule replayed on two FMU2Slave instances of the same binary."""
    force_vr = [shear_fmu.vr("force")]
    acc = [shear_fmu.vr(name) for name in ACCELERATIONS]
    driving = instantiate(shear_fmu, {}, force[0], "shear_a")
    outputs_a = driving.getReal(acc)
    link = outputs_a[2]
    driven = instantiate(shear_fmu, driven_parameters, link, "shear_b")
    rows = [outputs_a + driven.getReal(acc)]
    try:
        for k in range(len(force) - 1):
            if sequential:
                driving.setReal(force_vr, [force[k]])
                driving.doStep(k * STEP, STEP)
                outputs_a = driving.getReal(acc)
                driven.setReal(force_vr, [outputs_a[2]])
                driven.doStep(k * STEP, STEP)
                outputs_b = driven.getReal(acc)
            else:
                driving.setReal(force_vr, [force[k]])
                driven.setReal(force_vr, [link])
                driving.doStep(k * STEP, STEP)
                driven.doStep(k * STEP, STEP)
                outputs_a, outputs_b = driving.getReal(acc), driven.getReal(acc)
            link = outputs_a[2]
            rows.append(outputs_a + outputs_b)
    finally:
        for slave in (driving, driven):
            slave.terminate()
            slave.freeInstance()
    return np.array(rows)


@pytest.mark.parametrize("name, sequential", [("pair_parallel", False), ("pair_sequential", True)])
def test_container_under_fmpy_matches_the_shear_fmus_run_directly(containers, shear_fmu, record, name, sequential):
    path, _ = containers[name]
    columns = ("time", "force", "control_force_a", "control_force_b")
    signal = np.zeros(len(record.time), dtype=[(column, np.float64) for column in columns])
    signal["time"] = record.time
    signal["force"] = record.force
    # The container cannot interpolate inputs, so fmpy sets values only: the force held over each
    # step, as the container holds it for the embedded FMUs anyway.
    result = fmpy.simulate_fmu(
        str(path), input=signal, output=CONTAINER_OUTPUTS, output_interval=STEP, stop_time=record.time[-1]
    )
    by_container = np.stack([result[name] for name in CONTAINER_OUTPUTS], axis=1)

    expected = _emulate(shear_fmu, record.force, sequential)
    # Tolerance 1e-12 of each signal's peak: the container calls the same library with the same
    # arguments in the same order, and its step, 5/256 s, is exact in binary, so nothing but the
    # last bits of the step size it computes (target − time) could differ. Measured: bitwise equal.
    assert_within(by_container, expected, 1e-12, f"{name} against the emulated schedule")

    # The other schedule is far off on b's floors (measured: 0.7–1.1 × their peak; with the link
    # held over a step, the sequential b runs one link sample ahead of the parallel one), so the
    # comparison tells the schedules apart; a's outputs do not depend on the schedule.
    other = _emulate(shear_fmu, record.force, not sequential)
    scale = np.max(np.abs(other[:, 3:]), axis=0)
    assert np.all(np.max(np.abs(by_container[:, 3:] - other[:, 3:]), axis=0) > 0.1 * scale)

    # b's start values did reach b: with b at the prior means its floors differ by about their
    # peak (measured 1.0–1.05 ×); without the bumper alone, by 1.3–2.0 × (the gap closes).
    at_prior_means = _emulate(shear_fmu, record.force, sequential, driven_parameters={})
    assert np.all(np.max(np.abs(by_container[:, 3:] - at_prior_means[:, 3:]), axis=0) > 0.1 * scale)
