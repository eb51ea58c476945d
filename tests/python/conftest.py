"""Fixtures of the fmpy and third-party cross-checks of the shear FMU.

The FMU is `target/fmu/fmu_shear.fmu` (built by scripts/build-fmus.sh), or the file named by the
environment variable SHEAR_FMU. Run with the project's environment:

    scripts/setup-python.sh && .venv/bin/python -m pytest tests/python -q
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import fmpy.simulation
import pytest

from shear_drive import ShearFmu, read_record

REPO_ROOT = Path(__file__).resolve().parents[2]
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", REPO_ROOT / "target"))


def require_built(*paths: Path) -> None:
    """Fail (naming the build command) when a file the test runs is missing."""
    for path in paths:
        if not path.is_file():
            pytest.fail(f"{path} does not exist: run scripts/build-fmus.sh", pytrace=False)


def run_twin(binary: Path, *args: str, check: bool = False, timeout: float = 900,
             fmu_dir: Path | None = None, cwd: Path | None = None,
             extra_env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`binary` (this build's `twin`) run with `args`, its output captured as text, TWIN_FMU_DIR
    this build's FMUs (or `fmu_dir`), TWIN_FMU_LOG unset and `extra_env` added. `check`: assert
    that it exited 0, the message naming the command, its exit code and its output."""
    env = dict(os.environ, TWIN_FMU_DIR=str(fmu_dir or TARGET / "fmu"), **(extra_env or {}))
    env.pop("TWIN_FMU_LOG", None)
    done = subprocess.run([str(binary), *args], capture_output=True, text=True, env=env,
                          timeout=timeout, cwd=cwd)
    if check:
        assert done.returncode == 0, \
            f"twin {' '.join(args)}: exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


def run_twin_ok(binary: Path, *args: str, **options) -> subprocess.CompletedProcess:
    """[`run_twin`] that asserts the run exited 0."""
    return run_twin(binary, *args, check=True, **options)


def twin_binary_path() -> Path:
    """The `twin` CLI of this build (or the file named by TWIN_BIN, or TWIN_BINARY)."""
    named = os.environ.get("TWIN_BIN") or os.environ.get("TWIN_BINARY")
    return Path(named) if named else TARGET / "release" / "twin"


@pytest.fixture(scope="session")
def twin_binary() -> Path:
    """[`twin_binary_path`]; a test that needs it fails, naming the build command, when it is
    missing."""
    path = twin_binary_path()
    require_built(path)
    return path


@pytest.fixture(scope="session")
def twin_fmus() -> Path:
    """The folder of this build's FMUs (`TWIN_FMU_DIR` of the tests' `twin` runs), checked to hold
    the shear and LQR FMUs; a module that runs them lists it in `pytestmark`."""
    folder = TARGET / "fmu"
    require_built(folder / "fmu_shear.fmu", folder / "fmu_lqr.fmu")
    return folder


@pytest.fixture(scope="session")
def fmu_path() -> Path:
    path = Path(os.environ.get("SHEAR_FMU", REPO_ROOT / "target" / "fmu" / "fmu_shear.fmu"))
    if not path.is_file():
        pytest.fail(f"the shear FMU {path} does not exist: run scripts/build-fmus.sh", pytrace=False)
    return path


@pytest.fixture(scope="session")
def shear_fmu(fmu_path, tmp_path_factory) -> ShearFmu:
    return ShearFmu.open(fmu_path, tmp_path_factory.mktemp("fmu_shear"))


@pytest.fixture(scope="session")
def record():
    """dataset1: the structure shaken gently, 1024 samples at 51.2 Hz."""
    return read_record(REPO_ROOT / "data" / "dataset1.csv")


@pytest.fixture(scope="session")
def start_parameters(shear_fmu) -> dict:
    """Every parameter at its start value: the prior means, every effect switched off."""
    return {
        name: shear_fmu.start_value(name)
        for name, variable in shear_fmu.variables.items()
        if variable.causality == "parameter"
    }


@pytest.fixture
def fmpy_input_derivatives_fixed(monkeypatch):
    """Let fmpy 0.3.32's `simulate_fmu(..., set_input_derivatives=True)` run on this FMU.

    fmpy 0.3.32 keeps the derivatives of the continuous inputs in a buffer of a fixed nine
    elements (`derivatives=(value_type * 9)()` in fmpy/simulation.py, class Input), and
    `Input.apply` fills it with `derivatives[:] = d`, which raises "ValueError: Can only assign
    sequence of same size" unless the input signals hold exactly nine continuous inputs. This
    sizes that buffer to the number of inputs and changes nothing else; the test
    `test_fmpy_0_3_32_cannot_set_input_derivatives_unaided` shows the defect is still there.
    """
    original_init = fmpy.simulation.Input.__init__

    def init_with_sized_derivatives(self, *args, **kwargs):
        original_init(self, *args, **kwargs)
        self.continuous = [
            info._replace(derivatives=(info.derivatives._type_ * len(info.values))())
            for info in getattr(self, "continuous", [])
        ]

    monkeypatch.setattr(fmpy.simulation.Input, "__init__", init_with_sized_derivatives)
