//! `Twin`: a twin (an SSP archive around the shear FMU) and the CLI's operations on it —
//! compare, calibrate, diagnose, add physics, control, watch — each with the GIL released.

use std::path::PathBuf;
use std::time::Duration;

use numpy::PyArray1;
use orchestrator::cosim::import::Fmu;
use orchestrator::twin::run::{nmse_on, run_and_compare_with};
use orchestrator::twin::{ParameterValue, Twin as CoreTwin};
use orchestrator::workflows::calibrate::{calibrate, calibrated_twin, CalibrationSetup};
use orchestrator::workflows::control::{run_control, ControlOptions, EstimatorChoice, StateUnit};
use orchestrator::workflows::diagnose::{
    add_physics, diagnose, effects_from_report, Addition, Candidate, DiagnoseOptions,
};
use orchestrator::workflows::watch::background::DiagnosisOptions;
use orchestrator::workflows::watch::supervise::LearnOptions;
use orchestrator::workflows::watch::{watch, StreamSource, WatchOptions};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::record::Record;
use crate::{detached, invalid, to_object, to_py, Kind};

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

fn floats<'py>(py: Python<'py>, values: &[f64]) -> Bound<'py, PyAny> {
    PyArray1::from_slice(py, values).into_any()
}

fn check_tolerance(kind: Kind, tolerance: Option<f64>) -> PyResult<()> {
    match tolerance {
        Some(t) if !(t >= 0.0 && t.is_finite()) => Err(invalid(
            kind,
            format!("--tolerance must be a non-negative NMSE in %, was {t}"),
        )),
        _ => Ok(()),
    }
}

fn check_transient(kind: Kind, transient: f64, record: &Record) -> PyResult<()> {
    let data = &record.measurement;
    if !(transient >= 0.0 && transient.is_finite()) {
        return Err(invalid(
            kind,
            format!("--transient {transient}: must be a non-negative number of seconds"),
        ));
    }
    if transient >= data.duration() {
        return Err(invalid(
            kind,
            format!(
                "--transient {} s leaves nothing of {} ({} s long)",
                transient,
                data.path.display(),
                data.duration()
            ),
        ));
    }
    Ok(())
}

fn diagnose_options(
    transient: f64,
    threads: Option<usize>,
    tolerance: Option<f64>,
) -> PyResult<DiagnoseOptions> {
    let mut o = DiagnoseOptions {
        transient,
        tolerance,
        ..DiagnoseOptions::default()
    };
    if let Some(t) = threads {
        if t == 0 {
            return Err(invalid(Kind::Diagnose, "--threads must be at least 1"));
        }
        o.threads = t;
    }
    Ok(o)
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

    /// The calibrated sensor-noise variance per floor, (m/s²)²; None until calibrated.
    #[getter]
    fn noise_variance(&self) -> Option<[f64; 3]> {
        self.twin.noise_variance
    }

    fn __repr__(&self) -> String {
        format!("Twin({})", self.twin.describe())
    }

    /// `twin compare`: run the twin on the record's force, compare with its accelerations.
    /// Returns `{"report": <the CLI's JSON report>, "predictions": {"time", "acc1".. [,
    /// "latent_var1".., "sd1"..]: arrays}, "residual_sd": ...}`.
    #[pyo3(signature = (record, *, transient = 2.0, tolerance = None))]
    fn compare<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        transient: f64,
        tolerance: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        check_tolerance(Kind::Twin, tolerance)?;
        check_transient(Kind::Twin, transient, record)?;
        let data = &record.measurement;
        let compared = detached(py, || {
            run_and_compare_with(&self.twin, data, transient, tolerance, |_, _| {})
                .map_err(|e| to_py(Kind::Twin, e))
        })?;
        // The same report as `twin compare --report`.
        let report = orchestrator::report::json::compare(&self.twin, data, &compared, transient);
        let prediction = compared.prediction;
        let predictions = PyDict::new(py);
        predictions.set_item("time", floats(py, &prediction.time))?;
        for (f, acc) in prediction.acc.iter().enumerate() {
            predictions.set_item(format!("acc{}", f + 1), floats(py, acc))?;
        }
        for (prefix, triple) in [
            ("latent_var", &prediction.latent_var),
            ("sd", &prediction.sd),
        ] {
            if let Some(values) = triple {
                for (f, column) in values.iter().enumerate() {
                    predictions.set_item(format!("{prefix}{}", f + 1), floats(py, column))?;
                }
            }
        }
        let out = PyDict::new(py);
        out.set_item("report", to_object(py, &report)?)?;
        out.set_item("predictions", predictions)?;
        Ok(out)
    }

    /// `twin calibrate`: MAP calibration of `parameters` (default m1..3, c1..3, k1..3) and the
    /// noise variances on the record; `validate` records set the twin's tolerance. Returns the
    /// calibrated twin and the CLI's report (this twin is kept as it is).
    #[pyo3(signature = (record, *, parameters = None, starts = 12, seed = 1, transient = 2.0,
                        validate = Vec::new(), threads = None))]
    #[allow(clippy::too_many_arguments)]
    fn calibrate<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        parameters: Option<Vec<String>>,
        starts: usize,
        seed: u64,
        transient: f64,
        validate: Vec<PyRef<'py, Record>>,
        threads: Option<usize>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        check_transient(Kind::Calibrate, transient, record)?;
        let mut setup = CalibrationSetup {
            transient,
            starts,
            seed,
            ..CalibrationSetup::default()
        };
        if let Some(p) = parameters {
            setup.parameters = p;
        }
        if let Some(t) = threads {
            if t == 0 {
                return Err(invalid(Kind::Calibrate, "threads must be at least 1"));
            }
            setup.threads = t;
        }
        let data = &record.measurement;
        let validation: Vec<&orchestrator::twin::data::Measurement> =
            validate.iter().map(|r| &r.measurement).collect();
        let (new_twin, report) = detached(py, || {
            let kind = Kind::Calibrate;
            let calibration = calibrate(&self.twin, data, &setup).map_err(|e| to_py(kind, e))?;
            let mut new_twin =
                calibrated_twin(&self.twin, &calibration).map_err(|e| to_py(kind, e))?;
            let mut validated = Vec::new();
            for v in &validation {
                let nmse = nmse_on(&new_twin, v, transient).map_err(|e| to_py(kind, e))?;
                validated.push((v.path.display().to_string(), nmse));
            }
            new_twin.validation_nmse = orchestrator::report::json::validation_nmse(&validated);
            // `twin calibrate --report`'s fields, less `out` (nothing is written here).
            let report = orchestrator::report::json::calibrate(
                &self.twin,
                &new_twin,
                None,
                data,
                transient,
                &calibration,
                &validated,
            );
            let new_twin = Twin::holding_fmus(new_twin).map_err(|e| to_py(kind, e))?;
            Ok((new_twin, report))
        })?;
        Ok((new_twin, to_object(py, &report)?))
    }

    /// `twin diagnose`: none, recalibrate, add physics, sensor fault or update the data-based
    /// model, with the evidence. Returns the CLI's JSON report as a dict. `effects` limits the
    /// candidates (`["contact@2-3", "cubic@2"]`).
    #[pyo3(signature = (record, *, effects = None, transient = 2.0, tolerance = None,
                        threads = None, block = 1.0))]
    #[allow(clippy::too_many_arguments)]
    fn diagnose<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        effects: Option<Vec<String>>,
        transient: f64,
        tolerance: Option<f64>,
        threads: Option<usize>,
        block: f64,
    ) -> PyResult<Bound<'py, PyAny>> {
        check_tolerance(Kind::Diagnose, tolerance)?;
        check_transient(Kind::Diagnose, transient, record)?;
        let mut o = diagnose_options(transient, threads, tolerance)?;
        o.block = block;
        if let Some(effects) = effects {
            o.candidates = effects
                .iter()
                .map(|e| Candidate::parse(e).map_err(|m| invalid(Kind::Diagnose, m)))
                .collect::<PyResult<_>>()?;
        }
        let data = &record.measurement;
        let d = detached(py, || {
            diagnose(&self.twin, data, &o).map_err(|e| to_py(Kind::Diagnose, e))
        })?;
        to_object(py, &d)
    }

    /// `twin add-physics`: switch effects on (`effects=["contact@2-3"]`, or all of a
    /// `diagnosis` report's), estimate them on the record (`refine`: with the physics too, as
    /// the CLI does when the diagnosis recalibrated). Returns the new twin and the report.
    #[pyo3(signature = (record, *, effects = None, diagnosis = None, refine = false,
                        transient = 2.0, threads = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_physics<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        effects: Option<Vec<String>>,
        diagnosis: Option<&Bound<'py, PyAny>>,
        refine: bool,
        transient: f64,
        threads: Option<usize>,
    ) -> PyResult<(Twin, Bound<'py, PyAny>)> {
        let kind = Kind::Diagnose;
        let o = diagnose_options(transient, threads, None)?;
        let (candidates, refine) = match (effects, diagnosis) {
            (Some(_), Some(_)) => {
                return Err(invalid(kind, "give effects or a diagnosis, not both"));
            }
            (Some(effects), None) => (
                effects
                    .iter()
                    .map(|e| {
                        Candidate::parse(e)
                            .map(Addition::Library)
                            .map_err(|m| invalid(kind, m))
                    })
                    .collect::<PyResult<Vec<_>>>()?,
                refine,
            ),
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
                let (candidates, moved) = effects_from_report(&path).map_err(|e| {
                    // Name the argument, not the temporary file.
                    invalid(
                        kind,
                        format!("{:#}", anyhow::Error::from(e))
                            .replace(&path.display().to_string(), "the diagnosis"),
                    )
                })?;
                (candidates, refine || moved)
            }
            (None, None) => return Err(invalid(kind, "give effects or a diagnosis")),
        };
        let data = &record.measurement;
        let (new_twin, report) = detached(py, || {
            let (new_twin, report) = add_physics(&self.twin, data, &candidates, refine, &o)
                .map_err(|e| to_py(kind, e))?;
            let report = serde_json::to_value(&report).map_err(|e| to_py(kind, e))?;
            Ok((
                Twin::holding_fmus(new_twin).map_err(|e| to_py(kind, e))?,
                report,
            ))
        })?;
        Ok((new_twin, to_object(py, &report)?))
    }

    /// `twin control`: LQR designs (one per `q`) on the twin's structure, run in the loop on
    /// the record's force. Returns the CLI's JSON report.
    #[pyo3(signature = (record, q, *, r = 0.1, state_unit = "m", estimator = "integrate",
                        highpass = 0.5, seed = 1))]
    #[allow(clippy::too_many_arguments)]
    fn control<'py>(
        &self,
        py: Python<'py>,
        record: &Record,
        q: Vec<f64>,
        r: f64,
        state_unit: &str,
        estimator: &str,
        highpass: f64,
        seed: u64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Control;
        for &q in &q {
            if !(q.is_finite() && q >= 0.0) {
                return Err(invalid(
                    kind,
                    format!("--q {q}: the state weight must be a finite number ≥ 0"),
                ));
            }
        }
        if !(r.is_finite() && r > 0.0) {
            return Err(invalid(
                kind,
                format!("--r {r}: the control weight must be a finite number > 0"),
            ));
        }
        let unit = match state_unit {
            "m" => StateUnit::M,
            "mm" => StateUnit::Mm,
            other => return Err(invalid(kind, format!("state_unit '{other}': m or mm"))),
        };
        let estimator = match estimator {
            "integrate" => EstimatorChoice::Integrate,
            "kalman" => EstimatorChoice::Kalman,
            other => {
                return Err(invalid(
                    kind,
                    format!("estimator '{other}': integrate or kalman"),
                ))
            }
        };
        let options = ControlOptions {
            qs: q,
            r,
            unit,
            estimator,
            highpass_hz: highpass,
            substeps: None,
            sensor_noise: None,
            seed,
            gaps: Vec::new(),
            retune: None,
            schedule: None,
            estimator_costs: false,
        };
        let data = &record.measurement;
        let report = detached(py, || {
            let outcome = run_control(&self.twin, data, &options, &mut |_, _| {})
                .map_err(|e| to_py(kind, e))?;
            serde_json::to_value(&outcome.report).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &report)
    }

    /// `twin watch --source FILE`: the operational twin on a stream in a CSV file (read to its
    /// end; `follow`: as it grows until `idle` s pass without a line). Alerts go to `alerts`
    /// as JSON lines; returns the `end` alert's summary.
    #[pyo3(signature = (source, alerts, *, follow = false, idle = 10.0, window = 2.0,
                        tolerance = None, transient = 2.0, diagnosis = true,
                        diagnosis_record = 20.0, diagnosis_after = 5.0, checkpoint = None))]
    #[allow(clippy::too_many_arguments)]
    fn watch<'py>(
        &self,
        py: Python<'py>,
        source: PathBuf,
        alerts: PathBuf,
        follow: bool,
        idle: f64,
        window: f64,
        tolerance: Option<f64>,
        transient: f64,
        diagnosis: bool,
        diagnosis_record: f64,
        diagnosis_after: f64,
        checkpoint: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Watch;
        check_tolerance(kind, tolerance)?;
        if !(idle >= 0.0 && idle.is_finite()) {
            return Err(invalid(
                kind,
                format!("--idle must be a non-negative number of seconds, was {idle}"),
            ));
        }
        for (name, value) in [
            ("--diagnosis-record", diagnosis_record),
            ("--diagnosis-after", diagnosis_after),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(invalid(
                    kind,
                    format!("{name} must be a non-negative number of seconds, was {value}"),
                ));
            }
        }
        let options = WatchOptions {
            source: StreamSource::File {
                path: source,
                follow,
                idle: Duration::from_secs_f64(idle),
            },
            alerts,
            checkpoint,
            checkpoint_every: 512,
            window,
            tolerance,
            transient,
            rate: None,
            diagnosis: diagnosis.then_some(DiagnosisOptions {
                record: diagnosis_record,
                after: diagnosis_after,
            }),
            learning: LearnOptions::default(),
        };
        let summary = detached(py, || {
            let summary = watch(&self.twin, &options, |_| {}).map_err(|e| to_py(kind, e))?;
            serde_json::to_value(&summary).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &summary)
    }
}
