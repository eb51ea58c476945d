//! The gain schedule: low and high gains, switched when the estimated drift (or the residual's
//! variance) approaches the gap.

use super::closed_loop::{Gains, Gap, StateSource};
use super::options::{ScheduleOptions, VarianceTrigger};
use super::report::{DesignRun, RetuneReport, ScheduleReport, Switch};
use super::response::acc_rms;
use super::runs::{ControlBasis, Runner, ScheduledRun};
use super::ControlError;
use crate::twin::data::Measurement;
use crate::twin::Twin;
use numerics::lqr::Schedule;
use structure::channel::{Channel, Quantity};

/// `--schedule`: run the gain schedule between the smallest stable design and the highest (the
/// retuned one, else the largest q), watching the first gap, with the corrector beside the
/// physics when the latent variance triggers too.
pub(super) fn run_schedule(
    runner: &mut Runner,
    so: &ScheduleOptions,
    basis: &ControlBasis,
    gaps: &[Gap],
    designs: &[DesignRun],
    retune: Option<&RetuneReport>,
    qs: &[f64],
) -> Result<ScheduledRun, ControlError> {
    let gap = gaps.first().cloned().ok_or_else(|| {
        ControlError::Options(
            "--schedule needs a gap to watch: the twin has no contact; give --gap".into(),
        )
    })?;
    let (low, high) = schedule_designs(designs, retune, qs)?;
    let floors = basis.structure.storeys();
    let variance_threshold = variance_threshold(so.variance, &basis.twin, runner.data, floors)?;
    let schedule = Schedule {
        storey: gap.storey,
        gap: gap.gap(),
        side: gap.side(),
        margin: so.margin,
        lookahead: so.lookahead,
        dwell: so.dwell,
        variance_threshold: variance_threshold.clone(),
    };
    let gains = Gains::Scheduled {
        low: low.design.gain.clone(),
        high: high.design.gain.clone(),
        schedule,
    };
    let state = StateSource::Estimated(runner.estimator.clone());
    runner.setup.corrector = variance_threshold.is_some();
    let r = runner.run_law(gains, state);
    runner.setup.corrector = false;
    let r = r?.map_err(ControlError::Unstable)?;
    let (att, mean) = runner.attenuation_of(&r);
    let report = ScheduleReport {
        q_low: low.design.q,
        q_high: high.design.q,
        storey: gap.label(),
        gap: gap.gap(),
        margin: so.margin,
        lookahead: so.lookahead,
        dwell: so.dwell,
        switches: r
            .switches
            .iter()
            .map(|&(time, high)| Switch {
                time,
                to: if high { "high" } else { "low" }.into(),
            })
            .collect(),
        high_fraction: r.high_fraction,
        variance_threshold,
        drift_trigger_fraction: r.drift_trigger_fraction,
        variance_trigger_fraction: r.variance_trigger_fraction,
        contacts: r.contacts.len(),
        contact_times: r.contacts.iter().map(|c| c.time).collect(),
        attenuation_db: att,
        mean_attenuation_db: mean,
        control_rms: r.control_rms,
        control_peak: r.control_peak,
        acc_rms: acc_rms(&r),
    };
    Ok(ScheduledRun {
        report,
        response: r,
    })
}

/// The schedule's two designs: the stable one of smallest q, and the stable one of the
/// retuned q (else the largest requested); refused unless both exist and differ.
pub(super) fn schedule_designs(
    designs: &[DesignRun],
    retune: Option<&RetuneReport>,
    qs: &[f64],
) -> Result<(DesignRun, DesignRun), ControlError> {
    let low = designs
        .iter()
        .filter(|d| d.unstable.is_none())
        .min_by(|a, b| a.design.q.total_cmp(&b.design.q))
        .cloned();
    let high_q = retune
        .and_then(|r| r.chosen_q)
        .unwrap_or_else(|| qs[qs.len() - 1]);
    let high = designs
        .iter()
        .find(|d| d.design.q == high_q && d.unstable.is_none())
        .cloned();
    let (Some(low), Some(high)) = (low, high) else {
        return Err(ControlError::Options(
            "--schedule needs two stable designs (two --q, or --retune)".into(),
        ));
    };
    if low.design.q == high.design.q {
        return Err(ControlError::Options(
            "--schedule needs a higher q than the lowest: give two --q or --retune".into(),
        ));
    }
    Ok((low, high))
}

/// The corrector's latent variance above which the schedule switches to the high gain, per
/// floor (None: off, or `auto` on a twin without a corrector); refused when a threshold is
/// given to a twin without one.
pub(super) fn variance_threshold(
    trigger: VarianceTrigger,
    twin: &Twin,
    data: &Measurement,
    floors: usize,
) -> Result<Option<Vec<f64>>, ControlError> {
    let has_corrector = twin.component(crate::workflows::train::CORRECTOR).is_some();
    Ok(match trigger {
        VarianceTrigger::Off => None,
        VarianceTrigger::Value(v) => {
            if !has_corrector {
                return Err(ControlError::Options(format!(
                    "--variance-threshold {v}: {} has no corrector to give a latent \
                     variance (train one with `twin train`)",
                    twin.describe()
                )));
            }
            Some(vec![v; floors])
        }
        VarianceTrigger::Auto if has_corrector => Some(
            match twin.noise_variance.as_ref().and_then(|v| v.floors(floors)) {
                Some(v) => v,
                None => (0..floors)
                    .map(|f| {
                        crate::workflows::learn::PAPER_THRESHOLD
                            * crate::evaluation::stats::variance(
                                data.channel(Channel::Response {
                                    quantity: Quantity::Acceleration,
                                    floor: f + 1,
                                })
                                .unwrap_or(&[]),
                            )
                    })
                    .collect(),
            },
        ),
        VarianceTrigger::Auto => None,
    })
}
