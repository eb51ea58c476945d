//! Faulty sensors: one accelerometer's channel modelled as `gain·ŷ_f + offset + drift·t` of the
//! twin's own prediction `ŷ_f` (the physics unchanged). Linear in the three parameters, so each
//! floor's candidate is an ordinary least-squares fit on the fitted blocks, its sd from the
//! residual, and it is scored on the held-out blocks like the other alternatives. One
//! candidate per measured channel. The decision (stage 3a of [`super::diagnose`]): the one
//! channel whose fault explains the error, while every other floor is already fine, is a
//! `sensor_fault`.

use structure::channel::{Channel, Quantity};

use super::baseline::Baseline;
pub use super::report::{SensorFit, SensorSd};
use super::{Action, Diagnosis, Gates};
use crate::evaluation::stats::nmse;
use crate::twin::data::Measurement;

/// The fault model's parameters: gain, offset and drift (three whatever the building).
const PARAMETERS: usize = 3;
/// A row of the fault model's design matrix, or its gain, offset and drift.
type Parameters = nalgebra::SVector<f64, PARAMETERS>;
/// The normal matrix XᵀX of the fault model's least squares.
type Normal = nalgebra::SMatrix<f64, PARAMETERS, PARAMETERS>;

/// Fit the channel `channel` (on floor `floor`, from 1) on the `fitted` samples, score on
/// `held_out` and `after`. `None` when the normal equations are singular (a constant
/// prediction).
pub fn fit_channel(
    channel: &str,
    floor: usize,
    measured: &[f64],
    predicted: &[f64],
    time: &[f64],
    fitted: &[usize],
    held_out: &[usize],
    after: &[usize],
) -> Option<SensorFit> {
    let t0 = time.first().copied().unwrap_or(0.0);
    let row = |k: usize| Parameters::new(predicted[k], 1.0, time[k] - t0);
    // Normal equations XᵀX b = Xᵀy.
    let mut a = Normal::zeros();
    let mut b = Parameters::zeros();
    for &k in fitted {
        let x = row(k);
        b += x * measured[k];
        a += x * x.transpose();
    }
    let inv = invert(&a)?;
    let beta = inv * b;
    let rss: f64 = fitted
        .iter()
        .map(|&k| {
            let x = row(k);
            let p = x.dot(&beta);
            (measured[k] - p).powi(2)
        })
        .sum();
    let dof = fitted.len().saturating_sub(PARAMETERS).max(1) as f64;
    let s2 = rss / dof;
    let sd = inv.diagonal().map(|v| (s2 * v).max(0.0).sqrt());
    let model = |k: usize| beta[0] * predicted[k] + beta[1] + beta[2] * (time[k] - t0);
    let score = |idx: &[usize]| {
        let y: Vec<f64> = idx.iter().map(|&k| measured[k]).collect();
        let p: Vec<f64> = idx.iter().map(|&k| model(k)).collect();
        nmse(&y, &p)
    };
    let before = {
        let y: Vec<f64> = held_out.iter().map(|&k| measured[k]).collect();
        let p: Vec<f64> = held_out.iter().map(|&k| predicted[k]).collect();
        nmse(&y, &p)
    };
    Some(SensorFit {
        channel: channel.to_string(),
        floor,
        gain: beta[0],
        offset: beta[1],
        drift: beta[2],
        sd: SensorSd {
            gain: sd[0],
            offset: sd[1],
            drift: sd[2],
        },
        nmse_held_out_before: before,
        nmse_held_out: score(held_out),
        nmse_after: score(after),
    })
}

/// The inverse of the normal matrix; None when it is singular for its scale (a constant
/// prediction).
fn invert(a: &Normal) -> Option<Normal> {
    let det = a.determinant();
    let scale = a.amax();
    if !(det.is_finite() && det.abs() > 1e-14 * scale.powi(PARAMETERS as i32)) {
        return None;
    }
    a.try_inverse()
}

/// Stage 3a, faulty sensors: per channel, the measured as gain·ŷ + offset + drift·t of the
/// twin's prediction, least squares on the fitted blocks, scored on the held-out ones, into the
/// diagnosis's sensor candidates. The one fault that explains the error, with its reason.
pub(super) fn faulty_sensor(
    b: &Baseline,
    data: &Measurement,
    gates: &Gates,
    diagnosis: &mut Diagnosis,
) -> Option<(SensorFit, String)> {
    let fitted_idx: Vec<usize> = (0..b.samples.n).filter(|&k| b.samples.mask[k]).collect();
    diagnosis.sensor_candidates = (0..b.nc)
        .filter_map(|c| {
            fit_channel(
                &b.channels.names[c],
                b.channels.floors[c] + 1,
                &b.channels.measured[c],
                &b.scores.predicted[c],
                &data.time,
                &fitted_idx,
                &b.samples.held_out,
                &b.samples.after,
            )
        })
        .collect();
    sensor_decision(
        &b.channels.names,
        &diagnosis.sensor_candidates,
        &b.scores.nmse_before_held_out,
        &b.scores.noise_nmse_held_out,
        &b.scores.band_nmse,
        b.scores.tolerance.value,
        gates,
    )
}

/// `sensor_fault`: its reason, and the faulty channel's prediction and NMSE read through the
/// fault.
pub(super) fn report_sensor_fault(
    b: &Baseline,
    data: &Measurement,
    diagnosis: &mut Diagnosis,
    fault: &SensorFit,
    reason: &str,
) {
    let c = b.channels.index(&fault.channel);
    diagnosis.action = Action::SensorFault;
    diagnosis.reason = reason.to_owned();
    diagnosis.sensor = Some(fault.clone());
    diagnosis.series.after[c] = fault.apply(&b.scores.predicted[c], &data.time);
    diagnosis.nmse_after[c] = fault.nmse_after;
}

/// A sensor fault: exactly one floor's channel candidate cuts that floor's held-out NMSE by
/// [`Gates::required_cut`] and brings it within [`Gates::recalibration_noise_factor`] × its
/// explained level (or the tolerance), while every other floor is already fine: within
/// [`Gates::none_factor`] × its explained level, or the tolerance. A structural change moves
/// several floors' residuals coherently; a faulty sensor only its own.
pub(super) fn sensor_decision(
    names: &[String],
    fits: &[SensorFit],
    before_held_out: &[f64],
    noise_held_out: &[f64],
    band: &[f64],
    tolerance: f64,
    gates: &Gates,
) -> Option<(SensorFit, String)> {
    let explained = |c: usize| noise_held_out[c] + band[c];
    let fine = |c: usize, x: f64, factor: f64| x <= (factor * explained(c)).max(tolerance);
    let index = |s: &SensorFit| names.iter().position(|n| *n == s.channel);
    let explains: Vec<&SensorFit> = fits
        .iter()
        .filter(|s| {
            let Some(c) = index(s) else { return false };
            s.nmse_held_out * gates.required_cut <= before_held_out[c]
                && fine(c, s.nmse_held_out, gates.recalibration_noise_factor)
                && (0..names.len())
                    .filter(|&g| g != c)
                    .all(|g| fine(g, before_held_out[g], gates.none_factor))
        })
        .collect();
    let [s] = explains.as_slice() else {
        return None;
    };
    let c = index(s)?;
    let others: Vec<String> = (0..names.len())
        .filter(|&g| g != c)
        .map(|g| format!("{} {:.3} %", floor_of(&names[g]), before_held_out[g]))
        .collect();
    let (sensor, unit, rate) = match Channel::parse(&s.channel) {
        Some(Channel::Response {
            quantity: Quantity::Velocity,
            ..
        }) => ("velocity sensor", "m/s", "m/s²"),
        Some(Channel::Response {
            quantity: Quantity::Displacement,
            ..
        }) => ("displacement sensor", "m", "m/s"),
        _ => ("accelerometer", "m/s²", "m/s³"),
    };
    Some((
        (*s).clone(),
        format!(
            "the {sensor} on floor {} reads gain {:.3} ± {:.3}, offset {:.4} ± {:.4} {unit}, \
             drift {:.5} ± {:.5} {rate} of the twin's prediction: that cuts floor {}'s held-out \
             NMSE from {:.3} % to {:.3} % ({:.1}×), while the other floors are already within \
             the noise or the tolerance ({}): a sensor fault, not physics",
            s.floor,
            s.gain,
            s.sd.gain,
            s.offset,
            s.sd.offset,
            s.drift,
            s.sd.drift,
            s.floor,
            s.nmse_held_out_before,
            s.nmse_held_out,
            s.nmse_held_out_before / s.nmse_held_out,
            others.join(", ")
        ),
    ))
}

/// `floor 2` for `acc2`: how the reasons name a channel's floor.
pub(super) fn floor_of(name: &str) -> String {
    let digits = name.trim_start_matches(|c: char| !c.is_ascii_digit());
    if digits.is_empty() {
        name.to_string()
    } else {
        format!("floor {digits}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_gain_offset_and_drift() {
        let n = 2000;
        let time: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        let p: Vec<f64> = time
            .iter()
            .map(|t| (3.0 * t).sin() + 0.3 * (7.1 * t).cos())
            .collect();
        let y: Vec<f64> = p
            .iter()
            .zip(&time)
            .map(|(p, t)| 0.8 * p + 0.05 + 0.01 * t)
            .collect();
        let idx: Vec<usize> = (0..n).collect();
        let f = fit_channel("acc2", 2, &y, &p, &time, &idx, &idx, &idx).expect("fit");
        assert!((f.gain - 0.8).abs() < 1e-9 && (f.offset - 0.05).abs() < 1e-9);
        assert!((f.drift - 0.01).abs() < 1e-9 && f.floor == 2);
        assert!(f.nmse_held_out < 1e-12);
    }
}
