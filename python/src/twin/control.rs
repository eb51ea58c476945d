//! `Twin.control`'s stages: the designs' and the schedule's options from the keyword
//! arguments, the runs with the plot and the SSP archive written, and the result as a dict.

use std::path::PathBuf;

use orchestrator::report::control_plot::plot_control;
use orchestrator::twin::data::Measurement;
use orchestrator::twin::Twin as CoreTwin;
use orchestrator::workflows::control::{
    run_control, twin_for_control, ControlOptions, ControlOutcome, Retune, ScheduleOptions,
    VarianceTrigger,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::response;
use crate::{choice, invalid, to_object, to_py, Kind};

/// The designs' options from the keyword arguments (None: the CLI's default), checked; the
/// retune's (`target_contacts`, `max_force`) kept for the caller to switch on.
#[allow(clippy::too_many_arguments)]
pub(super) fn design_options(
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
pub(super) fn schedule_options(
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
pub(super) fn control_and_write(
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
pub(super) fn control_result<'py>(
    py: Python<'py>,
    outcome: &ControlOutcome,
) -> PyResult<Bound<'py, PyDict>> {
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
