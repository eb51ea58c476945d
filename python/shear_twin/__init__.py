"""shear_twin: the shear-frame digital twin from Python.

The same operations as the ``twin`` CLI, from the orchestrator library itself (a PyO3 extension,
not the CLI in a subprocess), the GIL released while they run::

    import shear_twin as st
    twin = st.Twin.open("out/demo/calibrated.ssp")
    record = st.Record.read("data/dataset3.csv")
    comparison = twin.compare(record)            # Comparison: .nmse, .predictions, .report
    diagnosis = twin.diagnose(record)            # Report: .action, .effects, ...
    new_twin, added = twin.add_physics(record, diagnosis=diagnosis)
    control = twin.control(record, [1e3], retune=True, schedule=True, ssp="controlled.ssp")
    twin.watch("mqtt://127.0.0.1:1883/shear", "alerts.jsonl", on_alert=print)
    corrected, training = twin.train(record)
    ran = st.run("controlled.ssp", step=1 / control.control_rate_hz)     # RunResult: .columns, .to_frame()

Every ``twin`` command has its call (README.md, *Python and fleets*, has the table), with the
CLI's options as keyword arguments (None: the library's default, the CLI's) and its report.
Errors are ``ShearTwinError`` subclasses whose message is the CLI's. Fleets of structures run
on Dask: ``shear_twin.fleet``.
"""

from __future__ import annotations

import json as _json
import os as _os
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names for the annotations only: the package's namespace is its API
    import os
    from collections.abc import Callable, Mapping, Sequence
    from typing import Any

from . import _native
from ._native import (
    CalibrateError,
    ControlError,
    DataError,
    DiagnoseError,
    HybridError,
    Record,
    RunError,
    ShearTwinError,
    SynthError,
    TrainError,
    TwinError,
    WatchError,
)

for _error in (ShearTwinError, DataError, TwinError, CalibrateError, DiagnoseError, ControlError,
               WatchError, SynthError, TrainError, RunError, HybridError):
    _error.__module__ = "shear_twin"

__all__ = [
    "Twin", "Record", "Report", "Comparison", "Control", "RunResult", "synth", "run", "pack_fmu",
    "export_fmus", "init", "record_from_frame", "read_frf", "identify_modes",
    "ShearTwinError", "DataError", "TwinError", "CalibrateError", "DiagnoseError",
    "ControlError", "WatchError", "SynthError", "TrainError", "RunError", "HybridError",
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
        """The report's field names (the CLI's JSON keys)."""
        return self._data.keys()

    def to_dict(self) -> dict[str, Any]:
        """The report as the CLI's JSON, a dict."""
        return self._data

    def to_json(self, indent: int | None = 2) -> str:
        """The report as the CLI's JSON text."""
        return _json.dumps(self._data, indent=indent)

    def __repr__(self) -> str:
        shown = {k: self._data[k] for k in ("action", "nmse", "nmse_before", "nmse_after") if k in self._data}
        return f"{type(self).__name__}({shown})"


class Comparison(Report):
    """``twin compare``'s report, with the predictions: ``channels`` names the record's
    measured channels (``acc1``, ``vel2``, ...) and every per-channel list of the report
    (``nmse``, ``noise_variance``, a failing window's ``nmse``) follows that order;
    ``predictions`` is a dict of numpy arrays (``time``, each measured channel by name, in SI,
    and the corrector's ``latent_var*``, ``sd*``), ready for ``pandas.DataFrame(c.predictions)``."""

    def __init__(self, report: dict[str, Any], predictions: dict[str, Any]):
        super().__init__(report)
        self.predictions = predictions

    def to_frame(self):
        """The predictions as a pandas DataFrame (the CLI's ``--predictions`` CSV)."""
        return _frame(self.predictions)


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
        """The archive the twin was opened from, None for one made in memory."""
        return self._native.path

    @property
    def parameters(self) -> dict[str, dict[str, float | int | bool]]:
        """The parameter values by component: ``{"physics": {"k2": 4300.0, ...}}``."""
        return self._native.parameters

    @property
    def noise_variance(self) -> dict[str, float] | None:
        """The calibrated noise variance by channel (SI units squared), None when uncalibrated."""
        return self._native.noise_variance

    def __repr__(self) -> str:
        return repr(self._native)

    def compare(self, record: Record, *, transient: float | None = None,
                tolerance: float | None = None, controller: str | os.PathLike | Report | dict | None = None,
                controller_q: float | None = None, plot: str | os.PathLike | None = None,
                frf: bool = False, latent_threshold: float | None = None,
                modes: bool = False) -> Comparison:
        """``twin compare``: run the twin on the record's excitation (``force`` or
        ``ground_acc``) and compare every measured channel, each in its own quantity; a record
        the twin cannot serve (another excitation, a floor it lacks) raises ``DataError``
        naming the column. ``controller``: a ``twin control`` report (a path, or the report
        ``Twin.control`` returned) whose design ``controller_q`` (default the first stable one)
        closes the loop. None means the CLI's default (``transient`` 2 s; ``tolerance`` 2 × the
        twin's worst validation NMSE, else 0.5 %). ``plot``: the CLI's ``--plot`` (.svg; with
        ``frf`` the frequency view, and with a corrector ``PLOT-latent.svg`` against
        ``latent_threshold``). ``modes``: also identify the record's modes beside the twin's
        (the CLI's ``--modes``; the report's ``modes``)."""
        out = self._native.compare(record, transient=transient, tolerance=tolerance,
                                   controller=_report_or_path(controller), controller_q=controller_q,
                                   plot=_path(plot), frf=frf, latent_threshold=latent_threshold,
                                   modes=modes)
        return Comparison(out["report"], out["predictions"])

    def calibrate(self, record: Record | Sequence[Record] | None = None, *,
                  parameters: list[str] | None = None,
                  priors: dict[str, dict[str, Any]] | None = None, starts: int | None = None,
                  seed: int | None = None, transient: float | None = None,
                  validate: Sequence[Record] = (), threads: int | None = None,
                  plot: str | os.PathLike | None = None, frf: str | os.PathLike | None = None,
                  band: tuple[float, float] | None = None,
                  gain_offset: bool = False) -> tuple["Twin", Report]:
        """``twin calibrate``: MAP calibration of ``parameters`` (default every floor's mass and
        storey's damping and stiffness of the twin's structure) and a noise variance per measured
        channel, on one record or on several runs (one MAP over all, each run its own channels);
        ``priors`` as the CLI's ``--priors`` file's JSON; the ``validate`` records' worst NMSE
        sets the new twin's tolerance. Defaults (None): 12 starts, seed 1, transient 2 s, all
        cores. Returns the calibrated twin and the report (``runs``: NMSE by channel per run).

        ``frf`` instead of a record (``twin calibrate --frf``): a measured FRF file (CSV
        ``frequency,acc1_re,acc1_im,…`` or a universal file's dataset 58; see ``read_frf``),
        fitted over ``band`` (Hz, ``(lo, hi)``; default every line above 0 Hz), ``gain_offset``
        a dB offset when the file's dB reference is unknown; 4 starts by default."""
        if frf is not None:
            if record is not None or tuple(validate) or transient is not None or threads is not None \
                    or plot is not None:
                raise TypeError("calibrate(frf=...) takes no record, validate, transient, threads or plot")
            twin, report = self._native.calibrate_frf(_os.fspath(frf), parameters=parameters, priors=priors,
                                                      band=None if band is None else tuple(band),
                                                      gain_offset=gain_offset, starts=starts, seed=seed)
            return Twin(twin), Report(report)
        if band is not None or gain_offset:
            raise TypeError("band and gain_offset go with frf=")
        if record is None:
            raise TypeError("calibrate: give a record (or runs), or frf=")
        if not isinstance(record, Record):
            record = list(record)
        twin, report = self._native.calibrate(record, parameters=parameters, priors=priors, starts=starts,
                                              seed=seed, transient=transient, validate=list(validate),
                                              threads=threads, plot=_path(plot))
        return Twin(twin), Report(report)

    def diagnose(self, record: Record, *, effects: list[str] | None = None, transient: float | None = None,
                 tolerance: float | None = None, threads: int | None = None,
                 block: float | None = None, always_fit: bool = False,
                 plot: str | os.PathLike | None = None) -> Report:
        """``twin diagnose``: none, recalibrate, add physics (which effect, where, how strong),
        sensor fault or update the data-based model, with the evidence. ``effects`` limits the
        candidates (``["contact@2-3", "cubic@2"]``). Defaults (None): transient 2 s, 1 s blocks,
        all cores, the twin's tolerance."""
        return Report(self._native.diagnose(record, effects=effects, transient=transient,
                                            tolerance=tolerance, threads=threads, block=block,
                                            always_fit=always_fit, plot=_path(plot)))

    def diagnose_ambient(self, path: str | os.PathLike, *,
                         plot: str | os.PathLike | None = None) -> Report:
        """``twin diagnose`` on an ambient record: a CSV of the responses alone (no ``force`` or
        ``ground_acc`` column; one it has is left out), as a building's monitoring measures
        them. The twin cannot run on it, so its modes are compared: identified output-only
        (SSI-COV) and set against the twin's band, ``none`` when every mode is inside it, else
        ``recalibrate`` with ``explanations``: each floor's mass or storey's stiffness alone
        fitted to the identified frequencies, best first (``tied_for_best`` of them fit as
        well). ``plot``: an SVG of the twin's shapes with the record's."""
        return Report(self._native.diagnose_ambient(_os.fspath(path), plot=_path(plot)))

    def modes(self, *, samples: int | None = None, plot: str | os.PathLike | None = None) -> Report:
        """``twin modal --twin``: the natural frequencies (Hz), damping ratios and mode shapes
        (floors 1..N, the largest component 1) of the twin's linear structure, each with its sd
        from the calibration's posterior (None for an uncalibrated twin) and, beside it, the sds
        of ``samples`` draws from the posterior (default 2000; 0: none). ``plot``: an SVG of the
        shapes along the height."""
        return Report(self._native.modes(samples=samples, plot=_path(plot)))

    def add_physics(self, record: Record | None = None, *, effects: list[str] | None = None,
                    diagnosis: Report | dict[str, Any] | None = None,
                    hybrid: str | os.PathLike | None = None, refine: bool = False,
                    transient: float | None = None, threads: int | None = None,
                    records: Sequence[Record] | None = None) -> tuple["Twin", Report]:
        """``twin add-physics``: switch effects on (``effects``, or all of a ``diagnosis``
        report's), estimate them on the record, then refit them jointly with the structure over
        the record and ``records`` (default: those the twin remembers from its calibration;
        ``--records``). ``hybrid`` (``--hybrid``): the contact law a ``twin hybrid run``
        report (its path) identified at its interface, held as identified, the structure
        refitted over ``record`` (optional) and ``records``. ``refine`` is accepted and ignored,
        as in the CLI. Returns the new twin and the report (NMSE per record before and after)."""
        if isinstance(diagnosis, Report):
            diagnosis = diagnosis.to_dict()
        twin, report = self._native.add_physics(record, effects=effects, diagnosis=diagnosis,
                                                hybrid=_path(hybrid), refine=refine, transient=transient,
                                                threads=threads,
                                                records=None if records is None else list(records))
        return Twin(twin), Report(report)

    def control(self, record: Record, q: Sequence[float], *, r: float | None = None,
                state_unit: str | None = None, estimator: str | None = None,
                highpass: float | None = None, substeps: int | None = None,
                sensor_noise: float | None = None, seed: int | None = None, gaps: Sequence[str] = (),
                retune: bool = False, target_contacts: int | None = None, max_force: float | None = None,
                schedule: bool = False, margin: float | None = None, lookahead: float | None = None,
                dwell: float | None = None, variance_threshold: str | float | None = None,
                estimator_costs: bool = False, ssp: str | os.PathLike | None = None,
                ssp_q: float | None = None, plot: str | os.PathLike | None = None) -> Control:
        """``twin control``: an LQR design per ``q`` on the twin's structure, run in the loop on
        the record's force, passive and under each design. ``retune``: the smallest q (on a grid
        up to 100 × the smallest) keeping the contact initiations ≤ ``target_contacts`` (3)
        within ``max_force``; ``schedule``: gain scheduling (``margin`` 0.4, ``lookahead``
        0.02 s, ``dwell`` 0.5 s, ``variance_threshold`` "auto", "off" or a number); ``gaps``:
        ``"2-3:5e-4[:negative|positive|both]"``; ``ssp``: also write the controlled system (the
        design ``ssp_q``) as an SSP archive. Defaults (None) as the CLI's: R 0.1, state in m,
        the integrating estimator, 0.5 Hz, the twin's calibrated sensor noise, seed 1.
        Returns the report with the time histories (``Control.responses``)."""
        if variance_threshold is not None and not isinstance(variance_threshold, str):
            variance_threshold = repr(float(variance_threshold))
        out = self._native.control(record, [float(x) for x in q], r=r, state_unit=state_unit,
                                   estimator=estimator, highpass=highpass, substeps=substeps,
                                   sensor_noise=sensor_noise, seed=seed, gaps=list(gaps), retune=retune,
                                   target_contacts=target_contacts, max_force=max_force,
                                   schedule=schedule, margin=margin, lookahead=lookahead, dwell=dwell,
                                   variance_threshold=variance_threshold,
                                   estimator_costs=estimator_costs, ssp=_path(ssp), ssp_q=ssp_q,
                                   plot=_path(plot))
        return Control(out)

    def watch(self, source: str | os.PathLike, alerts: str | os.PathLike, *,
              on_alert: Callable[[dict[str, Any]], Any] | None = None,
              columns: Mapping[str, str] | str | os.PathLike | None = None, client_id: str | None = None,
              follow: bool = False, idle: float | None = None, checkpoint: str | os.PathLike | None = None,
              checkpoint_every: int | None = None, window: float | None = None,
              tolerance: float | None = None, transient: float | None = None, rate: float | None = None,
              diagnosis: bool = True, diagnosis_record: float | None = None,
              diagnosis_after: float | None = None, query_threshold: float | None = None,
              learning: bool = True, budget: int | None = None, refit_every: int | None = None,
              diagnosis_wait: bool = False, adopt: bool = False) -> Report:
        """``twin watch``: the operational twin on a stream. ``source``: ``"-"`` (standard
        input, read to its end), ``"mqtt://HOST[:PORT]/TOPIC"`` (QoS 1, a persistent session
        with ``client_id``; alerts also published to TOPIC/alerts) or a CSV file (``follow``:
        as it grows, until ``idle`` s (10) pass without a line); its header names the columns
        as a record's does (time, force or ground_acc, any acc/vel/disp<i>, units such as
        ``acc1 (g)``; ``columns`` maps other names, as ``Record.read``'s). Alerts go to ``alerts`` as JSON
        lines; ``on_alert(alert)`` is called with each alert (a dict) as it is written — an
        exception it raises stops the watch and is raised here. ``diagnosis=False`` is
        ``--no-diagnosis``, ``learning=False`` ``--no-learning``, ``diagnosis_wait=True``
        ``--diagnosis-wait`` (a recorded stream replayed at full speed), ``adopt=True``
        ``--adopt`` (a firm recalibration or added effect swapped into the watch, its twin beside the
        alerts).
        Returns the ``end`` alert's summary."""
        summary = self._native.watch(
            str(source), str(alerts), on_alert=on_alert, columns=columns, client_id=client_id, follow=follow, idle=idle,
            checkpoint=_path(checkpoint), checkpoint_every=checkpoint_every, window=window,
            tolerance=tolerance, transient=transient, rate=rate, diagnosis=diagnosis,
            diagnosis_record=diagnosis_record, diagnosis_after=diagnosis_after,
            query_threshold=query_threshold, learning=learning, budget=budget, refit_every=refit_every,
            diagnosis_wait=diagnosis_wait, adopt=adopt)
        return Report(summary)

    def train(self, record: Record, *, lags: int | None = None, target: str | None = None,
              transient: float | None = None, stride: int | None = None,
              select_lags: Sequence[int] | None = None,
              selection_stride: int | None = None) -> tuple["Twin", Report]:
        """``twin train``: the GP bias corrector trained on the record and put behind the
        physics. ``target``: "discrepancy" (default) or "measured"; ``select_lags``: choose the
        lags among these by the lowest negative log marginal likelihood (fits on every
        ``selection_stride``-th sample, 4). Returns the twin with the corrector and the
        report."""
        twin, report = self._native.train(record, lags=lags, target=target, transient=transient,
                                          stride=stride,
                                          select_lags=None if select_lags is None else list(select_lags),
                                          selection_stride=selection_stride)
        return Twin(twin), Report(report)

    def learn(self, records: Sequence[Record], *, mode: str | None = None, forgetting: float | None = None,
              all_modes: bool = False, threshold: float | None = None, lags: int | None = None,
              target: str | None = None, transient: float | None = None, initial: int | None = None,
              refit_every: int | None = None, refit_growth: float | None = None,
              refit_iterations: int | None = None, nmse_every: int | None = None,
              change_run: int | None = None,
              out_dir: str | os.PathLike | None = None) -> tuple[Report, "Twin | None"]:
        """``twin learn``: stream-based active learning of the GP corrector over ``records`` in
        order (the paper's Algorithm 1). ``mode``: "uniform", "fixed" or "adaptive" (default,
        with ``forgetting`` 1); ``all_modes``: the six modes of Table 2 (``--modes all``).
        Returns the report and, for one mode, the twin with the corrector as learned (the CLI's
        ``--out``), else None; ``out_dir``: one plot per mode there (``learn-MODE.svg``)."""
        report, twin = self._native.learn(list(records), mode=mode, forgetting=forgetting,
                                          all_modes=all_modes, threshold=threshold, lags=lags,
                                          target=target, transient=transient, initial=initial,
                                          refit_every=refit_every, refit_growth=refit_growth,
                                          refit_iterations=refit_iterations, nmse_every=nmse_every,
                                          change_run=change_run, out_dir=_path(out_dir))
        return Report(report), None if twin is None else Twin(twin)

    def hybrid_threshold(self, *, a_err: Sequence[float] | None = None, **common: Any) -> Report:
        """``twin hybrid threshold`` on this twin's structure (its m, c, k; ``Twin.default()``
        for the CLI without ``--twin``): the peak excitation force at which the bumper between
        floors 2 and 3 first closes, for each amplitude error ``a_err`` (default −0.1 to 0.1 by
        0.02). ``common``: the options both hybrid commands take — ``excitation`` (a
        ``time,force`` CSV), ``seed``, ``duration``, ``sample_rate``, ``substeps``, ``gap``,
        ``contact_stiffness``, ``delay``, ``lag``, ``compensate``, ``energy_factor``, ``split``
        (the floor J the actuator drives as a string, e.g. "3", or a name: "specimen-floors-J-N",
        "specimen-storeys-A-N", "specimen-floor-N"; the paper's "specimen-floors-2-3" by
        default on three storeys, or "specimen-floor-3"), ``coupling`` ("auto",
        "monolithic", "stepped"), ``plot`` — None for the CLI's defaults. Returns the report."""
        return Report(self._native.hybrid_threshold(a_err=None if a_err is None else list(a_err),
                                                    **_hybrid(common)))

    def hybrid_run(self, *, peak: float | None = None, a_err: Sequence[float] | None = None,
                   displacement_noise: float | None = None, force_noise: float | None = None,
                   acceleration_noise: float | None = None, **common: Any) -> Report:
        """``twin hybrid run`` on this twin's structure: the test at ``peak`` N (5) for each
        amplitude error ``a_err`` (default 0 and 0.05) — contacts, floor 2's spectrum and
        harmonics, the contact law identified from the interface measured with
        ``displacement_noise`` (1e-6 m), ``force_noise`` (1e-3 N) and, when the specimen holds
        floor 2, ``acceleration_noise`` (1e-3 m/s², its accelerometer). ``common``: as
        ``hybrid_threshold``'s. Returns the report (for ``add_physics``' hybrid law)."""
        return Report(self._native.hybrid_run(peak=peak, a_err=None if a_err is None else list(a_err),
                                              displacement_noise=displacement_noise,
                                              force_noise=force_noise,
                                              acceleration_noise=acceleration_noise, **_hybrid(common)))


_HYBRID_COMMON = ("excitation", "seed", "duration", "sample_rate", "substeps", "gap", "contact_stiffness",
                  "delay", "lag", "compensate", "energy_factor", "split", "coupling", "plot")


def _hybrid(common: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(common) - set(_HYBRID_COMMON))
    if unknown:
        raise TypeError(f"unexpected keyword argument(s): {', '.join(unknown)}")
    return {k: _path(v) if k in ("excitation", "plot") else v for k, v in common.items()}


def _path(p: str | os.PathLike | None) -> str | None:
    return None if p is None else _os.fspath(p)


def _report_or_path(r: str | os.PathLike | Report | dict | None) -> str | dict | None:
    if r is None or isinstance(r, dict):
        return r
    if isinstance(r, Report):
        return r.to_dict()
    return _os.fspath(r)


def _frame(columns: dict[str, Any]):
    import pandas as pd

    return pd.DataFrame(columns)


class Control(Report):
    """``twin control``'s report (``designs``, ``passive``, ``retune``, ``schedule``, …) with
    the time histories: ``responses["passive"]``, ``responses[q]`` for each stable design and
    ``responses["scheduled"]``, each a dict of numpy arrays ``time``, ``acc1``..``acc3``,
    ``control`` (``frame(key)``: as a DataFrame)."""

    def __init__(self, out: dict[str, Any]):
        super().__init__(out["report"])
        self.responses: dict[Any, dict[str, Any]] = {"passive": out["passive"]}
        for design, response in zip(out["report"]["designs"], out["designs"]):
            if response is not None:
                self.responses[design["q"]] = response
        if out["scheduled"] is not None:
            self.responses["scheduled"] = out["scheduled"]

    def frame(self, key: Any = "passive"):
        """One response as a pandas DataFrame."""
        return _frame(self.responses[key])


class RunResult:
    """``twin run``'s recording: ``columns`` (``time`` first, then every output in
    modelDescription order) as numpy arrays; ``start``, ``stop``, ``step``; ``terminated``
    (the component that ended the run and when, or None)."""

    def __init__(self, columns: dict[str, Any], info: dict[str, Any]):
        self.columns = columns
        self.start: float = info["start"]
        self.stop: float = info["stop"]
        self.step: float = info["step"]
        self.terminated: tuple[str, float] | None = info["terminated"]

    def __getitem__(self, name: str) -> Any:
        return self.columns[name]

    def to_frame(self):
        """The recording as a pandas DataFrame (the CLI's ``--output`` CSV)."""
        return _frame(self.columns)

    def __repr__(self) -> str:
        return f"RunResult({len(self.columns) - 1} columns, {len(self.columns['time'])} points)"


def run(model: str | os.PathLike, *, start: float | None = None, stop: float | None = None,
        step: float | None = None, input: str | os.PathLike | Any = None,
        sets: dict[str, float | int | bool | str] | None = None, output_all: bool = False,
        hold_inputs: bool = False, algorithm: str | None = None,
        plot: str | os.PathLike | None = None) -> RunResult:
    """``twin run``: run any FMI 2.0 co-simulation FMU (``.fmu``) or SSP system (``.ssp``) and
    record its outputs. ``input``: a CSV path or a DataFrame (``time``, then columns named like
    the model's inputs, or ``component.variable`` in a system); ``sets``: start values by name;
    ``algorithm``: "gauss-seidel" (default) or "jacobi". None: the model's DefaultExperiment,
    then fmpy's rules, as the CLI."""
    scratch = None
    if input is not None and not isinstance(input, (str, _os.PathLike)):
        import tempfile

        scratch = tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False)
        input.to_csv(scratch, index=False)
        scratch.close()
        input = scratch.name
    try:
        columns, info = _native.run(_os.fspath(model), start=start, stop=stop, step=step,
                                    input=_path(input), sets=sets, output_all=output_all,
                                    hold_inputs=hold_inputs, algorithm=algorithm, plot=_path(plot))
    finally:
        if scratch is not None:
            _os.unlink(scratch.name)
    return RunResult(columns, info)


def pack_fmu(model_description: str | os.PathLike, library: str | os.PathLike, out: str | os.PathLike, *,
             documentation: str | os.PathLike | None = None, resources: str | os.PathLike | None = None) -> str:
    """``twin pack-fmu``: a built FMU library and its modelDescription.xml into a ``.fmu``
    archive. Returns the modelIdentifier."""
    return _native.pack_fmu(_os.fspath(model_description), _os.fspath(library), _os.fspath(out),
                            documentation=_path(documentation), resources=_path(resources))


def read_frf(path: str | os.PathLike) -> dict[str, Any]:
    """A measured FRF as ``twin calibrate --frf`` reads it (CSV ``frequency`` and per channel
    ``<channel>_re``/``_im`` or ``_db``, units in brackets; or a universal file's dataset 58):
    ``{"path", "frequency": array (Hz), "channels": {"acc1": array, ...}}``, each channel
    complex (SI per unit excitation) or, for a magnitude-only file, in dB."""
    return _native.read_frf(_os.fspath(path))


def identify_modes(records: Record | Sequence[Record]) -> Report:
    """``twin modal --data RUN1 --data RUN2 …``: the modes of a record, or of several runs of one
    test, as the CLI identifies them — LSCF through the measured force (the ``input_output``
    method, its band the one the force excites), SSI-COV from the responses alone (``ssi``),
    FDD/EFDD (``fdd``) and the methods' verdicts side by side (``verdicts``); each method's
    ``modes`` (frequency Hz, damping ratio, each with its sd; ``displacement_shape`` per floor of
    ``floors``) and the modes it set aside with the reason (``rejected``).

    Several runs: runs that share their response channels average together; runs that each
    measured other floors, all with the same measured force (a roving accelerometer), merge
    into one set of modes with shapes at every floor any run measured (PoSER style: the force
    is every run's reference, each run's pole refined in the time domain, each floor's shape
    component its run's residue at the mean pole). ``DataError`` when the runs cannot be one
    test (another sampling rate, a roving set without a measured force)."""
    runs = [records] if isinstance(records, Record) else list(records)
    return Report(_native.identify_modes(runs))


def export_fmus(out: str | os.PathLike) -> list[str]:
    """``twin export-fmus``: write the FMUs built into the package (shear, GP corrector, LQR,
    substructure) as ``out/<modelIdentifier>.fmu``, for other FMI tools; returns their paths."""
    return [str(p) for p in _native.export_fmus(_os.fspath(out))]


def _json_argument(value: Any, name: str) -> tuple[str | None, str]:
    """A JSON argument given as a dict or as the path of a JSON file: its text and its origin."""
    if value is None:
        return None, f"{name}="
    if isinstance(value, (str, _os.PathLike)):
        path = _os.fspath(value)
        with open(path, encoding="utf-8") as f:
            return f.read(), path
    return _json.dumps(value), f"{name}="


def init(out: str | os.PathLike | None = None, *, storeys: int | None = None,
         excitation: str | None = None, nominal: Any = None, priors: Any = None) -> Twin:
    """``twin init``: the twin of a shear building — ``storeys`` (1 to 50), ``excitation``
    (``"force:K"`` or ``"base"``), ``nominal`` (``{"m": [...], "c": [...], "k": [...]}``, SI, or
    the path of such a file) and ``priors`` (``--priors``'s JSON as a dict or a path), none of
    them: the default twin. Written to ``out`` as an SSP archive when given; returns it."""
    nominal_text, nominal_origin = _json_argument(nominal, "nominal")
    priors_text, priors_origin = _json_argument(priors, "priors")
    twin = Twin(_native.Twin.init(storeys, excitation, nominal_text, nominal_origin,
                                  priors_text, priors_origin))
    if out is not None:
        twin.save(_os.fspath(out))
    return twin


def record_from_frame(frame: Any, name: str = "<DataFrame>", *,
                      columns: dict[str, str] | str | os.PathLike | None = None) -> Record:
    """A record from a pandas DataFrame whose column names are a CSV header's (``time``,
    ``force`` or ``ground_acc``, ``acc<i>``/``vel<i>``/``disp<i>``, units as ``"acc2 (g)"``,
    ``control``; ``columns`` maps other names, as ``twin --columns``), checked as a CSV file
    is."""
    import numpy as np

    arrays = {str(c): np.ascontiguousarray(frame[c].to_numpy(dtype=np.float64))
              for c in frame.columns}
    if isinstance(columns, _os.PathLike):
        columns = _os.fspath(columns)
    return Record.from_arrays(arrays, columns=columns, name=name)


def synth(scenario: dict[str, Any], out: str | os.PathLike | None = None, *,
          controller: str | os.PathLike | Report | dict | None = None,
          controller_q: float | None = None) -> tuple[Record, dict[str, Any]]:
    """``twin synth``: a synthetic record of the frame (``scenario``: the scenario JSON as a
    dict, every field optional — the CLI's flags are its fields) and its truth (the hidden
    effects: the ``--truth`` file). ``out``: also write the record there. ``controller``: a
    ``twin control`` report whose design ``controller_q`` (default the first stable one) runs in
    the structure's loop; the record gets a ``control`` column."""
    return _native.synth(scenario, _path(out), controller=_report_or_path(controller),
                         controller_q=controller_q)

del TYPE_CHECKING, annotations  # the API alone: no helper of the implementation
