//! `Twin.control`: LQR designs on the twin's structure run in the loop on a record.

use super::{response, Twin};
use crate::record::Record;
use crate::{choice, detached, invalid, to_object, to_py, Kind};
use orchestrator::report::control_plot::plot_control;
use orchestrator::twin::data::Measurement;
use orchestrator::twin::Twin as CoreTwin;
use orchestrator::workflows::control::closed_loop::Gap;
use orchestrator::workflows::control::ControlOutcome;
use orchestrator::workflows::control::{
    run_control, twin_for_control, ControlOptions, Retune, ScheduleOptions, VarianceTrigger,
};
use orchestrator::workflows::options::check_svg;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

#[pymethods]
impl Twin {
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
}

/// The designs' options from the keyword arguments (None: the CLI's default), checked; the
/// retune's (`target_contacts`, `max_force`) kept for the caller to switch on.
#[allow(clippy::too_many_arguments)]
fn design_options(
    q: Vec<f64>,
    r: Option<f64>,
    state_unit: Option<&str>,
    estimator: Option<&str>,
    highpass: Option<f64>,
    substeps: Option<usize>,
    seed: Option<u64>,
    (target_contacts, max_force): (Option<usize>, Option<f64>),
    estimator_costs: bool,
    actuator_floor: Option<usize>,
) -> PyResult<ControlOptions> {
    let kind = Kind::Control;
    let d = ControlOptions::default();
    let rd = Retune::default();
    let options = ControlOptions {
        qs: q,
        r: r.unwrap_or(d.r),
        unit: match state_unit {
            Some(t) => choice(kind, "state-unit", t)?,
            None => d.unit,
        },
        estimator: match estimator {
            Some(t) => choice(kind, "estimator", t)?,
            None => d.estimator,
        },
        highpass_hz: highpass.unwrap_or(d.highpass_hz),
        substeps: substeps.or(d.substeps),
        seed: seed.unwrap_or(d.seed),
        retune: Some(Retune {
            target: target_contacts.unwrap_or(rd.target),
            max_force,
        }),
        estimator_costs,
        actuator_floor: actuator_floor.unwrap_or(d.actuator_floor),
        ..ControlOptions::default()
    };
    options.validate().map_err(|e| to_py(kind, e))?;
    Ok(options)
}

/// The gain schedule's options when `schedule` is on (None: the CLI's default each).
fn schedule_options(
    schedule: bool,
    margin: Option<f64>,
    lookahead: Option<f64>,
    dwell: Option<f64>,
    variance_threshold: Option<&str>,
) -> PyResult<Option<ScheduleOptions>> {
    let sd = ScheduleOptions::default();
    let variance = match variance_threshold {
        Some(t) => VarianceTrigger::parse(t).map_err(|e| to_py(Kind::Control, e))?,
        None => sd.variance,
    };
    Ok(schedule.then_some(ScheduleOptions {
        margin: margin.unwrap_or(sd.margin),
        lookahead: lookahead.unwrap_or(sd.lookahead),
        dwell: dwell.unwrap_or(sd.dwell),
        variance,
    }))
}

/// The runs (passive and under each design) on the twin as controlled, then the plot and the
/// SSP archive written when asked (the plot drawn before the archive is written, written
/// after).
fn control_and_write(
    twin: &CoreTwin,
    data: &Measurement,
    options: &ControlOptions,
    sensor_noise: Option<f64>,
    plot: &Option<PathBuf>,
    ssp: &Option<PathBuf>,
    ssp_q: Option<f64>,
) -> PyResult<ControlOutcome> {
    let kind = Kind::Control;
    let twin = twin_for_control(twin, sensor_noise);
    let outcome = run_control(&twin, data, options, &mut |_, _| {}).map_err(|e| to_py(kind, e))?;
    let svg = match plot {
        Some(path) => Some((
            path,
            plot_control(
                &outcome,
                &format!("twin control on {}", data.path.display()),
            )
            .map_err(|m| invalid(kind, format!("cannot draw {}: {m}", path.display())))?,
        )),
        None => None,
    };
    if let Some(path) = ssp {
        let span = (data.time[0], *data.time.last().unwrap_or(&data.time[0]));
        orchestrator::workflows::control::ssp::write_controlled_ssp(
            &twin,
            &outcome.report,
            ssp_q,
            Some(span),
            path,
        )
        .map_err(|e| {
            to_py(
                kind,
                anyhow::Error::from(e).context(format!("--ssp {}", path.display())),
            )
        })?;
    }
    if let Some((path, text)) = svg {
        orchestrator::fsutil::write_text_atomically(path, &text).map_err(|e| to_py(kind, e))?;
    }
    Ok(outcome)
}

/// The result as a dict: the CLI's report and each run's response (None for a design that
/// did not run).
fn control_result<'py>(py: Python<'py>, outcome: &ControlOutcome) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("report", to_object(py, &outcome.report)?)?;
    out.set_item("passive", response(py, &outcome.passive)?)?;
    let designs = outcome
        .designs
        .iter()
        .map(|d| d.as_ref().map(|r| response(py, r)).transpose())
        .collect::<PyResult<Vec<_>>>()?;
    out.set_item("designs", designs)?;
    out.set_item(
        "scheduled",
        outcome
            .scheduled
            .as_ref()
            .map(|r| response(py, r))
            .transpose()?,
    )?;
    Ok(out)
}
