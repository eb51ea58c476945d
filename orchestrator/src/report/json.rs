//! The JSON reports of `twin compare` and `twin calibrate`, built in one place for the CLI and
//! the Python package (`shear_twin`), so both give the same fields.

use std::path::Path;

use serde_json::{json, Value};

use crate::twin::data::Measurement;
use crate::twin::run::Compared;
use crate::twin::Twin;
use crate::workflows::calibrate::validated::Validated;

/// `twin compare --report`: `compared` is `twin` run on `data` after `transient` seconds.
/// Every per-channel array (`nmse`, `noise_variance`, the band's, a failing window's `nmse`) is
/// in the order of `channels`, the record's measured channels by name (on the paper's rig,
/// `acc1`, `acc2`, `acc3`); each value in the channel's own quantity, SI. `modes`: the record's
/// modes beside the twin's when they were asked for (`twin compare --modes`: the
/// identification costs more than the comparison itself), else the report has no `modes`.
pub fn compare(
    twin: &Twin,
    data: &Measurement,
    compared: &Compared,
    transient: f64,
    modes: Option<
        &Result<crate::workflows::modal::ModalEvidence, crate::workflows::modal::ModalError>,
    >,
) -> Value {
    let mut report = json!({
        "twin": twin.describe(),
        "data": data.path.display().to_string(),
        "channels": compared.comparison.names(),
        "nmse": compared.comparison.nmse,
        "failing_windows": compared.comparison.failing_windows,
        "noise_variance": compared.noise_variance,
        "noise_variance_source": compared.noise_source,
        "band": {
            "parameter_uncertainty": compared.parameter_variance.is_some(),
            "noise_nmse": compared.noise_nmse,
            "parameter_nmse": compared.band_nmse,
            "explained_nmse": compared.explained_nmse(),
        },
        "tolerance": compared.tolerance.value,
        "tolerance_source": compared.tolerance.source,
        "windows_below_tolerance": compared.comparison.windows_below_tolerance,
        "transient": transient,
        "samples": data.len(),
        "sample_interval": data.dt,
    });
    // The record's modes beside the twin's (information: the time-domain verdict stands).
    if let (Some(modes), Some(object)) = (modes, report.as_object_mut()) {
        let value = match modes {
            Ok(evidence) => serde_json::to_value(evidence).unwrap_or(Value::Null),
            Err(e) => json!({ "error": e.to_string() }),
        };
        object.insert("modes".to_owned(), value);
    }
    report
}

/// `twin calibrate --report`: `twin` calibrated on `data` (the first of its runs) into
/// `result`'s twin (written to `out`, when it is), checked on its validation records. `runs`
/// has every run's noise variances and NMSE by channel name.
pub fn calibrate(
    twin: &Twin,
    out: Option<&Path>,
    data: &Measurement,
    transient: f64,
    result: &Validated,
) -> Value {
    let calibration = &result.calibration;
    let by_name = |names: &[String], values: &[f64]| -> serde_json::Map<String, Value> {
        names
            .iter()
            .zip(values)
            .map(|(n, v)| (n.clone(), json!(v)))
            .collect()
    };
    let mut report = json!({
        "twin": twin.describe(),
        "data": data.path.display().to_string(),
        "transient": transient,
        "parameters": calibration.parameters,
        "correlation": calibration.correlation,
        "noise_variance": calibration.noise_variance,
        "noise_log_sd": calibration.noise_log_sd,
        "neg_log_posterior": calibration.neg_log_posterior,
        "nmse": calibration.nmse,
        "channels": calibration.channels,
        "runs": calibration
            .records
            .iter()
            .map(|r| json!({
                "data": r.record,
                "samples_used": r.samples_used,
                "nmse": by_name(&r.channels, &r.nmse),
                "noise_variance": by_name(&r.channels, &r.noise_variance),
                "noise_log_sd": by_name(&r.channels, &r.noise_log_sd),
            }))
            .collect::<Vec<_>>(),
        "validation": result
            .validated
            .iter()
            .map(|v| json!({
                "data": v.data,
                "nmse": v.nmse,
                "nmse_by_channel": by_name(&v.channels, &v.nmse),
                "accepted": v.accepted,
            }))
            .collect::<Vec<_>>(),
        "validation_nmse": result.twin.validation_nmse,
        "tolerance": result.tolerance,
        "starts": calibration.starts,
        "heads": calibration.heads,
        "simulations": calibration.simulations,
        "seconds": calibration.seconds,
    });
    if let (Some(out), Some(fields)) = (out, report.as_object_mut()) {
        fields.insert("out".into(), json!(out.display().to_string()));
    }
    report
}

/// `twin train --report`: the training, the lag selection, the corrected twin's NMSE.
pub fn train(
    twin: &Twin,
    data: &Measurement,
    out: Option<&Path>,
    trained: &crate::workflows::train::Trained,
) -> Value {
    let mut report = json!({
        "twin": twin.describe(),
        "data": data.path.display().to_string(),
        "training": trained.summary,
        "lag_selection": trained.selection,
        "channels": trained.channels,
        "nmse": trained.nmse,
        "nmse_physics": trained.nmse_physics,
    });
    if let Some(out) = out {
        report["out"] = json!(out.display().to_string());
    }
    report
}

/// `twin learn --report`: the options and each mode's results.
pub fn learn(
    twin: &Twin,
    records: &[String],
    options: &crate::workflows::learn::LearnOptions,
    seconds: f64,
    results: &[crate::workflows::learn::ModeResult],
) -> Value {
    json!({
        "twin": twin.describe(),
        "records": records,
        "lags": options.lags,
        "target": options.target.name(),
        "transient": options.transient,
        "initial": options.initial,
        "uniform_every": options.uniform_every,
        "refit_every_queries": options.refit_every,
        "refit_growth": options.refit_growth,
        "refit_iterations": options.refit_iterations,
        "nmse_every_queries": options.nmse_every,
        "change_run": options.change_run,
        "threshold_option": options.threshold,
        "seconds": seconds,
        "modes": results,
    })
}
