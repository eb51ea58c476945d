//! `Twin`: a twin (an SSP archive around the shear FMU) and the CLI's operations on it —
//! compare, calibrate, diagnose, add physics, control, watch — each with the GIL released.

mod control;

use std::path::PathBuf;

use numpy::PyArray1;
use orchestrator::cosim::import::Fmu;
use orchestrator::record::frf::{FrfValues, MeasuredFrf};
use orchestrator::record::ColumnMap;
use orchestrator::record::DataError;
use orchestrator::twin::data::Measurement;
use orchestrator::twin::{ParameterValue, RecordRef, RecordRole, Twin as CoreTwin};
use orchestrator::workflows::calibrate::validated::check_plot;
use orchestrator::workflows::calibrate::{
    calibrate_validated, default_parameters, priors_from_json, CalibrationSetup,
};
use orchestrator::workflows::compare::{compare, CompareOptions};
use orchestrator::workflows::control::closed_loop::{Gap, Response};
use orchestrator::workflows::control::ControllerSpec;
use orchestrator::workflows::diagnose::{
    add_hybrid_contact, add_physics, diagnose, effects_from_report, parse_additions,
    parse_candidates, with_record, DiagnoseOptions,
};
use orchestrator::workflows::learn::{
    chosen_modes, learned_twin, prepare, run_modes, LearnOptions,
};
use orchestrator::workflows::options::check_svg;
use orchestrator::workflows::train::{train_selected, LagSelection, TrainOptions};
use orchestrator::workflows::watch::background::DiagnosisOptions;
use orchestrator::workflows::watch::{watch_with_alerts, StreamSource, WatchError, WatchOptions};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::record::Record;
use crate::{choice, detached, invalid, to_object, to_py, Kind};
use control::{control_and_write, control_result, design_options, schedule_options};

/// A twin: the shear FMU (and a GP corrector, when trained) with its parameters, noise
/// variances and calibration, as an SSP archive. Open one with `Twin.open(path)`; every
/// operation leaves it as it is and returns a new twin where the CLI writes one.
#[pyclass(module = "shear_twin._native", frozen)]
pub struct Twin {
    pub(crate) twin: CoreTwin,
}

impl Twin {
    /// Keep every component's FMU library loaded for as long as this twin lives, so the runs
    /// of a worker that holds the twin open it from memory (dlopen of a loaded library) rather
    /// than from the file again.
    fn holding_fmus(mut twin: CoreTwin) -> Result<Self, anyhow::Error> {
        let paths: Vec<PathBuf> = twin.components.iter().map(|c| c.fmu_path.clone()).collect();
        for path in paths {
            let fmu = Fmu::open(&path)?;
            twin.keep_alive(std::sync::Arc::new(fmu));
        }
        Ok(Twin { twin })
    }
}

impl Twin {
    /// `add_physics(hybrid=…)`: the contact law a `twin hybrid run` report identified at its
    /// interface, held as identified, and the structure refitted over `record` (when given) and
    /// `others`, as `twin add-physics --hybrid`.
    fn add_hybrid<'py>(
        &self,
        py: Python<'py>,
        record: Option<&Record>,
        others: &[Measurement],
        report: &std::path::Path,
        options: &DiagnoseOptions,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        let kind = Kind::Diagnose;
        let data = record.map(|r| r.for_twin(&self.twin)).transpose()?;
        let all: Vec<&Measurement> = match data {
            Some(d) => with_record(d, others).0,
            None => others.iter().collect(),
        };
        if all.is_empty() {
            return Err(invalid(
                kind,
                "no record to refit the structure over: the twin remembers none; give record \
                 or records",
            ));
        }
        new_twin_and_report(py, kind, || {
            add_hybrid_contact(&self.twin, report, &all, options)
        })
    }
}

/// `work` run with the GIL released, its new twin holding its FMUs and its report as a
/// Python object (the CLI's JSON); its error as `kind`'s exception.
fn new_twin_and_report<'py, R: serde::Serialize, E: Into<anyhow::Error>>(
    py: Python<'py>,
    kind: Kind,
    work: impl FnOnce() -> Result<(CoreTwin, R), E> + Send,
) -> PyResult<(Twin, Bound<'py, PyAny>)> {
    let (new_twin, report) = detached(py, || {
        let (new_twin, report) = work().map_err(|e| to_py(kind, e))?;
        let report = serde_json::to_value(&report).map_err(|e| to_py(kind, e))?;
        Ok((
            Twin::holding_fmus(new_twin).map_err(|e| to_py(kind, e))?,
            report,
        ))
    })?;
    Ok((new_twin, to_object(py, &report)?))
}

/// A measured FRF file as the CLI reads it (`twin calibrate --frf`, `twin modal --frf`).
pub(crate) fn read_measured_frf(path: &std::path::Path) -> Result<MeasuredFrf, DataError> {
    MeasuredFrf::read(path, &ColumnMap::default())
}

/// A measured FRF: `{"path", "frequency": array (Hz), "channels": {name: array}}`, each
/// channel's values complex (SI per unit excitation) or, for a magnitude-only file, its dB.
#[pyfunction]
pub fn read_frf<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let frf = read_measured_frf(&path).map_err(|e| to_py(Kind::Data, e))?;
    let out = PyDict::new(py);
    out.set_item("path", frf.path.display().to_string())?;
    out.set_item("frequency", floats(py, &frf.frequency))?;
    let channels = PyDict::new(py);
    for c in &frf.channels {
        match &c.values {
            FrfValues::Complex(h) => {
                channels.set_item(c.channel.name(), PyArray1::from_slice(py, h))?
            }
            FrfValues::Db(db) => channels.set_item(c.channel.name(), floats(py, db))?,
        }
    }
    out.set_item("channels", channels)?;
    Ok(out)
}

fn floats<'py>(py: Python<'py>, values: &[f64]) -> Bound<'py, PyAny> {
    PyArray1::from_slice(py, values).into_any()
}

/// A closed-loop response as numpy arrays: `time`, `acc1`.., `control`.
fn response<'py>(py: Python<'py>, r: &Response) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("time", floats(py, &r.time))?;
    for (f, acc) in r.acc.iter().enumerate() {
        d.set_item(format!("acc{}", f + 1), floats(py, acc))?;
    }
    d.set_item("control", floats(py, &r.control))?;
    Ok(d)
}

/// A `twin control` report given as a path, or as the report itself (a dict).
pub(crate) fn controller_spec(kind: Kind, value: &Bound<'_, PyAny>) -> PyResult<ControllerSpec> {
    if let Ok(path) = value.extract::<PathBuf>() {
        return ControllerSpec::load(&path).map_err(|e| to_py(kind, e));
    }
    let json: serde_json::Value =
        pythonize::depythonize(value).map_err(|e| invalid(kind, e.to_string()))?;
    ControllerSpec::from_json(&json.to_string(), "the controller report")
        .map_err(|e| to_py(kind, e))
}

#[pymethods]
impl Twin {
    /// Open a twin archive (`.ssp`), as `twin ... --twin PATH` does.
    #[staticmethod]
    fn open(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        detached(py, || {
            let twin = CoreTwin::load(Some(&path)).map_err(|e| to_py(Kind::Twin, e))?;
            Twin::holding_fmus(twin).map_err(|e| to_py(Kind::Twin, e))
        })
    }

    /// The default twin (the shear FMU with its default parameters), `twin init`'s.
    #[staticmethod]
    fn default(py: Python<'_>) -> PyResult<Self> {
        detached(py, || {
            let twin = CoreTwin::load(None).map_err(|e| to_py(Kind::Twin, e))?;
            Twin::holding_fmus(twin).map_err(|e| to_py(Kind::Twin, e))
        })
    }

    /// The twin of a shear building, `twin init`'s: `storeys`, `excitation` ("force:K" or
    /// "base"), the nominal structure and the priors as JSON texts (`*_origin` names them in a
    /// refusal); none of them: the default twin.
    #[staticmethod]
    #[pyo3(signature = (storeys=None, excitation=None, nominal=None, nominal_origin=String::from("nominal="), priors=None, priors_origin=String::from("priors=")))]
    fn init(
        py: Python<'_>,
        storeys: Option<usize>,
        excitation: Option<String>,
        nominal: Option<String>,
        nominal_origin: String,
        priors: Option<String>,
        priors_origin: String,
    ) -> PyResult<Self> {
        use orchestrator::twin::structure::{InitOptions, Nominal};
        use orchestrator::workflows::init::InitRequest;
        detached(py, || {
            let excitation = excitation
                .map(|e| {
                    structure::Excitation::parse(&e).map_err(|err| {
                        to_py(Kind::Twin, anyhow::anyhow!("excitation={e:?}: {err}"))
                    })
                })
                .transpose()?;
            let nominal = nominal
                .map(|text| {
                    let origin = PathBuf::from(&nominal_origin);
                    Nominal::from_json(&text, &origin)
                        .map(|n| (origin, n))
                        .map_err(|e| to_py(Kind::Twin, e))
                })
                .transpose()?;
            let request = InitRequest {
                structure: InitOptions {
                    storeys,
                    excitation,
                    nominal,
                },
                priors: priors.map(|text| (priors_origin, text)),
            };
            let twin = request.twin().map_err(|e| to_py(Kind::Twin, e))?;
            Twin::holding_fmus(twin).map_err(|e| to_py(Kind::Twin, e))
        })
    }

    /// Write the twin as an SSP archive.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || {
            self.twin.write(&path).map_err(|e| to_py(Kind::Twin, e))
        })
    }

    /// Where the twin was read from (None for one made in memory).
    #[getter]
    fn path(&self) -> Option<String> {
        self.twin.source.as_ref().map(|p| p.display().to_string())
    }

    /// The twin's parameters by component: `{"physics": {"k2": 4300.0, ...}}`.
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        for c in &self.twin.components {
            let d = PyDict::new(py);
            for (name, value) in &c.parameters {
                match value {
                    ParameterValue::Real(x) => d.set_item(name, x)?,
                    ParameterValue::Integer(i) => d.set_item(name, i)?,
                    ParameterValue::Boolean(b) => d.set_item(name, b)?,
                }
            }
            out.set_item(&c.name, d)?;
        }
        Ok(out)
    }

    /// The calibrated sensor-noise variance per measured channel (its SI unit squared), by
    /// channel name; None until calibrated.
    #[getter]
    fn noise_variance(&self) -> Option<std::collections::BTreeMap<String, f64>> {
        self.twin
            .noise_variance
            .as_ref()
            .map(|n| n.iter().map(|(c, v)| (c.name(), v)).collect())
    }

    fn __repr__(&self) -> String {
        format!("Twin({})", self.twin.describe())
    }

    /// `twin compare`: run the twin on the record's excitation (in a closed loop with a `twin
    /// control` report's controller when `controller` is given), compare with every measured
    /// channel. Returns `{"report": <the CLI's JSON report>, "predictions": {"time", each
    /// measured channel by name [, "latent_var1".., "sd1"..]: arrays}}`.
    #[pyo3(signature = (record, *, transient = None, tolerance = None, controller = None,
                        controller_q = None, plot = None, frf = false, latent_threshold = None,
                        modes = false))]
    #[allow(clippy::too_many_arguments)]
    fn compare<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        transient: Option<f64>,
        tolerance: Option<f64>,
        controller: Option<&Bound<'py, PyAny>>,
        controller_q: Option<f64>,
        plot: Option<PathBuf>,
        frf: bool,
        latent_threshold: Option<f64>,
        modes: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let kind = Kind::Twin;
        if let Some(path) = &plot {
            check_svg(path).map_err(|e| to_py(kind, e))?;
        }
        let defaults = CompareOptions::default();
        let options = CompareOptions {
            transient: transient.unwrap_or(defaults.transient),
            tolerance,
            controller_q,
            latent_threshold,
        };
        options.validate().map_err(|e| to_py(kind, e))?;
        let data = record.for_twin(&self.twin)?;
        options.validate_for(data).map_err(|e| to_py(kind, e))?;
        let spec = controller.map(|c| controller_spec(kind, c)).transpose()?;
        let (compared, modes) = detached(py, || {
            let compared = compare(&self.twin, data, &options, spec.as_ref(), |_, _| {})
                .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let view = orchestrator::workflows::compare::compare_plot(
                    &self.twin, data, &compared, &options, frf,
                )
                .map_err(|message| {
                    to_py(
                        kind,
                        orchestrator::report::ReportError::BadInput {
                            path: path.clone(),
                            message,
                        },
                    )
                })?;
                orchestrator::report::plot_compared(
                    &compared.comparison,
                    &data.excitation.channel,
                    &view,
                    path,
                )
                .map_err(|e| to_py(kind, e))?;
            }
            let modes = modes.then(|| {
                orchestrator::workflows::modal::modal_evidence(
                    &self.twin,
                    data,
                    orchestrator::workflows::modal::ModalBand::default(),
                )
            });
            Ok((compared, modes))
        })?;
        // The same report as `twin compare --report [--modes]`.
        let report = orchestrator::report::json::compare(
            &self.twin,
            data,
            &compared,
            options.transient,
            modes.as_ref(),
        );
        let prediction = compared.prediction;
        let predictions = PyDict::new(py);
        predictions.set_item("time", floats(py, &prediction.time))?;
        for c in &prediction.channels {
            predictions.set_item(c.channel.name(), floats(py, &c.values))?;
        }
        for prefix in ["latent_var", "sd"] {
            for c in &prediction.channels {
                let band = if prefix == "sd" { &c.sd } else { &c.latent_var };
                let name = c.channel.name();
                if let (Some(values), Some(floor)) = (band, name.strip_prefix("acc")) {
                    predictions.set_item(format!("{prefix}{floor}"), floats(py, values))?;
                }
            }
        }
        let out = PyDict::new(py);
        out.set_item("report", to_object(py, &report)?)?;
        out.set_item("predictions", predictions)?;
        Ok(out)
    }

    /// `twin calibrate`: MAP calibration of `parameters` (default every floor's mass and storey's
    /// damping and stiffness, m1..mN, c1..cN, k1..kN) and the noise variances on the record, or
    /// on a list of records (runs: one MAP over all, each run its own channels and noise
    /// variances); `priors` overrides the twin's and the default priors, in `twin calibrate
    /// --priors`' format (`{"k": {"relative_sd": 0.3}, "k1": {"space": "linear", "mean": 4021,
    /// "variance": 10000}}`); `validate` records set the twin's tolerance. Returns the
    /// calibrated twin and the CLI's report (this twin is kept as it is).
    #[pyo3(signature = (record, *, parameters = None, priors = None, starts = None, seed = None,
                        transient = None, validate = Vec::new(), threads = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn calibrate<'py>(
        &self,
        py: Python<'py>,
        record: &Bound<'py, PyAny>,
        parameters: Option<Vec<String>>,
        priors: Option<&Bound<'py, PyAny>>,
        starts: Option<usize>,
        seed: Option<u64>,
        transient: Option<f64>,
        validate: Vec<PyRef<'py, Record>>,
        threads: Option<usize>,
        plot: Option<PathBuf>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        let kind = Kind::Calibrate;
        if let Some(path) = &plot {
            check_svg(path).map_err(|e| to_py(kind, e))?;
        }
        let mut setup = CalibrationSetup {
            parameters: default_parameters(&self.twin).map_err(|e| to_py(kind, e))?,
            ..CalibrationSetup::default()
        };
        if let Some(p) = parameters {
            setup.parameters = p;
        }
        if let Some(priors) = priors {
            let value: serde_json::Value =
                pythonize::depythonize(priors).map_err(|e| invalid(kind, e.to_string()))?;
            setup.prior_spec =
                Some(priors_from_json(&value.to_string(), "priors").map_err(|m| invalid(kind, m))?);
        }
        let runs: Vec<PyRef<'py, Record>> = match record.extract::<PyRef<'py, Record>>() {
            Ok(one) => vec![one],
            Err(_) => record
                .extract()
                .map_err(|_| invalid(kind, "record: a Record or a list of Records".to_owned()))?,
        };
        if runs.is_empty() {
            return Err(invalid(kind, "record: an empty list".to_owned()));
        }
        setup.starts = starts.unwrap_or(setup.starts);
        setup.seed = seed.unwrap_or(setup.seed);
        setup.transient = transient.unwrap_or(setup.transient);
        setup.threads = threads.unwrap_or(setup.threads);
        let data_runs: Vec<&Measurement> = runs.iter().map(|r| &r.measurement).collect();
        let data = data_runs[0];
        for d in &data_runs {
            setup.validate(d).map_err(|e| to_py(kind, e))?;
        }
        if plot.is_some() {
            check_plot(&self.twin, &data_runs).map_err(|e| to_py(kind, e))?;
        }
        let validation: Vec<&Measurement> = validate.iter().map(|r| &r.measurement).collect();
        let (new_twin, report) = detached(py, || {
            let v = calibrate_validated(&self.twin, &data_runs, &validation, &setup)
                .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let comparison = orchestrator::twin::run::run_and_compare(
                    &v.twin,
                    data,
                    setup.transient,
                    |_, _| {},
                )
                .map_err(|e| to_py(kind, e))?
                .comparison;
                orchestrator::report::plot_calibrated(&comparison, data, path)
                    .map_err(|e| to_py(kind, e))?;
            }
            // `twin calibrate --report`'s fields, less `out` (nothing is written here).
            let report = orchestrator::report::json::calibrate(
                &self.twin,
                &v.twin,
                None,
                data,
                setup.transient,
                &v.calibration,
                &v.validated,
            );
            // The records read from files, for `add_physics` to refit over, as `twin
            // calibrate` stores them (records made from arrays have no file to name).
            let mut calibrated = v.twin;
            let roles = data_runs
                .iter()
                .map(|m| (*m, RecordRole::Calibration))
                .chain(validation.iter().map(|m| (*m, RecordRole::Validation)));
            let mut stored = Vec::new();
            for (m, role) in roles {
                if m.path.is_file() {
                    stored.push(RecordRef::of(&m.path, role).map_err(|e| to_py(kind, e))?);
                }
            }
            calibrated.records = stored;
            let new_twin = Twin::holding_fmus(calibrated).map_err(|e| to_py(kind, e))?;
            Ok((new_twin, report))
        })?;
        Ok((new_twin, to_object(py, &report)?))
    }

    /// `twin diagnose`: none, recalibrate, add physics, sensor fault or update the data-based
    /// model, with the evidence. Returns the CLI's JSON report as a dict. `effects` limits the
    /// candidates (`["contact@2-3", "cubic@2"]`).
    #[pyo3(signature = (record, *, effects = None, transient = None, tolerance = None,
                        threads = None, block = None, always_fit = false, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn diagnose<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        effects: Option<Vec<String>>,
        transient: Option<f64>,
        tolerance: Option<f64>,
        threads: Option<usize>,
        block: Option<f64>,
        always_fit: bool,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Diagnose;
        let mut o = DiagnoseOptions {
            tolerance,
            always_fit,
            ..DiagnoseOptions::default()
        };
        o.transient = transient.unwrap_or(o.transient);
        o.threads = threads.unwrap_or(o.threads);
        o.block = block.unwrap_or(o.block);
        let data = record.for_twin(&self.twin)?;
        o.validate_for(data).map_err(|e| to_py(kind, e))?;
        if let Some(effects) = effects {
            o.candidates = Some(parse_candidates(&effects).map_err(|e| to_py(kind, e))?);
        }
        let d = detached(py, || {
            let d = diagnose(&self.twin, data, &o).map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let svg = orchestrator::report::diagnose_plot::draw_diagnosis(&d)
                    .map_err(|e| to_py(kind, e))?;
                orchestrator::fsutil::write_text_atomically(path, &svg)
                    .map_err(|e| to_py(kind, e))?;
            }
            Ok(d)
        })?;
        to_object(py, &d)
    }

    /// `twin diagnose` on an ambient record (a CSV of the responses alone, no excitation
    /// column; one it has is left out): the record's modes identified output-only (SSI-COV)
    /// against the twin's band, `none` or `recalibrate` with the single floor mass or storey
    /// stiffness that explains the frequencies best. Returns the CLI's JSON report as a dict;
    /// `plot` an SVG of the shapes, the twin's and the record's.
    #[pyo3(signature = (path, *, plot = None))]
    fn diagnose_ambient<'py>(
        &self,
        py: Python<'py>,
        path: PathBuf,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Diagnose;
        if let Some(p) = &plot {
            check_svg(p).map_err(|e| to_py(kind, e))?;
        }
        let d = detached(py, || {
            let record = orchestrator::record::AmbientRecord::read(
                &path,
                &orchestrator::record::ReadOptions::default(),
            )
            .map_err(|e| to_py(Kind::Data, e))?;
            let d = orchestrator::workflows::diagnose::diagnose_ambient(
                &self.twin,
                &record,
                orchestrator::workflows::modal::ModalBand::default(),
            )
            .map_err(|e| to_py(kind, e))?;
            if let Some(p) = &plot {
                let svg =
                    orchestrator::report::mode_plot::draw_ambient_diagnosis(&d).map_err(|m| {
                        to_py(kind, anyhow::anyhow!("cannot draw {}: {m}", p.display()))
                    })?;
                orchestrator::fsutil::write_text_atomically(p, &svg).map_err(|e| to_py(kind, e))?;
            }
            Ok(d)
        })?;
        to_object(py, &d)
    }

    /// `twin modal`: the twin's natural frequencies (Hz), damping ratios and mode shapes (floors
    /// 1..N), each with its sd from the calibration's posterior and the sds of `samples` draws
    /// from it beside (0: no sampling check); `plot` an SVG of the shapes along the height.
    #[pyo3(signature = (*, samples = None, plot = None))]
    fn modes<'py>(
        &self,
        py: Python<'py>,
        samples: Option<usize>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Twin;
        if let Some(path) = &plot {
            orchestrator::workflows::options::check_svg(path).map_err(|e| to_py(kind, e))?;
        }
        let mut options = orchestrator::workflows::modal::ModalOptions::default();
        options.samples = samples.unwrap_or(options.samples);
        let modes = detached(py, || {
            let modes = orchestrator::workflows::modal::twin_modes(&self.twin, &options)
                .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                orchestrator::report::mode_plot::plot_mode_shapes(&modes, None, path)
                    .map_err(|e| to_py(kind, e))?;
            }
            Ok(modes)
        })?;
        to_object(py, &modes)
    }

    /// `twin add-physics`: switch effects on (`effects=["contact@2-3"]`, or all of a
    /// `diagnosis` report's), estimate them on the record, then refit them jointly with the
    /// structure over the record and `records` (default: the records the twin remembers from
    /// `twin calibrate`). `refine` is accepted and ignored, as in the CLI. Returns the new twin
    /// and the report (NMSE per record before and after).
    #[pyo3(signature = (record = None, *, effects = None, diagnosis = None, hybrid = None,
                        refine = false, transient = None, threads = None, records = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_physics<'py>(
        &self,
        py: Python<'py>,
        record: Option<&Record>,
        effects: Option<Vec<String>>,
        diagnosis: Option<&Bound<'py, PyAny>>,
        hybrid: Option<PathBuf>,
        refine: bool,
        transient: Option<f64>,
        threads: Option<usize>,
        records: Option<Vec<PyRef<'py, Record>>>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        let kind = Kind::Diagnose;
        let mut o = DiagnoseOptions::default();
        o.transient = transient.unwrap_or(o.transient);
        o.threads = threads.unwrap_or(o.threads);
        o.validate().map_err(|e| to_py(kind, e))?;
        let _ = refine;
        let others: Vec<orchestrator::twin::data::Measurement> = match records {
            Some(given) => given
                .iter()
                .map(|r| r.for_twin(&self.twin).cloned())
                .collect::<PyResult<_>>()?,
            None => self.twin.load_records().map_err(|e| to_py(kind, e))?,
        };
        if let Some(report) = hybrid {
            if effects.is_some() || diagnosis.is_some() {
                return Err(invalid(
                    kind,
                    "hybrid: the contact law comes from the hybrid test's report; give no \
                     effects or diagnosis with it",
                ));
            }
            return self.add_hybrid(py, record, &others, &report, &o);
        }
        let Some(record) = record else {
            return Err(invalid(
                kind,
                "record: the new record the effects are estimated on",
            ));
        };
        let candidates = match (effects, diagnosis) {
            (Some(_), Some(_)) => {
                return Err(invalid(kind, "give effects or a diagnosis, not both"));
            }
            (Some(effects), None) => {
                parse_additions(&effects).map_err(|e| invalid(kind, e.to_string()))?
            }
            (None, Some(report)) => {
                // The report as the CLI reads it: through the same file reader.
                let value: serde_json::Value =
                    pythonize::depythonize(report).map_err(|e| invalid(kind, e.to_string()))?;
                let file = tempfile::Builder::new()
                    .suffix(".json")
                    .tempfile()
                    .map_err(|e| to_py(kind, e))?;
                serde_json::to_writer(file.as_file(), &value).map_err(|e| to_py(kind, e))?;
                let path = file.path().to_path_buf();
                let (candidates, _) = effects_from_report(&path).map_err(|e| {
                    // Name the argument, not the temporary file.
                    invalid(
                        kind,
                        format!("{:#}", anyhow::Error::from(e))
                            .replace(&path.display().to_string(), "the diagnosis"),
                    )
                })?;
                candidates
            }
            (None, None) => return Err(invalid(kind, "give effects or a diagnosis")),
        };
        let data = record.for_twin(&self.twin)?;
        new_twin_and_report(py, kind, || {
            add_physics(&self.twin, data, &others, &candidates, &o)
        })
    }

    /// `twin calibrate --frf`: MAP calibration on a measured FRF (a CSV `frequency,
    /// acc1_re, acc1_im, …` or a universal file's dataset 58), of `parameters` (default every
    /// floor's mass and storey's damping and stiffness) under `priors` (as `calibrate`'s), over
    /// the `band` (Hz, `(lo, hi)`; default every line above 0 Hz); `gain_offset` fits a dB
    /// offset when the file's dB reference is unknown. Returns the calibrated twin and the
    /// CLI's report.
    #[pyo3(signature = (frf, *, parameters = None, priors = None, band = None,
                        gain_offset = false, starts = None, seed = None))]
    #[allow(clippy::too_many_arguments)]
    fn calibrate_frf<'py>(
        &self,
        py: Python<'py>,
        frf: PathBuf,
        parameters: Option<Vec<String>>,
        priors: Option<&Bound<'py, PyAny>>,
        band: Option<(f64, f64)>,
        gain_offset: bool,
        starts: Option<usize>,
        seed: Option<u64>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        use orchestrator::workflows::calibrate::frf::{calibrate_frf, FrfSetup};
        let kind = Kind::Calibrate;
        let measured = read_measured_frf(&frf).map_err(|e| to_py(kind, e))?;
        if let Some((lo, hi)) = band {
            if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
                return Err(invalid(
                    kind,
                    format!("band: ({lo}, {hi}) is not 0 <= lo < hi Hz"),
                ));
            }
        }
        let defaults = FrfSetup::default();
        let setup = FrfSetup {
            parameters: parameters.unwrap_or(defaults.parameters),
            prior_spec: match priors {
                Some(priors) => {
                    let value: serde_json::Value =
                        pythonize::depythonize(priors).map_err(|e| invalid(kind, e.to_string()))?;
                    Some(
                        priors_from_json(&value.to_string(), "priors")
                            .map_err(|m| invalid(kind, m))?,
                    )
                }
                None => None,
            },
            band,
            gain_offset,
            starts: starts.unwrap_or(defaults.starts),
            seed: seed.unwrap_or(defaults.seed),
        };
        new_twin_and_report(py, kind, || calibrate_frf(&self.twin, &measured, &setup))
    }

    /// `twin control`: LQR designs (one per `q`) on the twin's structure, run in the loop on
    /// the record's force, passive and under each design; `retune`, `schedule` as the CLI's;
    /// `ssp`: also write the controlled system as an SSP archive. Returns `{"report": <the
    /// CLI's JSON report>, "passive": {...}, "designs": [{...} or None], "scheduled": {...} or
    /// None}`, each response as arrays `time`, `acc1`.., `control`.
    #[pyo3(signature = (record, q, *, r = None, state_unit = None, estimator = None,
                        highpass = None, substeps = None, sensor_noise = None, seed = None,
                        gaps = Vec::new(), retune = false, target_contacts = None,
                        max_force = None, schedule = false, margin = None, lookahead = None,
                        dwell = None, variance_threshold = None, estimator_costs = false,
                        actuator_floor = None, ssp = None, ssp_q = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn control<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        q: Vec<f64>,
        r: Option<f64>,
        state_unit: Option<&str>,
        estimator: Option<&str>,
        highpass: Option<f64>,
        substeps: Option<usize>,
        sensor_noise: Option<f64>,
        seed: Option<u64>,
        gaps: Vec<String>,
        retune: bool,
        target_contacts: Option<usize>,
        max_force: Option<f64>,
        schedule: bool,
        margin: Option<f64>,
        lookahead: Option<f64>,
        dwell: Option<f64>,
        variance_threshold: Option<&str>,
        estimator_costs: bool,
        actuator_floor: Option<usize>,
        ssp: Option<PathBuf>,
        ssp_q: Option<f64>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let kind = Kind::Control;
        if let Some(path) = &plot {
            check_svg(path).map_err(|e| to_py(kind, e))?;
        }
        let err = |e: orchestrator::workflows::options::InvalidOption| to_py(kind, e);
        let mut options = design_options(
            q,
            r,
            state_unit,
            estimator,
            highpass,
            substeps,
            seed,
            (target_contacts, max_force),
            estimator_costs,
            actuator_floor,
        )?;
        options.retune = options.retune.filter(|_| retune);
        options.sensor_noise = orchestrator::workflows::control::sensor_noise(sensor_noise)
            .map_err(err)?
            .0;
        options.gaps = gaps
            .iter()
            .map(|g| Gap::parse(g))
            .collect::<Result<Vec<_>, _>>()
            .map_err(err)?;
        options.schedule =
            schedule_options(schedule, margin, lookahead, dwell, variance_threshold)?;
        let data = record.for_twin(&self.twin)?;
        let outcome = detached(py, || {
            control_and_write(&self.twin, data, &options, sensor_noise, &plot, &ssp, ssp_q)
        })?;
        control_result(py, &outcome)
    }

    /// `twin watch`: the operational twin on a stream — `source` `-` (standard input), a CSV
    /// file (read to its end; `follow`: as it grows until `idle` s pass without a line) or
    /// `mqtt://HOST[:PORT]/TOPIC`. Alerts go to `alerts` as JSON lines (and to TOPIC/alerts
    /// from MQTT); `on_alert(alert: dict)` is called for each one as it is written, with the
    /// GIL (an exception it raises stops the watch and is raised here). The stream's header
    /// names its columns as a record's does (`columns`: a column map, a dict or a MAP.json
    /// path, as `twin watch --columns`). Returns the `end` alert's summary.
    #[pyo3(signature = (source, alerts, *, on_alert = None, columns = None, client_id = None, follow = false,
                        idle = None, checkpoint = None, checkpoint_every = None, window = None,
                        tolerance = None, transient = None, rate = None, diagnosis = true,
                        diagnosis_record = None, diagnosis_after = None,
                        query_threshold = None, learning = true, budget = None,
                        refit_every = None, diagnosis_wait = false, adopt = false))]
    #[allow(clippy::too_many_arguments)]
    fn watch<'py>(
        &self,
        py: Python<'py>,
        source: &Bound<'py, PyAny>,
        alerts: PathBuf,
        on_alert: Option<Py<PyAny>>,
        columns: Option<&Bound<'py, PyAny>>,
        client_id: Option<String>,
        follow: bool,
        idle: Option<f64>,
        checkpoint: Option<PathBuf>,
        checkpoint_every: Option<u64>,
        window: Option<f64>,
        tolerance: Option<f64>,
        transient: Option<f64>,
        rate: Option<f64>,
        diagnosis: bool,
        diagnosis_record: Option<f64>,
        diagnosis_after: Option<f64>,
        query_threshold: Option<f64>,
        learning: bool,
        budget: Option<u32>,
        refit_every: Option<u32>,
        diagnosis_wait: bool,
        adopt: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Watch;
        let err = |e: WatchError| to_py(kind, e);
        let source = source.extract::<PathBuf>()?.display().to_string();
        orchestrator::workflows::options::check_tolerance(tolerance).map_err(|e| to_py(kind, e))?;
        let stream = StreamSource::parse(&source, follow, idle, client_id).map_err(err)?;
        let mut options = WatchOptions::new(stream, alerts);
        options.columns = crate::record::column_map(columns)?;
        let d = DiagnosisOptions::default();
        options.checkpoint = checkpoint;
        options.checkpoint_every = checkpoint_every.unwrap_or(options.checkpoint_every);
        options.window = window.unwrap_or(options.window);
        options.tolerance = tolerance;
        options.transient = transient.unwrap_or(options.transient);
        options.rate = rate;
        options.diagnosis = diagnosis.then_some(DiagnosisOptions {
            record: diagnosis_record.unwrap_or(d.record),
            after: diagnosis_after.unwrap_or(d.after),
            transient: options.transient,
            wait: diagnosis_wait,
            ..d
        });
        options.adopt = adopt;
        options.learning.threshold = query_threshold;
        options.learning.learn = learning;
        options.learning.budget = budget.unwrap_or(options.learning.budget);
        options.learning.refit_every = refit_every.unwrap_or(options.learning.refit_every);
        options.validate().map_err(err)?;
        // The callback's exception, kept to be raised here as it was.
        let mut raised: Option<PyErr> = None;
        let summary = detached(py, || {
            let mut on_alert_fn = |alert: &serde_json::Value| -> Result<(), String> {
                let Some(callback) = &on_alert else {
                    return Ok(());
                };
                Python::attach(|py| {
                    let called = to_object(py, alert).and_then(|a| callback.call1(py, (a,)));
                    called.map(|_| ()).map_err(|e| {
                        let message = e.to_string();
                        raised = Some(e);
                        message
                    })
                })
            };
            let summary = watch_with_alerts(&self.twin, &options, |_| {}, &mut on_alert_fn);
            match summary {
                Ok(s) => serde_json::to_value(&s).map_err(|e| to_py(kind, e)),
                Err(WatchError::Callback(_)) if raised.is_some() => {
                    Err(raised.take().expect("the callback's error"))
                }
                Err(e) => Err(err(e)),
            }
        })?;
        to_object(py, &summary)
    }

    /// `twin train`: the GP bias corrector trained on the record and put behind the physics
    /// (`select_lags`: the lags chosen among these by the marginal likelihood). Returns the
    /// twin with the corrector and the CLI's report (less `out`).
    #[pyo3(signature = (record, *, lags = None, target = None, transient = None, stride = None,
                        select_lags = None, selection_stride = None))]
    #[allow(clippy::too_many_arguments)]
    fn train<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        lags: Option<usize>,
        target: Option<&str>,
        transient: Option<f64>,
        stride: Option<usize>,
        select_lags: Option<Vec<usize>>,
        selection_stride: Option<usize>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        let kind = Kind::Train;
        let d = TrainOptions::default();
        let options = TrainOptions {
            lags: lags.unwrap_or(d.lags),
            target: match target {
                Some(t) => choice::<fmu_gp_corrector::TargetForm>(kind, "target", t)?,
                None => d.target,
            },
            transient: transient.unwrap_or(d.transient),
            stride: stride.unwrap_or(d.stride),
        };
        options.validate().map_err(|e| to_py(kind, e))?;
        let selection = select_lags.map(|candidates| LagSelection {
            candidates,
            stride: selection_stride.unwrap_or(orchestrator::workflows::train::SELECTION_STRIDE),
        });
        if let Some(s) = &selection {
            s.validate().map_err(|e| to_py(kind, e))?;
        }
        let data = record.for_twin(&self.twin)?;
        let (twin, report) = detached(py, || {
            let trained = train_selected(&self.twin, data, &options, selection.as_ref())
                .map_err(|e| to_py(kind, e))?;
            let report = orchestrator::report::json::train(&self.twin, data, None, &trained);
            Ok((
                Twin::holding_fmus(trained.twin).map_err(|e| to_py(kind, e))?,
                report,
            ))
        })?;
        Ok((twin, to_object(py, &report)?))
    }

    /// `twin learn`: stream-based active learning of the GP corrector over `records` (the
    /// paper's Algorithm 1), in `mode` (uniform, fixed, adaptive with `forgetting`) or, with
    /// `all_modes`, the six modes of Table 2 in parallel. Returns the CLI's report and, for one
    /// mode, the twin with the corrector as learned (None for several).
    #[pyo3(signature = (records, *, mode = None, forgetting = None, all_modes = false,
                        threshold = None, lags = None, target = None, transient = None,
                        initial = None, refit_every = None, refit_growth = None,
                        refit_iterations = None, nmse_every = None, change_run = None,
                        out_dir = None))]
    #[allow(clippy::too_many_arguments)]
    fn learn<'py>(
        &self,
        py: Python<'py>,
        records: Vec<PyRef<'py, Record>>,
        mode: Option<&str>,
        forgetting: Option<f64>,
        all_modes: bool,
        threshold: Option<f64>,
        lags: Option<usize>,
        target: Option<&str>,
        transient: Option<f64>,
        initial: Option<usize>,
        refit_every: Option<u32>,
        refit_growth: Option<f64>,
        refit_iterations: Option<u64>,
        nmse_every: Option<usize>,
        change_run: Option<usize>,
        out_dir: Option<PathBuf>,
    ) -> PyResult<(Bound<'py, PyAny>, Option<Twin>)> {
        use orchestrator::workflows::learn::{FORGETTING, MODE};
        let kind = Kind::Train;
        let modes = chosen_modes(
            mode.unwrap_or(MODE),
            forgetting.unwrap_or(FORGETTING),
            all_modes,
        )
        .map_err(|e| to_py(kind, e))?;
        let d = LearnOptions::default();
        let options = LearnOptions {
            lags: lags.unwrap_or(d.lags),
            target: match target {
                Some(t) => choice::<fmu_gp_corrector::TargetForm>(kind, "target", t)?,
                None => d.target,
            },
            transient: transient.unwrap_or(d.transient),
            initial: initial.unwrap_or(d.initial),
            threshold,
            refit_every: refit_every.unwrap_or(d.refit_every),
            refit_growth: refit_growth.unwrap_or(d.refit_growth),
            refit_iterations: refit_iterations.unwrap_or(d.refit_iterations),
            nmse_every: nmse_every.unwrap_or(d.nmse_every).max(1),
            change_run: change_run.unwrap_or(d.change_run),
            ..d
        };
        options.validate().map_err(|e| to_py(kind, e))?;
        if records.is_empty() {
            return Err(invalid(kind, "give at least one record"));
        }
        let data: Vec<Measurement> = records
            .iter()
            .map(|r| r.for_twin(&self.twin).cloned())
            .collect::<PyResult<_>>()?;
        let (report, learned) = detached(py, || {
            let started = std::time::Instant::now();
            let streams = prepare(&self.twin, &data, &options).map_err(|e| to_py(kind, e))?;
            let results = run_modes(&streams, &modes, &options).map_err(|e| to_py(kind, e))?;
            let seconds = started.elapsed().as_secs_f64();
            let names: Vec<String> = data.iter().map(|m| m.path.display().to_string()).collect();
            let report =
                orchestrator::report::json::learn(&self.twin, &names, &options, seconds, &results);
            if let Some(dir) = &out_dir {
                orchestrator::report::learn_plot::write_plots(&results, dir)
                    .map_err(|e| to_py(kind, e))?;
            }
            let learned = match results.as_slice() {
                [one] => Some(
                    learned_twin(&self.twin, one, &options)
                        .map_err(|e| to_py(kind, e))
                        .and_then(|t| Twin::holding_fmus(t).map_err(|e| to_py(kind, e)))?,
                ),
                _ => None,
            };
            Ok((report, learned))
        })?;
        Ok((to_object(py, &report)?, learned))
    }

    /// `twin hybrid threshold`: the simulated real-time hybrid test on this twin's structure —
    /// the peak excitation force at which the bumper above the driven floor first closes, for
    /// each amplitude error `a_err` (default −0.1 to 0.1 by 0.02), the structure (the twin's,
    /// any storey count) cut as `split` says (`--split`: "J" or a name; default the paper's cut
    /// at floor 2, "specimen-floors-2-3" on three storeys). Returns the CLI's report.
    #[pyo3(signature = (*, a_err = None, excitation = None, seed = None, duration = None,
                        sample_rate = None, substeps = None, gap = None,
                        contact_stiffness = None, delay = None, lag = None, compensate = None,
                        energy_factor = None, split = None, coupling = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn hybrid_threshold<'py>(
        &self,
        py: Python<'py>,
        a_err: Option<Vec<f64>>,
        excitation: Option<PathBuf>,
        seed: Option<u64>,
        duration: Option<f64>,
        sample_rate: Option<f64>,
        substeps: Option<u32>,
        gap: Option<f64>,
        contact_stiffness: Option<f64>,
        delay: Option<f64>,
        lag: Option<f64>,
        compensate: Option<usize>,
        energy_factor: Option<f64>,
        split: Option<&str>,
        coupling: Option<&str>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Hybrid;
        let options = hybrid_options(
            excitation,
            seed,
            duration,
            sample_rate,
            substeps,
            gap,
            contact_stiffness,
            delay,
            lag,
            compensate,
            energy_factor,
            split,
            coupling,
        )?;
        let report = detached(py, || {
            let (report, curve, _) = orchestrator::workflows::hybrid::options::threshold(
                &self.twin,
                &options,
                a_err.as_deref(),
            )
            .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let svg = orchestrator::report::hybrid_plot::threshold_svg(&curve)
                    .map_err(|m| invalid(kind, m))?;
                orchestrator::fsutil::write_text_atomically(path, &svg)
                    .map_err(|e| to_py(kind, e))?;
            }
            serde_json::to_value(&report).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &report)
    }

    /// `twin hybrid run`: the simulated real-time hybrid test on this twin's structure at
    /// `peak` N (5) for each amplitude error `a_err` (default 0 and 0.05): contacts, floor 2's
    /// spectrum and harmonics, the contact law identified from the interface measured with
    /// `displacement_noise` (1 µm), `force_noise` (1 mN) and, when the specimen holds floor 2,
    /// its accelerometer's `acceleration_noise` (1 mm/s²). Returns the CLI's report.
    #[pyo3(signature = (*, peak = None, a_err = None, displacement_noise = None,
                        force_noise = None, acceleration_noise = None, excitation = None, seed = None, duration = None,
                        sample_rate = None, substeps = None, gap = None,
                        contact_stiffness = None, delay = None, lag = None, compensate = None,
                        energy_factor = None, split = None, coupling = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn hybrid_run<'py>(
        &self,
        py: Python<'py>,
        peak: Option<f64>,
        a_err: Option<Vec<f64>>,
        displacement_noise: Option<f64>,
        force_noise: Option<f64>,
        acceleration_noise: Option<f64>,
        excitation: Option<PathBuf>,
        seed: Option<u64>,
        duration: Option<f64>,
        sample_rate: Option<f64>,
        substeps: Option<u32>,
        gap: Option<f64>,
        contact_stiffness: Option<f64>,
        delay: Option<f64>,
        lag: Option<f64>,
        compensate: Option<usize>,
        energy_factor: Option<f64>,
        split: Option<&str>,
        coupling: Option<&str>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        use orchestrator::workflows::hybrid::experiment::InterfaceNoise;
        let kind = Kind::Hybrid;
        let options = hybrid_options(
            excitation,
            seed,
            duration,
            sample_rate,
            substeps,
            gap,
            contact_stiffness,
            delay,
            lag,
            compensate,
            energy_factor,
            split,
            coupling,
        )?;
        let d = InterfaceNoise::default();
        let noise = InterfaceNoise {
            displacement: displacement_noise.unwrap_or(d.displacement),
            force: force_noise.unwrap_or(d.force),
            acceleration: acceleration_noise.unwrap_or(d.acceleration),
            seed: options.seed,
        };
        let peak = peak.unwrap_or(orchestrator::workflows::hybrid::options::RUN_PEAK);
        let report = detached(py, || {
            let (report, outcomes, setup) = orchestrator::workflows::hybrid::options::run(
                &self.twin,
                &options,
                peak,
                a_err.as_deref(),
                noise,
            )
            .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let svg = orchestrator::report::hybrid_plot::runs_svg(&outcomes, setup.dt)
                    .map_err(|m| invalid(kind, m))?;
                orchestrator::fsutil::write_text_atomically(path, &svg)
                    .map_err(|e| to_py(kind, e))?;
            }
            serde_json::to_value(&report).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &report)
    }
}

/// `twin hybrid`'s shared options from keyword arguments (None: the library's default).
#[allow(clippy::too_many_arguments)]
fn hybrid_options(
    excitation: Option<PathBuf>,
    seed: Option<u64>,
    duration: Option<f64>,
    sample_rate: Option<f64>,
    substeps: Option<u32>,
    gap: Option<f64>,
    contact_stiffness: Option<f64>,
    delay: Option<f64>,
    lag: Option<f64>,
    compensate: Option<usize>,
    energy_factor: Option<f64>,
    split: Option<&str>,
    coupling: Option<&str>,
) -> PyResult<orchestrator::workflows::hybrid::options::HybridOptions> {
    let d = orchestrator::workflows::hybrid::options::HybridOptions::default();
    Ok(orchestrator::workflows::hybrid::options::HybridOptions {
        excitation,
        seed: seed.unwrap_or(d.seed),
        duration: duration.unwrap_or(d.duration),
        sample_rate: sample_rate.unwrap_or(d.sample_rate),
        substeps: substeps.unwrap_or(d.substeps),
        gap: gap.unwrap_or(d.gap),
        contact_stiffness: contact_stiffness.unwrap_or(d.contact_stiffness),
        delay: delay.unwrap_or(d.delay),
        lag: lag.unwrap_or(d.lag),
        compensate: compensate.or(d.compensate),
        energy_factor: energy_factor.unwrap_or(d.energy_factor),
        storeys: None,
        split: match split {
            Some(text) => Some(
                text.parse()
                    .map_err(|m: String| invalid(Kind::Hybrid, format!("--split: {m}")))?,
            ),
            None => d.split,
        },
        coupling: match coupling {
            Some(c) => choice(Kind::Hybrid, "coupling", c)?,
            None => d.coupling,
        },
    })
}
