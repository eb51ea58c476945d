//! When a look at a change has waited for enough post-change data: its verdict is firm by its
//! own evidence, or because the look before gave the same.
//!
//! A look's verdict is firm on its own when the evidence tells the candidates apart and pins
//! the answer that would be adopted: its log evidence leads every other action's by at least
//! [`DECISIVE_LEAD`] (a Bayes factor of 100, "decisive" on Jeffreys' scale), and its site is
//! pinned — a recalibration's most moved parameter moved at least [`SITE_APART`] times as many
//! posterior sds as any other, its posterior sd at most [`PRECISE`] of its value; a single
//! library effect's every parameter known to [`PRECISE_EFFECT`] of itself. Otherwise (a faulty
//! sensor, several effects, a lead or a width short of these) the next look decides, and two
//! looks in a row with the same verdict are firm, as before. The alert says how long it waited
//! and why.

use serde::Serialize;

use crate::workflows::diagnose::{Action, Diagnosis};

/// The least log evidence lead over every other action that decides alone: ln 100.
pub const DECISIVE_LEAD: f64 = 4.605_170_185_988_091;

/// The recalibration's site moves at least this many times the posterior sds of any other
/// parameter.
pub const SITE_APART: f64 = 3.0;

/// The recalibration's site's posterior sd at most this share of its value: the adopted value
/// known to 0.5 % (a 15 % stiffness loss to a thirtieth of itself).
pub const PRECISE: f64 = 0.005;

/// A single effect's fitted parameters' posterior sds at most this share of their values.
pub const PRECISE_EFFECT: f64 = 0.05;

/// What a look's evidence says of its verdict.
#[derive(Debug, Clone, Serialize)]
pub struct Weight {
    /// The verdict's log evidence lead over the best other action (nats; None when the report
    /// gives no evidence to compare, as for a faulty sensor).
    pub lead: Option<f64>,
    /// Recalibrate: the site parameter's move in posterior sds and the next largest.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub site_sds: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_sds: Option<f64>,
    /// The answer's largest posterior sd relative to its value.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relative_sd: Option<f64>,
    /// Decisive on its own: why (None: the next look decides).
    pub decisive: Option<String>,
}

/// The evidence of diagnosis `d` for its verdict.
pub fn weigh(d: &Diagnosis) -> Weight {
    let mut w = Weight {
        lead: None,
        site_sds: None,
        next_sds: None,
        relative_sd: None,
        decisive: None,
    };
    let best_effect = d
        .candidates
        .iter()
        .map(|c| c.evidence)
        .fold(f64::NEG_INFINITY, f64::max);
    match d.action {
        Action::Recalibrate => {
            let Some(r) = &d.recalibration else {
                return w;
            };
            w.lead = best_effect.is_finite().then_some(r.evidence - best_effect);
            let mut moves: Vec<_> = r.parameters.iter().collect();
            moves.sort_by(|a, b| b.change_in_sd.abs().total_cmp(&a.change_in_sd.abs()));
            let Some(site) = moves.first() else {
                return w;
            };
            w.site_sds = Some(site.change_in_sd.abs());
            w.next_sds = moves.get(1).map(|p| p.change_in_sd.abs());
            w.relative_sd = Some(site.sd / site.after.abs());
            let lead = w.lead.unwrap_or(f64::INFINITY);
            let apart = w
                .next_sds
                .map_or(f64::INFINITY, |n| site.change_in_sd.abs() / n);
            let width = site.sd / site.after.abs();
            if lead >= DECISIVE_LEAD && apart >= SITE_APART && width <= PRECISE {
                w.decisive = Some(format!(
                    "recalibration's log evidence leads the best effect's by {lead:.1}, {} moved \
                     {:.1} posterior sd ({apart:.1}× any other parameter), its sd {:.2} % of its \
                     value",
                    site.name,
                    site.change_in_sd.abs(),
                    100.0 * width
                ));
            }
        }
        Action::AddPhysics if d.effects.len() == 1 => {
            let e = &d.effects[0];
            let Some(chosen) = d.candidates.iter().find(|c| c.name.label == e.name.label) else {
                return w;
            };
            let others = d
                .candidates
                .iter()
                .filter(|c| c.name.label != e.name.label)
                .map(|c| c.evidence)
                .chain(d.recalibration.as_ref().map(|r| r.evidence))
                .fold(f64::NEG_INFINITY, f64::max);
            w.lead = others.is_finite().then_some(chosen.evidence - others);
            // The fitted parameters (a contact's side is chosen, not fitted: it has no sd).
            let width = e
                .parameters
                .iter()
                .filter_map(|(name, v)| e.sd.get(name).map(|sd| sd / v.abs()))
                .fold(0.0, f64::max);
            w.relative_sd = Some(width);
            let lead = w.lead.unwrap_or(f64::INFINITY);
            if lead >= DECISIVE_LEAD && width <= PRECISE_EFFECT {
                w.decisive = Some(format!(
                    "{}'s log evidence leads every other candidate's and recalibration's by \
                     {lead:.1}, its parameters known to {:.2} % of themselves",
                    e.name.label,
                    100.0 * width
                ));
            }
        }
        _ => {}
    }
    w
}

/// The residual ratio within which an effect fits the samples before a change as well as the
/// twin does (every channel's residual sum of squares at most 5 % larger).
pub const AS_WELL: f64 = 1.05;

/// The ratio below which it already acted there (some channel's residual cut by 5 %).
pub const ACTED: f64 = 0.95;

/// "The structure changed at t₀" against "an effect that was always there": how the effect a
/// look added fits the samples before the change it was fitted after.
#[derive(Debug, Clone, Serialize)]
pub struct Before {
    /// Per channel, the residual sum of squares before the change with the effect over
    /// without.
    pub ratio: Vec<f64>,
    /// It fits them as well as the twin does: it may have been there all along.
    pub consistent: bool,
    /// It already acted there.
    pub acting: bool,
    /// What the verdict says of the change.
    pub says: String,
}

/// [`Before`] from the residual sums of squares before the change at `at` without (`old`)
/// and with (`new`) the effect `label`.
pub fn before(old: &[f64], new: &[f64], label: &str, at: f64) -> Before {
    let ratio: Vec<f64> = old.iter().zip(new).map(|(o, n)| n / o).collect();
    let consistent = ratio.iter().all(|&r| r <= AS_WELL);
    let acting = consistent && ratio.iter().any(|&r| r <= ACTED);
    let best = ratio.iter().copied().fold(f64::INFINITY, f64::min);
    let worst = ratio.iter().copied().fold(0.0, f64::max);
    let says = if acting {
        format!(
            "{label} already acted before the change at {at:.3} s (it cuts the residual there \
             to {best:.2} of the twin's): it was there before, and the change at {at:.3} s is \
             something else"
        )
    } else if consistent {
        format!(
            "{label} fits the samples before the change at {at:.3} s as well as the twin does \
             (it does not act there): it may have been there all along, the change at {at:.3} s \
             being what made it act (a larger force, a drift) rather than its appearing"
        )
    } else {
        format!(
            "{label} does not fit the samples before the change at {at:.3} s (their residual × \
             {worst:.2} with it): it appeared at the change"
        )
    };
    Before {
        ratio,
        consistent,
        acting,
        says,
    }
}
