//! `Twin`'s operational side: watch a stream, train the GP corrector, learn it actively over
//! records.

use super::Twin;
use crate::record::Record;
use crate::{choice, detached, invalid, to_object, to_py, Kind};
use orchestrator::twin::data::Measurement;
use orchestrator::workflows::learn::{
    chosen_modes, learned_twin, prepare, run_modes, LearnOptions,
};
use orchestrator::workflows::train::{train_selected, LagSelection, TrainOptions};
use orchestrator::workflows::watch::background::DiagnosisOptions;
use orchestrator::workflows::watch::{watch_with_alerts, StreamSource, WatchError, WatchOptions};
use pyo3::prelude::*;
use std::path::PathBuf;

#[pymethods]
impl Twin {
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
}
