//! Stage 2, significance: whether the twin's error is statistically (beyond what noise and
//! parameter uncertainty explain) and practically (beyond the tolerance) significant; unless it
//! is both, the action is `none` and nothing is fitted.

use super::baseline::Baseline;
use super::channels::worst;
use super::{Action, Diagnosis, Gates};
use crate::twin::run::Tolerance;

/// Whether the twin's error raises the alarm, and why not when it does not.
pub(super) struct Alarm {
    /// Significant both statistically and practically.
    pub(super) raised: bool,
    /// The reason a `none` gives.
    pub(super) none_reason: String,
}

/// Stage 2: the error is statistically significant when a channel's NMSE exceeds
/// [`Gates::none_factor`] × its explained level, practically when the worst exceeds the
/// tolerance; both go into the diagnosis. The alarm.
pub(super) fn significance(b: &Baseline, gates: &Gates, diagnosis: &mut Diagnosis) -> Alarm {
    let s = &b.scores;
    let statistically =
        (0..b.nc).any(|c| s.nmse_before[c] > gates.none_factor * s.explained_nmse[c]);
    let practically = worst(&s.nmse_before) > s.tolerance.value;
    diagnosis.statistically_significant = statistically;
    diagnosis.practically_significant = practically;
    Alarm {
        raised: statistically && practically,
        none_reason: none_reason(
            &s.nmse_before,
            &s.noise_nmse,
            &s.band_nmse,
            gates.none_factor,
            statistically,
            &s.tolerance,
        ),
    }
}

/// `none` before any fit: its reason, and a word on the record's modes when they moved beyond
/// the twin's band.
pub(super) fn none_without_fits(diagnosis: &mut Diagnosis, none_reason: String) {
    diagnosis.action = Action::None;
    diagnosis.reason = match diagnosis.modes.as_ref().filter(|m| !m.shifted.is_empty()) {
        Some(m) => format!(
            "{none_reason}; but the record's modes ({}) moved beyond the twin's band: {} — a \
             change the time domain does not show yet, or an identification to check \
             (twin modal --data, twin watch --track-modes)",
            m.method,
            m.describe_shifts()
        ),
        None => none_reason,
    };
}

/// Why `none`: within the explained level, or below the tolerance, or both.
pub(super) fn none_reason(
    nmse: &[f64],
    noise: &[f64],
    band: &[f64],
    factor: f64,
    statistically: bool,
    tolerance: &Tolerance,
) -> String {
    let explained: Vec<f64> = noise.iter().zip(band).map(|(n, b)| n + b).collect();
    let stat =
        format!(
        "{} NMSE ({}) is within {}× of what the twin's band explains on this record ({}: noise \
         {} + parameter uncertainty {})",
        if statistically { "not every channel's" } else { "every channel's" },
        per_channel(nmse),
        factor,
        per_channel(&explained),
        per_channel(noise),
        per_channel(band)
    );
    let worst_floor = worst(nmse);
    let practical = format!(
        "the worst channel's NMSE {:.3} % {} the tolerance of {:.3} % ({})",
        worst_floor,
        if worst_floor > tolerance.value {
            "exceeds"
        } else {
            "is within"
        },
        tolerance.value,
        tolerance.source
    );
    if statistically {
        format!("{stat}, but {practical}: not practically significant, nothing to do")
    } else {
        format!("{stat}, and {practical}: nothing to do")
    }
}

/// `0.123 / 0.456 / 0.789 %`: one value per channel, in the record's order (the report's
/// `channels`).
pub(super) fn per_channel(x: &[f64]) -> String {
    let values: Vec<String> = x.iter().map(|v| format!("{v:.3}")).collect();
    format!("{} %", values.join(" / "))
}
