//! `Twin`: a twin (an SSP archive around the shear FMU) and the CLI's operations on it —
//! compare, calibrate, diagnose, add physics, control, watch — each with the GIL released.

mod analysis;
mod control;
mod hybrid;
mod learning;

use std::path::PathBuf;

use numpy::PyArray1;
use orchestrator::cosim::import::Fmu;
use orchestrator::record::frf::{FrfValues, MeasuredFrf};
use orchestrator::record::ColumnMap;
use orchestrator::record::DataError;
use orchestrator::twin::data::Measurement;
use orchestrator::twin::{ParameterValue, Twin as CoreTwin};
use orchestrator::workflows::compare::{compare, CompareOptions};
use orchestrator::workflows::control::closed_loop::Response;
use orchestrator::workflows::control::ControllerSpec;
use orchestrator::workflows::diagnose::{add_hybrid_contact, with_record, DiagnoseOptions};
use orchestrator::workflows::options::check_svg;
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
}
