//! What a diagnosis and `add-physics` report: the JSON contract's types.

use std::collections::BTreeMap;

use serde::Serialize;
use structure::effects::Term;

use super::{Action, Addition, Candidate, Gates, Kind};
use crate::evaluation::compare::FailingWindow;
use crate::evaluation::stats::variance;

/// An estimated parameter: its short name, value and posterior sd.
#[derive(Clone, Debug, Serialize)]
pub struct Estimate {
    pub name: String,
    pub value: f64,
    pub sd: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct EffectReport {
    #[serde(flatten)]
    pub name: EffectName,
    pub parameters: BTreeMap<String, f64>,
    pub sd: BTreeMap<String, f64>,
    /// A discovered effect's terms (empty for the library's kinds).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub terms: Vec<TermReport>,
}

/// One term of a discovered effect: `coefficient · function` at the effect's site.
#[derive(Clone, Debug, Serialize)]
pub struct TermReport {
    /// The function's name, e.g. `v|v|`, `max(0,x-s)`.
    pub function: String,
    pub coefficient: f64,
    pub sd: f64,
    /// The function's `s` (m or m/s), where it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// The kind of an effect a diagnosis names: one of the library's, or `discovered`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EffectKind {
    Contact,
    Cubic,
    Friction,
    Discovered,
}

impl From<Kind> for EffectKind {
    fn from(kind: Kind) -> Self {
        match kind {
            Kind::Contact => EffectKind::Contact,
            Kind::Cubic => EffectKind::Cubic,
            Kind::Friction => EffectKind::Friction,
        }
    }
}

impl PartialEq<Kind> for EffectKind {
    fn eq(&self, other: &Kind) -> bool {
        *self == EffectKind::from(*other)
    }
}

/// Which effect, where: what the named effect and every candidate of a report share.
#[derive(Clone, Debug, Serialize)]
pub struct EffectName {
    pub kind: EffectKind,
    /// Contact `[lower, upper]` floors, cubic `[storey]`, friction `[floor]`; discovered
    /// `[storey]` or `[floor]` as `site` says.
    pub location: Vec<usize>,
    /// Contact only: "both", "positive" or "negative".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub side: Option<&'static str>,
    /// Discovered only: "storey" or "floor".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub site: Option<&'static str>,
    /// `KIND@LOCATION[:SIDE]`, what `twin add-physics --effect` takes; `discovered@storey2`.
    pub label: String,
}

impl EffectName {
    pub(super) fn of(c: &Candidate) -> Self {
        EffectName {
            kind: c.kind.into(),
            location: c.location(),
            side: c.kind.has_side().then_some(c.side.name()),
            site: None,
            label: c.label(),
        }
    }

    pub(super) fn of_addition(a: &Addition) -> Self {
        match a {
            Addition::Library(c) => EffectName::of(c),
            Addition::Discovered(terms) => {
                let site = terms.first().map(|t| t.site);
                EffectName {
                    kind: EffectKind::Discovered,
                    location: site.map(|s| vec![s.at()]).unwrap_or_default(),
                    side: None,
                    site: site.map(|s| match s {
                        structure::effects::Site::Storey(_) => "storey",
                        structure::effects::Site::Floor(_) => "floor",
                    }),
                    label: a.label(),
                }
            }
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct CandidateReport {
    #[serde(flatten)]
    pub name: EffectName,
    /// Log Bayes factor (Laplace) against the twin as it is, on the fitted blocks.
    pub evidence: f64,
    /// NMSE per channel over the whole record after the transient.
    pub nmse_after: Vec<f64>,
    /// NMSE per channel on the held-out blocks.
    pub nmse_held_out: Vec<f64>,
    pub parameters: Vec<Estimate>,
    /// Cut the error by the required factor and beat recalibration.
    pub passes: bool,
    pub simulations: usize,
    pub seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct MovedParameter {
    pub name: String,
    pub before: f64,
    pub after: f64,
    pub sd: f64,
    /// `(after − before) / sd`.
    pub change_in_sd: f64,
    pub relative_change: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct RecalibrationReport {
    pub evidence: f64,
    pub nmse_after: Vec<f64>,
    pub nmse_held_out: Vec<f64>,
    /// Every parameter, largest move (in posterior sd) first.
    pub parameters: Vec<MovedParameter>,
    pub noise_variance: Vec<f64>,
    pub simulations: usize,
    pub seconds: f64,
}

/// Correlations of the missing storey shear with storey drift, and of the missing floor force
/// with the sign of the floor's velocity.
#[derive(Clone, Debug, Serialize)]
pub struct Localisation {
    /// Per storey, 1 first: corr(missing shear, drift).
    pub shear_vs_drift: Vec<f64>,
    /// Per storey: corr(missing shear, drift³).
    pub shear_vs_drift_cubed: Vec<f64>,
    /// Per storey: corr(missing shear, the part of the drift beyond its 80th percentile of |drift|,
    /// the shape of a contact force).
    pub shear_vs_drift_beyond: Vec<f64>,
    /// Per floor, 1 first: corr(missing floor force, sign of the floor's velocity).
    pub force_vs_velocity_sign: Vec<f64>,
    /// The storey or floor with the largest |correlation| of any kind, e.g. "storey 3".
    pub strongest: String,
}

/// How one channel enters the diagnosis, and how much of the answer it saw.
#[derive(Clone, Debug, Serialize)]
pub struct Sensing {
    pub channel: String,
    /// `acceleration`, `velocity` or `displacement`: the quantity its residual, noise, band and
    /// the candidates' fits are in.
    pub quantity: String,
    /// How the localisation (forces: the residual times the floor mass) reads it: `as
    /// measured` (an accelerometer), or its residual `differentiated once` (velocity) or
    /// `differentiated twice` (displacement) by central differences.
    pub localisation: String,
    /// The RMS after the transient of what the verdict changes in this channel's prediction,
    /// over the channel's noise sd (the twin's noise variance): how clearly this sensor sees
    /// the answer (the identifiability it gives). None when the verdict changes nothing.
    pub visibility: Option<f64>,
}

impl Diagnosis {
    /// Fill each channel's [`Sensing::visibility`] from the series before and after the
    /// verdict and the noise level.
    pub(super) fn measure_visibility(&mut self) {
        let first = self.series.first;
        for (c, sensing) in self.sensing.iter_mut().enumerate() {
            // noise_nmse is 100·σ²/var(measured) after the transient.
            let noise_sd =
                (self.noise_nmse[c] / 100.0 * variance(&self.series.measured[c][first..])).sqrt();
            let after = &self.series.after[c][first..];
            let change = after
                .iter()
                .zip(&self.series.before[c][first..])
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / after.len().max(1) as f64;
            sensing.visibility = (change > 0.0 && noise_sd > 0.0).then(|| change.sqrt() / noise_sd);
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct LatentVariance {
    pub max: Vec<f64>,
    pub mean: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Diagnosis {
    pub record: String,
    /// The located change the record was diagnosed after (s of the record): every fit
    /// started there, from the state the twin reached on the samples before it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub changed_at: Option<f64>,
    /// The measured channels, in the record's order: every per-channel list (`nmse_before`,
    /// `nmse_after`, …) is in this order.
    pub channels: Vec<String>,
    pub twin: String,
    pub nmse_before: Vec<f64>,
    /// NMSE per channel that the twin's noise variances alone explain on this record.
    pub noise_nmse: Vec<f64>,
    /// NMSE per channel that the twin's parameter uncertainty explains (its band's `J Σ Jᵀ`; 0
    /// for a twin without a posterior covariance).
    pub band_nmse: Vec<f64>,
    /// `noise_nmse + band_nmse`: what the twin's ±3σ band explains.
    pub explained_nmse: Vec<f64>,
    /// Practical significance (NMSE %) and where it comes from.
    pub tolerance: f64,
    pub tolerance_source: String,
    /// Some floor's NMSE exceeds `gates.none_factor` × its explained level.
    pub statistically_significant: bool,
    /// The worst floor's NMSE exceeds the tolerance.
    pub practically_significant: bool,
    pub nmse_before_held_out: Vec<f64>,
    pub noise_nmse_held_out: Vec<f64>,
    pub failing_windows: Vec<FailingWindow>,
    /// The corrector's latent variance V(f) on the record, when the twin has one.
    pub latent_variance: Option<LatentVariance>,
    pub action: Action,
    /// Why, in a sentence with the numbers.
    pub reason: String,
    /// The first of `effects` (what a single-effect diagnosis names).
    pub effect: Option<EffectReport>,
    /// Every effect added, in the order forward selection chose them, with their jointly
    /// fitted parameters.
    pub effects: Vec<EffectReport>,
    /// The physics parameters the joint refit with the effects moved by more than 3 posterior
    /// sd and 1 %, largest move first (empty unless the action is `add_physics`).
    pub physics_moved: Vec<MovedParameter>,
    /// The forward selection's rounds.
    pub selection: Vec<SelectionStep>,
    /// The search for an effect outside the library, when it ran.
    pub discovery: Option<DiscoveryReport>,
    /// The faulty channel, when the action is `sensor_fault`.
    pub sensor: Option<SensorFit>,
    /// Every floor's sensor candidate (gain, offset, drift of the twin's prediction), floor 1
    /// first; empty when nothing was fitted.
    pub sensor_candidates: Vec<SensorFit>,
    pub nmse_after: Vec<f64>,
    pub recalibration: Option<RecalibrationReport>,
    /// Best evidence first.
    pub candidates: Vec<CandidateReport>,
    /// Candidates whose fit failed (no start converged, the FMU refused every value): label
    /// and error. They take no part in the decision.
    pub failed_candidates: Vec<(String, String)>,
    /// Candidates of the default library not fitted (at none of the [`super::SCREEN_SITES`]
    /// best sites): label and the share of the held-out residual their linearised force leaves
    /// ([`super::discover::screen`]); empty when every candidate was fitted.
    pub screened_out: Vec<(String, f64)>,
    /// On a long record, the samples of its head the candidates were raced on before round 1
    /// (`race`); None when they were not raced.
    pub race_head: Option<usize>,
    /// The candidates the race left out: label and worst-floor held-out NMSE (%) on the head,
    /// best first; empty when there was no race.
    pub raced_out: Vec<(String, f64)>,
    pub localisation: Localisation,
    /// Per channel: its quantity, how the localisation reads it, and how much of the verdict's
    /// change it saw.
    pub sensing: Vec<Sensing>,
    /// The record's modes beside the twin's (`workflows::modal::evidence`); None when the
    /// record could not be identified (`modes_error` says why).
    pub modes: Option<crate::workflows::modal::ModalEvidence>,
    pub modes_error: Option<String>,
    pub gates: Gates,
    pub block_seconds: f64,
    pub seconds: f64,
    /// For the plot (not in the JSON).
    #[serde(skip)]
    pub series: Series,
}

/// Time series the plot draws.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub time: Vec<f64>,
    pub first: usize,
    /// Each channel's floor (from 1); `measured`, `before` and `after` are per channel.
    pub floors: Vec<usize>,
    pub measured: Vec<Vec<f64>>,
    pub before: Vec<Vec<f64>>,
    pub after: Vec<Vec<f64>>,
    pub drift: Vec<Vec<f64>>,
    /// Missing storey shear per storey (N): from the residual of the twin as given; for the
    /// winning effect's storey, the shear the linear part misses along the fitted model.
    pub missing_shear: Vec<Vec<f64>>,
    /// The winning effect's storey force (N) for its storey, when one won.
    pub effect_force: Option<Vec<f64>>,
    /// The evidence panel's horizontal axis when it is not the storey's drift (a discovered
    /// force of the drift rate).
    pub evidence_axis: Option<EvidenceAxis>,
}

/// What the evidence panel draws the missing shear against.
#[derive(Clone, Debug)]
pub struct EvidenceAxis {
    pub label: String,
    pub values: Vec<f64>,
    /// Whether the fitted force is a curve of it (else it is drawn as points).
    pub curve: bool,
}

/// The search for an effect outside the library.
#[derive(Clone, Debug, Serialize)]
pub struct DiscoveryReport {
    /// The regression's result: the winning site, and every site's sparse model with the
    /// share of the held-out residual it leaves (linearised). `None`: no site's model with a
    /// nonlinear term cut it by the step gate.
    pub regression: Option<Found>,
    /// The second pass, linearised around the refitted model's trajectory.
    pub relinearised: Option<Found>,
    /// The terms kept, with the FMI refit's coefficients and sd.
    pub terms: Vec<TermReport>,
    /// After the refit through the FMU (with the physics): per channel.
    pub nmse_held_out: Option<Vec<f64>>,
    pub nmse_after: Option<Vec<f64>>,
    /// Cut the error by the required factor and beat recalibration.
    pub passes: bool,
    pub seconds: f64,
}

/// What `twin add-physics` did.
#[derive(Clone, Debug, Serialize)]
pub struct AddPhysicsReport {
    pub record: String,
    /// The first of `effects`.
    pub effect: EffectReport,
    /// Every effect added, in order.
    pub effects: Vec<EffectReport>,
    /// The structure's parameters after the joint refit over every record.
    pub refined_physics: Vec<Estimate>,
    /// NMSE per channel on `record` before and after the joint refit.
    pub nmse_before: Vec<f64>,
    pub nmse_after: Vec<f64>,
    /// On `record` after the first stage (the effects alone, the physics held).
    pub nmse_effects_alone: Vec<f64>,
    /// Log Bayes factor of the first stage against the twin as it was, on `record`.
    pub evidence: f64,
    /// `record`'s noise variances in the joint fit.
    pub noise_variance: Vec<f64>,
    /// Every record of the joint refit, `record` first.
    pub records: Vec<RecordNmse>,
    /// The new twin's validation NMSE (worst floor of its worst record under the cap): twice
    /// it is `twin compare`'s default tolerance.
    pub validation_nmse: Option<f64>,
    pub seconds: f64,
}

/// One record of a joint refit: NMSE per channel before and after, and its noise variances.
#[derive(Clone, Debug, Serialize)]
pub struct RecordNmse {
    pub record: String,
    pub nmse_before: Vec<f64>,
    pub nmse_after: Vec<f64>,
    pub noise_variance: Vec<f64>,
}

/// One round of the forward selection.
#[derive(Clone, Debug, Serialize)]
pub struct SelectionStep {
    pub round: usize,
    /// The effect added in this round.
    pub added: String,
    /// Worst-floor held-out NMSE of the model before the round.
    pub worst_before: f64,
    /// Held-out NMSE per floor with the effect added, everything else held.
    pub nmse_held_out_effect: Vec<f64>,
    /// Held-out NMSE per floor after the joint refit of every chosen effect and the physics.
    pub nmse_held_out_joint: Vec<f64>,
    /// Whether the joint refit was kept (it lowered the held-out error).
    pub joint_kept: bool,
    /// Every candidate the round tried: label and worst-floor held-out NMSE.
    pub tried: Vec<(String, f64)>,
    pub seconds: f64,
    /// The model after this round, refitted jointly with the physics, explained the record,
    /// so no later round ran (a long record's shortcut, `settled`).
    pub settled: bool,
}

/// One site's sparse model.
#[derive(Clone, Debug, Serialize)]
pub struct SiteModel {
    pub site: String,
    /// `function` names (with `s` where used) of the selected terms.
    pub terms: Vec<String>,
    /// Held-out weighted residual left (linearised), as a fraction of what the physics
    /// parameters alone leave (1 = the terms explain nothing more).
    pub held_out_fraction: f64,
}

/// What was found: the terms (regression coefficients) and every site's model.
#[derive(Clone, Debug, Serialize)]
pub struct Found {
    #[serde(skip)]
    pub terms: Vec<Term>,
    pub site: String,
    pub held_out_fraction: f64,
    pub sites: Vec<SiteModel>,
}

/// A channel's fitted fault: `measured ≈ gain·predicted + offset + drift·(t − t₀)`, `t₀` the
/// record's first sample time.
#[derive(Clone, Debug, Serialize)]
pub struct SensorFit {
    /// The channel's name, e.g. `acc2`.
    pub channel: String,
    /// Its floor, from 1.
    pub floor: usize,
    pub gain: f64,
    /// m/s².
    pub offset: f64,
    /// m/s² per s.
    pub drift: f64,
    /// Posterior (least-squares) sd of gain, offset and drift.
    pub sd: SensorSd,
    /// This floor's held-out NMSE (%) before and with the fault modelled.
    pub nmse_held_out_before: f64,
    pub nmse_held_out: f64,
    /// The same over the whole record after the transient.
    pub nmse_after: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct SensorSd {
    pub gain: f64,
    pub offset: f64,
    pub drift: f64,
}

impl SensorFit {
    /// The channel as the fault model reads it from the prediction.
    pub fn apply(&self, predicted: &[f64], time: &[f64]) -> Vec<f64> {
        let t0 = time.first().copied().unwrap_or(0.0);
        predicted
            .iter()
            .zip(time)
            .map(|(p, t)| self.gain * p + self.offset + self.drift * (t - t0))
            .collect()
    }
}
