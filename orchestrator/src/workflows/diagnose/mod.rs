//! `twin diagnose` and `twin add-physics`: when a twin fails on a record, decide what to do —
//! nothing, recalibrate, add physics, or leave it to the data-based corrector — and, when
//! physics is missing, which effect of the shear FMU's library, where, and how strong.
//!
//! # How a record is diagnosed
//!
//! 1. **Compare.** The twin as given runs on the record (FMI): NMSE per floor after the
//!    transient, failing windows, and the corrector's latent variance when it has one. The
//!    physics alone runs too, recording the storey drifts and floor velocities.
//! 2. **Explained level and tolerance.** The twin's calibrated noise variances `σ²_f` say how
//!    much NMSE noise alone explains on this record: `100 σ²_f / var(ÿ_f)`; its calibration's
//!    Laplace posterior covariance `Σ` of the physics parameters, propagated through the FMU's
//!    sensitivities `J` (finite differences through FMI), adds what the parameter uncertainty
//!    explains: `100 mean(J Σ Jᵀ) / var(ÿ_f)` (on a record louder than the calibration record
//!    the noise share falls, the parameter share does not). The error is *statistically*
//!    significant when a floor's NMSE exceeds [`Gates::none_factor`] (2) × that explained level,
//!    *practically* significant when the worst floor's NMSE exceeds the tolerance
//!    (`--tolerance`, else 2 × the twin's worst validation NMSE, else 0.5 %). Unless it is both,
//!    the action is `none` and nothing is fitted.
//! 3. **Held-out blocks.** The record after the transient is cut into blocks of
//!    [`DiagnoseOptions::block`] (1 s); even blocks are fitted, odd ones held out. Every
//!    fitted alternative is scored on the held-out blocks, so an extra parameter that only fits
//!    noise is not rewarded, and contact that only happens late in the record still falls in
//!    both halves.
//!    **Faulty sensors** ([`sensor`]): per floor, the measured channel as `gain·ŷ_f + offset +
//!    drift·t` of the twin's prediction (physics unchanged), least squares on the fitted
//!    blocks, scored on the held-out ones. When exactly one floor's fit cuts that floor's
//!    held-out NMSE by [`Gates::required_cut`] to within
//!    [`Gates::recalibration_noise_factor`] × its explained level (or the tolerance), while
//!    every other floor is already within [`Gates::none_factor`] × its explained level (or the
//!    tolerance), the action is `sensor_fault` and nothing else is fitted (unless
//!    [`DiagnoseOptions::always_fit`]): a structural change moves several floors' residuals
//!    coherently, a faulty sensor only its own; a dead channel is found as gain ≈ 0.
//! 4. **Alternatives, in parallel threads**, each a MAP fit through FMI (`calibrate`, Laplace
//!    posterior) on the fitted blocks:
//!    - *recalibration*: the nine physics parameters under the paper's priors;
//!    - *each candidate of the effect library* ([`Candidate::library`]: contact at ground–1,
//!      1–2, 2–3, each side or both; cubic stiffness per storey; friction per floor), only its
//!      own parameters estimated, the physics held at the twin's values.
//!
//!    Evidence: the Laplace log evidence of each fit minus that of the twin as it is, i.e. a log
//!    Bayes factor against "no change" (positive favours the alternative).
//! 5. **Decide** (worst floor, held-out NMSE): the residuals of a wrong or incomplete model are
//!    coloured, not white, so evidence alone rewards tiny spurious effects (a friction of a
//!    milli-newton "wins" on a record with no change). The decision is gated on how far the
//!    error falls, and the evidence only ranks the alternatives that pass:
//!    - an effect passes alone when it cuts the error by [`Gates::required_cut`] (4×) and
//!      beats recalibration by [`Gates::beat_recalibration`] (2×);
//!    - **forward selection** ([`select`]) builds the model up from there, for several changes
//!      at once: the passing candidate of highest evidence (else the one cutting the error most,
//!      by [`Gates::step_cut`] at least; a recalibration is a move too), the rounds repeated
//!      while the model is short of the noise or the tolerance, every chosen effect finally
//!      refitted jointly with the physics. The combination must meet the same 4× and 2× gates
//!      as a whole: `add_physics`, with `effects` in order and the physics that moved;
//!    - else, recalibration, when it cuts the error by 4× and brings every floor within
//!      [`Gates::recalibration_noise_factor`] (3) of the noise level: `recalibrate`, with the
//!      parameters that moved;
//!    - else **discovery** ([`discover`]): sparse regression of the missing force over
//!      candidate functions of one storey's or floor's state, linearised through the structure;
//!      the terms found become the shear FMU's `discovered` effect, refitted with the physics
//!      through FMI and gated the same way (it also runs, and may replace the library's answer,
//!      when that answer leaves more than the noise): `add_physics` with a `discovered` effect;
//!    - else `update_data_model`: nothing in the library or sparse explains the error; the
//!      corrector should learn it (no effect is named).
//! 6. **Localise**: the residual acceleration times the floor masses is the force the model
//!    misses on each floor (a velocity or displacement sensor's residual differentiated once
//!    or twice; every other stage reads each channel in its own quantity: acc<i>, vel<i>,
//!    disp<i>); summed from the top it is the storey shear the model misses, which
//!    is correlated with each storey's drift (linear, cubic) and each floor's velocity sign
//!    (friction). Reported as evidence beside the fits.
//!
//! # Where each stage lives
//!
//! [`diagnose`] below reads as its stages, one submodule each: `baseline` (set-up: the record's
//! blocks, the twin and its physics run and scored, the report so far), `significance` (stage
//! 2), [`sensor`] (3a), `screen` (the library screened), `race` (on a long record, the
//! screened candidates raced on its head), `round_one` (the recalibration and the
//! candidates fitted alone), `search` (forward selection through [`select`], and discovery
//! through [`discover`]), `verdict` (the action and its evidence). They share `channels` (the
//! record's channels), `physics` (the physics run), `fit` (one alternative's fit), `localise`
//! (the missing force) and [`effects`] (a fit's estimates and the effect's report, read by the
//! verdict, the selection, discovery and `add`).
//!
//! `twin add-physics` refuses a `sensor_fault` diagnosis (not physics); it switches the chosen
//! effects on (a discovered one with its terms), estimates their parameters on the whole record
//! (more starts), optionally refines the physics parameters jointly, and writes the new twin.

pub mod add;
pub mod ambient;
mod baseline;
pub mod candidate;
pub mod change;
mod channels;
pub mod discover;
pub(crate) mod effects;
mod fit;
mod localise;
mod options;
mod physics;
mod race;
pub mod report;
mod round_one;
mod screen;
mod search;
pub mod select;
pub mod sensor;
mod significance;
mod verdict;

use std::path::PathBuf;
use std::time::Instant;

use serde::Serialize;

use crate::cosim::import::ImportError;
use crate::twin::data::Measurement;
use crate::twin::Twin;
use crate::twin::TwinError;
use crate::workflows::calibrate::CalibrateError;

use baseline::baseline;
use channels::worst;
use race::raced;
use round_one::{baseline_evidence, fit_round_one, report_round_one};
use screen::screened;
use search::{discovery, search_library};
use sensor::{faulty_sensor, report_sensor_fault};
use significance::{none_without_fits, significance};

// What the stages share, read by the other submodules as `super::…`.
use effects::{effect_report, estimates};
use fit::{fit, fitting_twin, with_switches, Fitted, Split};
use physics::{prior_scales, run_physics, PhysicsReals, PhysicsRun};

/// What can stop a diagnosis or an added effect. The messages say which record, twin or file.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// A twin, record or option that cannot be diagnosed.
    #[error("{0}")]
    Setup(String),
    #[error("{context}")]
    In {
        context: String,
        #[source]
        source: Box<DiagnoseError>,
    },
    #[error("reading the diagnosis {}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: not JSON", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{0}")]
    Plot(String),
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
    #[error(transparent)]
    Run(#[from] crate::twin::run::RunError),
}

pub type Result<T, E = DiagnoseError> = std::result::Result<T, E>;
pub use add::{
    add_hybrid_contact, add_physics, effects_from_report, refit_over_records, with_record,
    HybridAddReport, Refit, JOINT_STARTS,
};
pub use ambient::{diagnose_ambient, AmbientDiagnosis};
pub use candidate::{Addition, Candidate, Kind, Scales, Side};
pub use options::{check_sites, parse_additions, parse_candidates};
pub use report::*;

pub use baseline::blocks;
pub(crate) use channels::Channels;
pub(crate) use effects::Estimates;
pub use fit::{fit_substeps, FIT_STEP_PHASE};
pub use options::FIT_SUBSTEPS;
pub use options::{DiagnoseOptions, Gates, Progress};
pub(crate) use physics::storeys_of;
pub use race::{RACE_HEAD, RACE_MIN, RACE_SHOWS};
pub use screen::{SCREEN_DECISIVE, SCREEN_KEEP, SCREEN_SITES};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Action {
    None,
    Recalibrate,
    AddPhysics,
    UpdateDataModel,
    /// One sensor is faulty (gain, offset, drift, dead): not physics.
    SensorFault,
}

impl Action {
    pub fn name(self) -> &'static str {
        match self {
            Action::None => "none",
            Action::Recalibrate => "recalibrate",
            Action::AddPhysics => "add_physics",
            Action::UpdateDataModel => "update_data_model",
            Action::SensorFault => "sensor_fault",
        }
    }
}

/// Diagnose `twin` on `data` (see the module documentation).
pub fn diagnose(twin: &Twin, data: &Measurement, options: &DiagnoseOptions) -> Result<Diagnosis> {
    if let Some(after) = change::after_the_change(twin, data, options)? {
        let mut diagnosis = diagnose(&after.twin, &after.data, &after.options)?;
        diagnosis.changed_at = Some(after.at);
        return Ok(diagnosis);
    }
    let started = Instant::now();
    let (b, mut diagnosis) = baseline(twin, data, options)?;
    let gates = options.gates;

    // 2. Significant, statistically and practically? Unless both, nothing is fitted.
    let alarm = significance(&b, &gates, &mut diagnosis);
    if !alarm.raised && !options.always_fit {
        none_without_fits(&mut diagnosis, alarm.none_reason);
        return Ok(finished(diagnosis, started));
    }

    // 3a. Faulty sensors: one that explains the error is the verdict, nothing else fitted.
    let sensor_fault = faulty_sensor(&b, data, &gates, &mut diagnosis);
    if let Some((fault, reason)) = sensor_fault.as_ref().filter(|_| alarm.raised) {
        report_sensor_fault(&b, data, &mut diagnosis, fault, reason);
        if !options.always_fit {
            return Ok(finished(diagnosis, started));
        }
    }

    // 3–4. The alternatives, in parallel: the recalibration and every screened candidate.
    let baseline_evidence = baseline_evidence(&b, data, options)?;
    let ground = b.ground(data, options);
    let library = screened(&ground, &mut diagnosis, b.candidates.clone())?;
    let candidates = raced(&ground, &mut diagnosis, library.clone())?;
    let results = fit_round_one(&ground, &candidates, baseline_evidence)?;
    let before_worst = worst(&b.scores.nmse_before_held_out);
    let round = report_round_one(&ground, &mut diagnosis, &candidates, results, before_worst)?;
    let order = by_evidence(&diagnosis.candidates);

    // 5. Forward selection (see `select`), while the error is still to be explained.
    // A full round (on recalibrated physics) tries every screened candidate, raced or not.
    let ctx = select::Context::of(&b, data, options, baseline_evidence, &library);
    let explain = alarm.raised && sensor_fault.is_none();
    let search = search_library(&ctx, &b, &mut diagnosis, &round, before_worst, explain)?;

    // 7. Discovery (see `discover`): when nothing above explains the error, or the library's
    // combination leaves more than the noise.
    let discovery = discovery(&ctx, &b.base_run, &search, &mut diagnosis)?;

    // 6. Decide: `none` and a sensor fault were decided above (the alternatives then fitted for
    // the report only).
    if !alarm.raised {
        diagnosis.action = Action::None;
        diagnosis.reason = alarm.none_reason;
    } else if explain {
        let verdict = b.verdict(data.dt, before_worst, round.recal_worst);
        verdict.decide(&mut diagnosis, &round.recal, &search, &discovery, &order);
    }
    put_in_order(&mut diagnosis, order);
    Ok(finished(diagnosis, started))
}

/// The diagnosis completed: each channel's visibility measured, the seconds it took.
fn finished(mut diagnosis: Diagnosis, started: Instant) -> Diagnosis {
    diagnosis.measure_visibility();
    diagnosis.seconds = started.elapsed().as_secs_f64();
    diagnosis
}

/// The indices of the reported candidates, highest evidence first.
fn by_evidence(candidates: &[CandidateReport]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..candidates.len()).collect();
    order.sort_by(|&a, &b| candidates[b].evidence.total_cmp(&candidates[a].evidence));
    order
}

/// The reported candidates in `order`.
fn put_in_order(diagnosis: &mut Diagnosis, order: Vec<usize>) {
    diagnosis.candidates = order
        .into_iter()
        .map(|i| diagnosis.candidates[i].clone())
        .collect();
}
