"""shear_twin: the shear-frame digital twin from Python.

The same operations as the ``twin`` CLI, from the orchestrator library itself (a PyO3 extension,
not the CLI in a subprocess), the GIL released while they run::

    import shear_twin as st
    twin = st.Twin.open("out/demo/calibrated.ssp")
    record = st.Record.read("data/dataset3.csv")
    comparison = twin.compare(record)            # Comparison: .nmse, .predictions, .report
    diagnosis = twin.diagnose(record)            # Report: .action, .effects, ...
    new_twin, added = twin.add_physics(record, diagnosis=diagnosis)

Errors are ``ShearTwinError`` subclasses whose message is the CLI's. Fleets of structures run
on Dask: ``shear_twin.fleet``.
"""

from __future__ import annotations

import json
from typing import Any

from . import _native
from ._native import (
    CalibrateError,
    ControlError,
    DataError,
    DiagnoseError,
    Record,
    ShearTwinError,
    SynthError,
    TwinError,
    WatchError,
)

for _error in (ShearTwinError, DataError, TwinError, CalibrateError, DiagnoseError, ControlError,
               WatchError, SynthError):
    _error.__module__ = "shear_twin"

__all__ = [
    "Twin", "Record", "Report", "Comparison", "synth",
    "ShearTwinError", "DataError", "TwinError", "CalibrateError", "DiagnoseError",
    "ControlError", "WatchError", "SynthError",
]


class Report:
    """A report of the CLI's JSON as an object: its fields as attributes (``r.action``) and
    items (``r["action"]``); ``to_dict()`` the plain dict, ``to_json()`` the CLI's file."""

    def __init__(self, data: dict[str, Any]):
        self._data = data

    def __getattr__(self, name: str) -> Any:
        try:
            return self._data[name]
        except KeyError:
            raise AttributeError(name) from None

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __contains__(self, key: str) -> bool:
        return key in self._data

    def keys(self):
        return self._data.keys()

    def to_dict(self) -> dict[str, Any]:
        return self._data

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self._data, indent=indent)

    def __repr__(self) -> str:
        shown = {k: self._data[k] for k in ("action", "nmse", "nmse_before", "nmse_after") if k in self._data}
        return f"{type(self).__name__}({shown})"


class Comparison(Report):
    """``twin compare``'s report, with the predictions: ``predictions`` is a dict of numpy
    arrays (``time``, ``acc1``..``acc3``, and the corrector's ``latent_var*``, ``sd*``), ready
    for ``pandas.DataFrame(c.predictions)``."""

    def __init__(self, report: dict[str, Any], predictions: dict[str, Any]):
        super().__init__(report)
        self.predictions = predictions


class Twin:
    """A twin (an SSP archive around the shear FMU). Every operation leaves it unchanged and
    returns a new ``Twin`` where the CLI writes one."""

    def __init__(self, native: _native.Twin):
        self._native = native

    @staticmethod
    def open(path: str) -> "Twin":
        """Open a twin archive (``.ssp``)."""
        return Twin(_native.Twin.open(str(path)))

    @staticmethod
    def default() -> "Twin":
        """The default twin: the shear FMU with its default parameters (``twin init``)."""
        return Twin(_native.Twin.default())

    def save(self, path: str) -> None:
        """Write the twin as an SSP archive."""
        self._native.save(str(path))

    @property
    def path(self) -> str | None:
        return self._native.path

    @property
    def parameters(self) -> dict[str, dict[str, float | int | bool]]:
        return self._native.parameters

    @property
    def noise_variance(self) -> list[float] | None:
        return self._native.noise_variance

    def __repr__(self) -> str:
        return repr(self._native)

    def compare(self, record: Record, *, transient: float = 2.0,
                tolerance: float | None = None) -> Comparison:
        out = self._native.compare(record, transient=transient, tolerance=tolerance)
        return Comparison(out["report"], out["predictions"])

    def calibrate(self, record: Record, *, parameters: list[str] | None = None, starts: int = 12,
                  seed: int = 1, transient: float = 2.0, validate: list[Record] = (),
                  threads: int | None = None) -> tuple["Twin", Report]:
        twin, report = self._native.calibrate(record, parameters=parameters, starts=starts, seed=seed,
                                              transient=transient, validate=list(validate),
                                              threads=threads)
        return Twin(twin), Report(report)

    def diagnose(self, record: Record, *, effects: list[str] | None = None, transient: float = 2.0,
                 tolerance: float | None = None, threads: int | None = None,
                 block: float = 1.0) -> Report:
        return Report(self._native.diagnose(record, effects=effects, transient=transient,
                                            tolerance=tolerance, threads=threads, block=block))

    def add_physics(self, record: Record, *, effects: list[str] | None = None,
                    diagnosis: Report | dict[str, Any] | None = None, refine: bool = False,
                    transient: float = 2.0, threads: int | None = None) -> tuple["Twin", Report]:
        if isinstance(diagnosis, Report):
            diagnosis = diagnosis.to_dict()
        twin, report = self._native.add_physics(record, effects=effects, diagnosis=diagnosis,
                                                refine=refine, transient=transient, threads=threads)
        return Twin(twin), Report(report)

    def control(self, record: Record, q: list[float], *, r: float = 0.1, state_unit: str = "m",
                estimator: str = "integrate", highpass: float = 0.5, seed: int = 1) -> Report:
        return Report(self._native.control(record, list(q), r=r, state_unit=state_unit,
                                           estimator=estimator, highpass=highpass, seed=seed))

    def watch(self, source: str, alerts: str, *, follow: bool = False, idle: float = 10.0,
              window: float = 2.0, tolerance: float | None = None, transient: float = 2.0,
              diagnosis: bool = True, diagnosis_record: float = 20.0,
              diagnosis_after: float = 5.0, checkpoint: str | None = None) -> Report:
        summary = self._native.watch(str(source), str(alerts), follow=follow, idle=idle,
                                     window=window, tolerance=tolerance, transient=transient,
                                     diagnosis=diagnosis, diagnosis_record=diagnosis_record,
                                     diagnosis_after=diagnosis_after,
                                     checkpoint=None if checkpoint is None else str(checkpoint))
        return Report(summary)


def synth(scenario: dict[str, Any], out: str | None = None) -> tuple[Record, dict[str, Any]]:
    """A synthetic record of ``twin synth``'s structure and its truth (the hidden effects)."""
    return _native.synth(scenario, None if out is None else str(out))
