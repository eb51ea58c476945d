//! `Twin`'s analyses of records: calibrate (on records or a measured FRF), diagnose (a record or
//! an ambient one), the modes and add_physics.

use super::{new_twin_and_report, read_measured_frf, Twin};
use crate::record::Record;
use crate::{detached, invalid, to_object, to_py, Kind};
use orchestrator::twin::data::Measurement;
use orchestrator::twin::{RecordRef, RecordRole};
use orchestrator::workflows::calibrate::validated::check_plot;
use orchestrator::workflows::calibrate::{
    calibrate_validated, default_parameters, priors_from_json, CalibrationSetup,
};
use orchestrator::workflows::diagnose::{
    add_physics, diagnose, effects_from_report, parse_additions, parse_candidates, DiagnoseOptions,
};
use orchestrator::workflows::options::check_svg;
use pyo3::prelude::*;
use std::path::PathBuf;

#[pymethods]
impl Twin {
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
            let report =
                orchestrator::report::json::calibrate(&self.twin, None, data, setup.transient, &v);
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
}
