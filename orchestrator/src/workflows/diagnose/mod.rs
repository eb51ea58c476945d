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
//! `twin add-physics` refuses a `sensor_fault` diagnosis (not physics); it switches the chosen
//! effects on (a discovered one with its terms), estimates their parameters on the whole record
//! (more starts), optionally refines the physics parameters jointly, and writes the new twin.

pub mod add;
pub mod ambient;
pub mod candidate;
pub mod change;
pub mod discover;
mod options;
pub mod report;
pub mod select;
pub mod sensor;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde::Serialize;
use structure::building::parameter_names;
use structure::channel::{Channel, Quantity};
use structure::effects::{Law, Placement, Term};

use crate::cosim::import::ImportError;
use crate::cosim::import::{Fmu, ModelDescription, UnpackedFmu};
use crate::evaluation::compare::FailingWindow;
use crate::evaluation::stats::{first_after_transient, nmse, rms, variance};
use crate::twin::data::Measurement;
use crate::twin::noise::NoiseVariances;
use crate::twin::run::{run_and_compare_with, Compared, Tolerance};
use crate::twin::simulator::Simulator;
use crate::twin::TwinError;
use crate::twin::{ParameterValue, Twin, PHYSICS};
use crate::workflows::calibrate::CalibrateError;
use crate::workflows::calibrate::{
    calibrate, fixed_log_evidence, Calibration, CalibrationSetup, Prior,
};
use crate::workflows::train::physics_only;

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
pub use discover::Found;
pub use options::{check_sites, parse_additions, parse_candidates};
pub use report::*;
pub use sensor::{SensorFit, SensorSd};

/// The decision thresholds (see the module documentation).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Gates {
    /// `none` when every floor's NMSE ≤ this × the NMSE noise alone explains.
    pub none_factor: f64,
    /// An alternative must cut the worst-floor held-out NMSE by at least this factor.
    pub required_cut: f64,
    /// An effect must beat recalibration's worst-floor held-out NMSE by this factor.
    pub beat_recalibration: f64,
    /// Recalibration explains the error when every floor's held-out NMSE is within this factor
    /// of the noise level.
    pub recalibration_noise_factor: f64,
    /// Forward selection adds an effect that cuts the model's worst-floor held-out NMSE by at
    /// least this factor (the combination must still meet `required_cut` and
    /// `beat_recalibration` as a whole).
    pub step_cut: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
}

impl Default for Gates {
    fn default() -> Self {
        Gates {
            none_factor: 2.0,
            required_cut: 4.0,
            beat_recalibration: 2.0,
            recalibration_noise_factor: 3.0,
            step_cut: 1.5,
            max_effects: 3,
        }
    }
}

/// Candidates fitted through the FMU at most when the library is the default (the paper rig's
/// whole library is 15: contact at three storeys on three sides, cubic per storey, friction per
/// floor; a taller building's is 5 per storey).
pub const SCREEN_KEEP: usize = 15;

/// The default library is screened before any candidate is fitted through the FMU
/// ([`discover::screen`], the linearised score of every candidate from the twin's residual) and
/// only the candidates at this many sites are fitted: the sites (a storey, or a floor for
/// friction) whose best candidate scores best, every kind and side at each. A site rather than
/// a candidate, because a strong effect's linearisation can favour another kind at the same
/// storey (a strong cubic spring of storey 3 scores like a two-sided contact there) but not
/// another storey. Only when the screen is decisive: its best site's linearised force leaves at
/// most [`SCREEN_DECISIVE`] of the residual. Otherwise (the effect barely seen through the
/// linearisation: a cubic spring of a five-storey frame under ground motion seen by three
/// accelerometers left 0.98 of it, below friction at three floors) the best [`SCREEN_KEEP`]
/// candidates are fitted.
pub const SCREEN_SITES: usize = 3;

/// The screen decides by sites when its best site explains at least half the residual.
pub const SCREEN_DECISIVE: f64 = 0.5;

/// Sub-steps while fitting candidates. The fits run the shear FMU with `integrator` = 2: contacts
/// alone step exactly (their cost does not depend on sub-steps), every other effect (cubic,
/// friction, discovered terms) with this many fixed RK4 sub-steps, and a fit's cost is
/// proportional to them. RK4's error falls 16× per doubling: 64 sub-steps give 1.1e-9 %
/// worst-floor NMSE for a 1e9 N/m³ cubic on the paper's prior damping
/// (`fmu-shear/tests/effects_accuracy.rs`), so about 2e-2 % at 8, below the differences the
/// decision gates look at (factors of 2 and 4 on NMSEs of 0.1 % and up). Measured on dataset3:
/// every candidate's NMSE after its fit within 2e-3 % of the fit at 16 sub-steps, the same
/// decision, 30 % less CPU. The fitted parameters are then scored with the twin's own integrator.
pub const FIT_SUBSTEPS: i32 = 8;

/// The largest phase (radians) of the structure's fastest mode over one RK4 sub-step of a fit.
/// The paper's rig at its prior means (fastest mode 7.97 Hz) sampled at 51.2 Hz takes 0.98 rad
/// a sample, so [`FIT_SUBSTEPS`] there (0.12 rad each, whose error is measured above). A record
/// sampled far above its structure's modes needs fewer for the same error per period: the
/// 4-storey frame at 322.58 Hz (fastest mode 8.4 Hz) takes 2. Below the rig's 0.12 so
/// that its records and every slower-sampled one keep the full [`FIT_SUBSTEPS`].
pub const FIT_STEP_PHASE: f64 = 0.1;

/// The RK4 sub-steps a sample of the fits take: as many as keep the structure's fastest mode
/// (`fastest_hz`) within [`FIT_STEP_PHASE`] a sub-step at the sampling step `dt`, at most
/// `most`, at least one.
pub fn fit_substeps(most: i32, fastest_hz: f64, dt: f64) -> i32 {
    let phase = 2.0 * std::f64::consts::PI * fastest_hz * dt;
    if !(phase.is_finite() && phase > 0.0) {
        return most;
    }
    ((phase / FIT_STEP_PHASE).ceil() as i32).clamp(1, most.max(1))
}

#[derive(Clone, Debug)]
pub struct DiagnoseOptions {
    pub transient: f64,
    /// Length (s) of the alternating fitted and held-out blocks.
    pub block: f64,
    pub gates: Gates,
    /// The candidates tried (None: the whole library at every site of the twin's building,
    /// [`Candidate::library`]).
    pub candidates: Option<Vec<Candidate>>,
    /// Optimiser starts per candidate, and for the recalibration.
    pub starts: usize,
    pub recalibration_starts: usize,
    /// Simulations one start of a candidate fit may use.
    pub simulations_per_start: usize,
    pub threads: usize,
    pub seed: u64,
    /// Fit every alternative even when the error is within the noise (`none`).
    pub always_fit: bool,
    /// Practical significance, NMSE % (None: the twin's default, see [`Tolerance::resolve`]).
    pub tolerance: Option<f64>,
    /// RK4 sub-steps of the shear FMU while candidates are fitted (its `substeps`); each fit is
    /// then scored at the twin's own sub-steps. `None`: the twin's own throughout.
    pub fit_substeps: Option<i32>,
    /// Told what the diagnosis is doing, stage by stage (a terminal's progress line).
    pub progress: Option<Progress>,
    /// The time (s of the record) the structure changed at, when known (a located change):
    /// the twin holds before it, and what came after is diagnosed from the state the twin
    /// reached there ([`change`]).
    pub changed_at: Option<f64>,
}

/// Where a diagnosis says what it is doing.
#[derive(Clone)]
pub struct Progress(pub std::sync::Arc<dyn Fn(&str) + Send + Sync>);

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Progress")
    }
}

impl DiagnoseOptions {
    fn tell(&self, what: &str) {
        if let Some(p) = &self.progress {
            (p.0)(what);
        }
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            block: 1.0,
            gates: Gates::default(),
            candidates: None,
            starts: 3,
            recalibration_starts: 8,
            simulations_per_start: 250,
            threads: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            seed: 1,
            always_fit: false,
            tolerance: None,
            fit_substeps: Some(FIT_SUBSTEPS),
            progress: None,
            changed_at: None,
        }
    }
}

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

/// One physics run: every floor's acceleration, velocity and displacement and every storey's
/// drift, floor (storey) 1 first.
#[derive(Clone)]
struct PhysicsRun {
    /// Per floor: absolute accelerations, and velocities and displacements relative to the
    /// ground.
    acc: Vec<Vec<f64>>,
    velocity: Vec<Vec<f64>>,
    displacement: Vec<Vec<f64>>,
    /// Per storey.
    drift: Vec<Vec<f64>>,
}

impl PhysicsRun {
    /// Floor `floor`'s (from 0) series of `quantity`.
    fn at(&self, floor: usize, quantity: Quantity) -> &[f64] {
        match quantity {
            Quantity::Velocity => &self.velocity[floor],
            Quantity::Displacement => &self.displacement[floor],
            _ => &self.acc[floor],
        }
    }
}

/// The storeys of the building `twin` models: its [`Twin::structure`] (what the record's guard
/// checked the record against), the one place a diagnosis learns them.
pub(crate) fn storeys_of(twin: &Twin) -> Result<usize> {
    Ok(twin.structure()?.storeys())
}

/// The measured channels a diagnosis reads, in the record's order: each one's name, floor,
/// quantity and values (SI). Accelerometers, velocity and displacement sensors alike: each
/// channel is predicted, fitted and scored in its own quantity; only the localisation, which
/// reads forces, takes the residual as an acceleration ([`Channels::residual_acceleration`]).
/// A floor the structure lacks is refused by name.
#[derive(Clone, Debug)]
pub(crate) struct Channels {
    pub names: Vec<String>,
    /// Each channel's floor, from 0.
    pub floors: Vec<usize>,
    /// Each channel's quantity: acceleration (absolute), velocity or displacement (relative
    /// to the ground), as the record's `acc<i>`, `vel<i>`, `disp<i>` and the shear FMU's
    /// outputs of those names.
    pub quantities: Vec<Quantity>,
    pub measured: Vec<Vec<f64>>,
}

impl Channels {
    pub fn of(data: &Measurement, storeys: usize) -> Result<Channels> {
        let mut out = Channels {
            names: Vec::new(),
            floors: Vec::new(),
            quantities: Vec::new(),
            measured: Vec::new(),
        };
        for signal in &data.responses {
            let name = signal.channel.name();
            let (quantity, floor) = match signal.channel {
                Channel::Response {
                    quantity:
                        q @ (Quantity::Acceleration | Quantity::Velocity | Quantity::Displacement),
                    floor,
                } => (q, floor),
                _ => {
                    return Err(DiagnoseError::Setup(format!(
                        "{}: column '{name}': a diagnosis reads responses (acc<i>, vel<i>, \
                         disp<i>); the record has {}",
                        data.path.display(),
                        data.channel_names().join(", ")
                    )))
                }
            };
            if !(1..=storeys).contains(&floor) {
                return Err(DiagnoseError::Setup(format!(
                    "{}: column '{name}': the twin's building has floors 1 to {storeys}",
                    data.path.display()
                )));
            }
            out.names.push(name);
            out.floors.push(floor - 1);
            out.quantities.push(quantity);
            out.measured.push(signal.values.clone());
        }
        if out.names.is_empty() {
            return Err(DiagnoseError::Setup(format!(
                "{}: no response channel (acc<i>, vel<i>, disp<i>) to diagnose",
                data.path.display()
            )));
        }
        Ok(out)
    }

    /// The (floor, quantity) of each channel: where and what a sensitivity is read at.
    pub fn sensors(&self) -> Vec<(usize, Quantity)> {
        self.floors
            .iter()
            .copied()
            .zip(self.quantities.iter().copied())
            .collect()
    }

    /// How each channel enters the diagnosis (its visibility is measured at the end).
    pub fn sensing(&self) -> Vec<Sensing> {
        self.names
            .iter()
            .zip(&self.quantities)
            .map(|(name, q)| {
                let (quantity, localisation) = match q {
                    Quantity::Velocity => ("velocity", "differentiated once"),
                    Quantity::Displacement => ("displacement", "differentiated twice"),
                    _ => ("acceleration", "as measured"),
                };
                Sensing {
                    channel: name.clone(),
                    quantity: quantity.into(),
                    localisation: localisation.into(),
                    visibility: None,
                }
            })
            .collect()
    }

    /// Per channel, what the physics run `run` gives at its floor in its quantity.
    fn predicted(&self, run: &PhysicsRun) -> Vec<Vec<f64>> {
        self.sensors()
            .into_iter()
            .map(|(f, q)| run.at(f, q).to_vec())
            .collect()
    }

    /// Per channel, measured minus what the physics run `run` gives, in the channel's quantity.
    fn residuals(&self, run: &PhysicsRun) -> Vec<Vec<f64>> {
        self.measured
            .iter()
            .zip(self.predicted(run))
            .map(|(measured, predicted)| {
                measured
                    .iter()
                    .zip(&predicted)
                    .map(|(m, p)| m - p)
                    .collect()
            })
            .collect()
    }

    /// Channel `c`'s residual (measured − `predicted`) as an acceleration: as it is for an
    /// accelerometer, differentiated once (velocity) or twice (displacement) by central
    /// differences (one-sided at the ends) on the sampling interval `dt`. Differencing
    /// amplifies the noise in proportion to the frequency, so such a channel's localisation
    /// is noisier at high frequency; the fits never use it.
    pub fn residual_acceleration(&self, c: usize, predicted: &[f64], dt: f64) -> Vec<f64> {
        let residual: Vec<f64> = self.measured[c]
            .iter()
            .zip(predicted)
            .map(|(m, p)| m - p)
            .collect();
        match self.quantities[c] {
            Quantity::Velocity => derivative(&residual, dt),
            Quantity::Displacement => derivative(&derivative(&residual, dt), dt),
            _ => residual,
        }
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// The index of the channel named `name` (one of this record's).
    pub fn index(&self, name: &str) -> usize {
        self.names.iter().position(|n| n == name).unwrap_or(0)
    }

    /// NMSE per channel of `predicted` (per channel) over the samples `idx`.
    pub fn nmse_on(&self, predicted: &[Vec<f64>], idx: &[usize]) -> Vec<f64> {
        nmse_on(&self.measured, predicted, idx)
    }
}

/// The derivative of a sampled series by central differences, one-sided at the ends.
fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a) as f64 * dt)
        })
        .collect()
}

/// Run the physics component of `twin` with `extra` parameters (and `values` for `names`).
fn run_physics(
    twin: &Twin,
    data: &Measurement,
    extra: &BTreeMap<String, ParameterValue>,
    names: &[String],
    values: &[f64],
) -> Result<PhysicsRun> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let fmu = Fmu::open(&component.fmu_path)?;
    let storeys = storeys_of(twin)?;
    let mut base = component.parameters.clone();
    base.extend(extra.clone());
    for n in names {
        base.remove(n);
    }
    let vrs = names
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<u32>, _>>()?;
    let recorded: Vec<String> = ["acc", "drift", "vel", "disp"]
        .iter()
        .flat_map(|q| (1..=storeys).map(move |i| format!("{q}{i}")))
        .collect();
    let outputs = recorded
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<u32>, _>>()?;
    let mut sim = Simulator::for_record(&fmu, base, data, "diagnose")?;
    let mut out: Vec<Vec<f64>> = vec![Vec::new(); recorded.len()];
    sim.record(&vrs, values, &outputs, &mut out)?;
    let displacement = out.split_off(3 * storeys);
    let velocity = out.split_off(2 * storeys);
    let drift = out.split_off(storeys);
    Ok(PhysicsRun {
        acc: out,
        velocity,
        displacement,
        drift,
    })
}

/// The physics component's real parameters: the twin's value, else the FMU's start value, read
/// from its modelDescription, which is opened once.
struct PhysicsReals {
    /// The building's storeys.
    storeys: usize,
    given: BTreeMap<String, ParameterValue>,
    model_description: ModelDescription,
    fmu_name: String,
}

impl PhysicsReals {
    fn of(twin: &Twin) -> Result<Self> {
        let component = twin.component(PHYSICS).ok_or_else(|| {
            DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component"))
        })?;
        // The model description alone: nothing here runs the FMU.
        let model_description = UnpackedFmu::open(&component.fmu_path)?.model_description;
        Ok(PhysicsReals {
            storeys: storeys_of(twin)?,
            given: component.parameters.clone(),
            model_description,
            fmu_name: component.fmu_name.clone(),
        })
    }

    /// The structure's fastest undamped mode (Hz) at these values.
    fn fastest_mode_hz(&self) -> Result<f64> {
        let per_storey = |p: char| -> Result<Vec<f64>> {
            (1..=self.storeys)
                .map(|i| self.get(&format!("{p}{i}")))
                .collect()
        };
        let structure = ::structure::building::Structure {
            mass: per_storey('m')?,
            damping: per_storey('c')?,
            stiffness: per_storey('k')?,
            excitation: Default::default(),
        };
        Ok(structure
            .natural_frequencies()
            .last()
            .copied()
            .unwrap_or(f64::NAN))
    }

    fn get(&self, name: &str) -> Result<f64> {
        if let Some(ParameterValue::Real(x)) = self.given.get(name) {
            return Ok(*x);
        }
        self.model_description
            .variable(name)
            .and_then(|v| v.start.as_deref())
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| {
                DiagnoseError::Setup(format!("{}: no value for '{name}'", self.fmu_name))
            })
    }
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// NMSE per channel over the samples `idx`.
fn nmse_on(measured: &[Vec<f64>], predicted: &[Vec<f64>], idx: &[usize]) -> Vec<f64> {
    measured
        .iter()
        .zip(predicted)
        .map(|(measured, predicted)| {
            let y: Vec<f64> = idx.iter().map(|&k| measured[k]).collect();
            let p: Vec<f64> = idx.iter().map(|&k| predicted[k]).collect();
            nmse(&y, &p)
        })
        .collect()
}

fn worst(x: &[f64]) -> f64 {
    x.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

/// The scales of the candidates' priors on this record: the twin's storey stiffness, and the
/// RMS after the transient of the physics run's drifts and velocities and of the force.
fn prior_scales(
    reals: &PhysicsReals,
    run: &PhysicsRun,
    data: &Measurement,
    first: usize,
) -> Result<Scales> {
    let stiffness = (1..=run.drift.len())
        .map(|s| reals.get(&format!("k{s}")))
        .collect::<Result<Vec<f64>>>()?;
    // The load's size: the force, or under ground motion the whole building's inertia times
    // the ground's acceleration (the load −M·1·a_g of the relative coordinates).
    let load = match data.excitation.channel {
        ::structure::channel::Channel::Excitation(::structure::channel::ExcitationKind::Force) => {
            1.0
        }
        _ => (1..=run.drift.len())
            .map(|f| reals.get(&format!("m{f}")))
            .sum::<Result<f64>>()?,
    };
    Ok(Scales {
        stiffness,
        drift_rms: run.drift.iter().map(|d| rms(&d[first..])).collect(),
        velocity_rms: run.velocity.iter().map(|v| rms(&v[first..])).collect(),
        force_rms: load * rms(&data.excitation.values[first..]),
    })
}

/// What one alternative's fit gives.
#[derive(Clone)]
struct Fitted {
    calibration: Calibration,
    evidence: f64,
    /// Per channel.
    nmse_after: Vec<f64>,
    nmse_held_out: Vec<f64>,
    run: PhysicsRun,
}

/// The physics twin with a candidate's switches on.
fn with_switches(physics: &Twin, candidate: Option<&Candidate>) -> Result<Twin> {
    let mut out = physics.duplicate();
    if let Some(c) = candidate {
        let component = out.component_mut(PHYSICS).ok_or_else(|| {
            DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component"))
        })?;
        component.parameters.extend(c.switches());
    }
    Ok(out)
}

/// The twin a candidate is fitted with on a record sampled every `dt`: the shear FMU at
/// `most` RK4 sub-steps, fewer when every effect switched on is a contact or a cubic spring
/// (the structure's fastest mode sets them, [`fit_substeps`]; friction and discovered terms
/// keep `most`, as their force laws have time scales of their own — a friction fitted at two
/// sub-steps a sample on the 4-storey contact record went to a sharp law the finer scoring run
/// rejected), and, where the FMU has the choice (`integrator` = 2), contacts alone still
/// stepped exactly (they are cheaper so than by sub-steps) while every other effect takes the
/// fixed sub-steps instead of the error-controlled path, whose tolerance the scoring run keeps.
fn fitting_twin(twin: &Twin, most: i32, dt: f64) -> Result<Twin> {
    let mut coarse = twin.duplicate();
    let reals = PhysicsReals::of(&coarse)?;
    let component = coarse
        .component_mut(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let polynomial = component
        .parameters
        .iter()
        .filter(|(name, value)| {
            name.ends_with("_enabled") && **value == ParameterValue::Boolean(true)
        })
        .all(|(name, _)| name.starts_with("cubic") || name.starts_with("contact"));
    let substeps = if polynomial {
        fit_substeps(most, reals.fastest_mode_hz()?, dt)
    } else {
        most
    };
    let chooses = reals.model_description.variable("integrator").is_some();
    component
        .parameters
        .insert("substeps".into(), ParameterValue::Integer(substeps));
    if chooses {
        component
            .parameters
            .insert("integrator".into(), ParameterValue::Integer(2));
    }
    Ok(coarse)
}

/// The samples a fit uses: the fitted ones (`mask`), the held-out ones it is scored on, the
/// first after the transient, and whether its starts climb the ladder of the record's heads
/// (`calibrate::ladder`; see [`climbs`]).
#[derive(Clone, Copy)]
pub(super) struct Split<'a> {
    pub mask: &'a [bool],
    pub held_out: &'a [usize],
    pub first: usize,
    pub climb: bool,
}

/// Whether a diagnosis's fits on a record of `n` samples climb the ladder of its heads: when
/// the record is long enough to have one (`ladder::rungs`) and the twin's error shows on its
/// first rung (a failing window starts there), so that an effect or a change the fits are to
/// find is in the samples the starts are screened on. An effect that shows only late in the
/// record is fitted on every sample from every start.
fn climbs(n: usize, time: &[f64], failing: &[FailingWindow]) -> bool {
    let rungs = crate::workflows::calibrate::ladder::rungs(n);
    let Some(&head) = rungs.first() else {
        return false;
    };
    let head_end = time
        .get(head.saturating_sub(1))
        .copied()
        .unwrap_or(f64::NEG_INFINITY);
    failing.iter().any(|w| w.start < head_end)
}

/// Fit `parameters` (with `priors`) of `twin`'s physics on the `split`'s fitted samples and
/// score the fit on the whole record and on the held-out samples.
#[allow(clippy::too_many_arguments)]
fn fit(
    twin: &Twin,
    data: &Measurement,
    parameters: Vec<String>,
    priors: BTreeMap<String, Prior>,
    split: Split,
    starts: usize,
    threads: usize,
    simulations_per_start: usize,
    options: &DiagnoseOptions,
    baseline_evidence: f64,
    initial: &BTreeMap<String, f64>,
    starts_at: Vec<BTreeMap<String, f64>>,
) -> Result<Fitted> {
    let setup = CalibrationSetup {
        parameters: parameters.clone(),
        priors,
        transient: options.transient,
        starts,
        seed: options.seed,
        threads,
        mask: Some(split.mask.to_vec()),
        simulations_per_start,
        initial: initial.clone(),
        starts_at,
        climb: split.climb,
        ..CalibrationSetup::default()
    };
    let calibration = match options.fit_substeps {
        Some(most) => calibrate(&fitting_twin(twin, most, data.dt)?, data, &setup)?,
        None => calibrate(twin, data, &setup)?,
    };
    let values: Vec<f64> = calibration.parameters.iter().map(|p| p.value).collect();
    let run = run_physics(twin, data, &BTreeMap::new(), &parameters, &values)?;
    let after: Vec<usize> = (split.first..data.len()).collect();
    let channels = Channels::of(data, run.acc.len())?;
    let predicted = channels.predicted(&run);
    Ok(Fitted {
        evidence: calibration.log_evidence - baseline_evidence,
        nmse_after: channels.nmse_on(&predicted, &after),
        nmse_held_out: channels.nmse_on(&predicted, split.held_out),
        run,
        calibration,
    })
}

/// The screen's choice: when it is decisive, the candidates at the [`SCREEN_SITES`] sites
/// whose best candidate scores lowest (every kind and side there), else every candidate; at
/// most [`SCREEN_KEEP`] of them (the lowest scores first), in the library's order; and the rest
/// with their scores.
fn screen_sites(
    candidates: Vec<Candidate>,
    scores: Vec<f64>,
) -> (Vec<Candidate>, Vec<(Candidate, f64)>) {
    let site = |c: &Candidate| (c.placement() == Placement::Floor, c.at);
    let mut best: Vec<((bool, usize), f64)> = Vec::new();
    for (c, &score) in candidates.iter().zip(&scores) {
        match best.iter_mut().find(|(s, _)| *s == site(c)) {
            Some((_, b)) => *b = b.min(score),
            None => best.push((site(c), score)),
        }
    }
    best.sort_by(|a, b| a.1.total_cmp(&b.1));
    let decisive = best.first().is_some_and(|b| b.1 <= SCREEN_DECISIVE);
    let take = if decisive { SCREEN_SITES } else { best.len() };
    let sites: Vec<(bool, usize)> = best.iter().take(take).map(|b| b.0).collect();
    let (mut kept, mut dropped): (Vec<_>, Vec<_>) = candidates
        .into_iter()
        .zip(scores)
        .enumerate()
        .partition(|(_, (c, _))| sites.contains(&site(c)));
    if kept.len() > SCREEN_KEEP {
        kept.sort_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        dropped.extend(kept.split_off(SCREEN_KEEP));
        kept.sort_by_key(|k| k.0);
    }
    dropped.sort_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
    (
        kept.into_iter().map(|(_, (c, _))| c).collect(),
        dropped.into_iter().map(|(_, cs)| cs).collect(),
    )
}

/// Calls its closure when dropped: a fit counts as done however it ended.
struct Told<F: FnMut()>(F);

impl<F: FnMut()> Drop for Told<F> {
    fn drop(&mut self) {
        (self.0)()
    }
}

/// The fitted and held-out samples: after the transient, alternate blocks of `block` seconds.
pub fn blocks(time: &[f64], first: usize, block: f64) -> (Vec<bool>, Vec<usize>) {
    let mut mask = vec![false; time.len()];
    let mut held = Vec::new();
    let t0 = time.get(first).copied().unwrap_or(0.0);
    for k in first..time.len() {
        let b = ((time[k] - t0) / block).floor() as i64;
        if b % 2 == 0 {
            mask[k] = true;
        } else {
            held.push(k);
        }
    }
    (mask, held)
}

#[derive(Clone, Copy)]
enum Job {
    Recalibrate,
    Effect(Candidate),
}

impl Job {
    /// The order of a job's usual cost, dearest first: the smooth effects (RK4 sub-steps),
    /// then the recalibration, then the contacts (exact maps).
    fn cost_rank(&self) -> u8 {
        match self {
            Job::Effect(c) if c.kind == Kind::Friction => 0,
            Job::Effect(c) if c.kind == Kind::Cubic => 1,
            Job::Recalibrate => 2,
            Job::Effect(_) => 3,
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
    let candidates = screened(&ground, &mut diagnosis, b.candidates.clone())?;
    let results = fit_round_one(&ground, &candidates, baseline_evidence)?;
    let before_worst = worst(&b.scores.nmse_before_held_out);
    let round = report_round_one(&ground, &mut diagnosis, &candidates, results, before_worst)?;
    let order = by_evidence(&diagnosis.candidates);

    // 5. Forward selection (see `select`), while the error is still to be explained.
    let ctx = b.selection_context(data, options, baseline_evidence, &candidates);
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

/// Whether the twin's error raises the alarm, and why not when it does not.
struct Alarm {
    /// Significant both statistically and practically.
    raised: bool,
    /// The reason a `none` gives.
    none_reason: String,
}

/// Stage 2: the error is statistically significant when a channel's NMSE exceeds
/// [`Gates::none_factor`] × its explained level, practically when the worst exceeds the
/// tolerance; both go into the diagnosis. The alarm.
fn significance(b: &Baseline, gates: &Gates, diagnosis: &mut Diagnosis) -> Alarm {
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
fn none_without_fits(diagnosis: &mut Diagnosis, none_reason: String) {
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

/// The diagnosis completed: each channel's visibility measured, the seconds it took.
fn finished(mut diagnosis: Diagnosis, started: Instant) -> Diagnosis {
    diagnosis.measure_visibility();
    diagnosis.seconds = started.elapsed().as_secs_f64();
    diagnosis
}

/// Stage 3a, faulty sensors: per channel, the measured as gain·ŷ + offset + drift·t of the
/// twin's prediction, least squares on the fitted blocks, scored on the held-out ones, into the
/// diagnosis's sensor candidates. The one fault that explains the error, with its reason.
fn faulty_sensor(
    b: &Baseline,
    data: &Measurement,
    gates: &Gates,
    diagnosis: &mut Diagnosis,
) -> Option<(SensorFit, String)> {
    let fitted_idx: Vec<usize> = (0..b.samples.n).filter(|&k| b.samples.mask[k]).collect();
    diagnosis.sensor_candidates = (0..b.nc)
        .filter_map(|c| {
            sensor::fit_channel(
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
fn report_sensor_fault(
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

/// The log evidence of the twin's physics as it is, on the fitted blocks: every alternative's
/// evidence is a log Bayes factor against it.
fn baseline_evidence(b: &Baseline, data: &Measurement, options: &DiagnoseOptions) -> Result<f64> {
    let evidence_setup = CalibrationSetup {
        transient: options.transient,
        mask: Some(b.samples.mask.clone()),
        ..CalibrationSetup::default()
    };
    Ok(fixed_log_evidence(&b.physics, data, &evidence_setup)?)
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

/// Whether the recalibration explains the error: it cuts the worst-floor held-out NMSE by
/// [`Gates::required_cut`] and brings every channel within
/// [`Gates::recalibration_noise_factor`] × its noise level.
fn recalibration_explains(
    b: &Baseline,
    gates: &Gates,
    round: &RoundOne,
    before_worst: f64,
) -> bool {
    round.recal_worst * gates.required_cut <= before_worst
        && (0..b.nc).all(|c| {
            round.recal.nmse_held_out[c]
                <= gates.recalibration_noise_factor * b.scores.noise_nmse_held_out[c]
        })
}

/// Stage 5: whether the recalibration explains the error, and, when the error is to be
/// explained (`explain`), the forward selection (see [`select`]) from round 1's fits, the
/// candidates that passed alone first; its steps go into the diagnosis.
fn search_library(
    ctx: &select::Context,
    b: &Baseline,
    diagnosis: &mut Diagnosis,
    round: &RoundOne,
    before_worst: f64,
    explain: bool,
) -> Result<Search> {
    let gates = ctx.options.gates;
    let recal_explains = recalibration_explains(b, &gates, round, before_worst);
    let selection = if explain {
        let passes: Vec<bool> = diagnosis.candidates.iter().map(|c| c.passes).collect();
        Some(select::forward(
            ctx,
            &round.fitted,
            &passes,
            &round.recal,
            before_worst,
            &|what| ctx.options.tell(what),
        )?)
    } else {
        None
    };
    if let Some(s) = &selection {
        diagnosis.selection = s.steps.clone();
    }
    Ok(Search {
        selection,
        gates,
        recal_explains,
        before_worst,
        recal_worst: round.recal_worst,
    })
}

/// The library's combination when it passes: the selection, its final fit and that fit's
/// worst-floor held-out NMSE.
type Combination<'s> = (&'s select::Selection, &'s Fitted, f64);

/// The library's search after round 1: the forward selection, when it ran, and what discovery
/// and the decision read beside it.
struct Search {
    selection: Option<select::Selection>,
    gates: Gates,
    /// The recalibration alone explains the error ([`recalibration_explains`]).
    recal_explains: bool,
    /// Worst-floor held-out NMSE of the twin as given, and after recalibration.
    before_worst: f64,
    recal_worst: f64,
}

impl Search {
    /// The selection's model when it meets, as a whole, the gates a single effect meets: a cut
    /// of [`Gates::required_cut`] and [`Gates::beat_recalibration`] against the recalibration.
    fn combination(&self) -> Option<Combination<'_>> {
        let gates = self.gates;
        self.selection.as_ref().and_then(|s| {
            if s.chosen.is_empty() {
                return None;
            }
            let fitted = s.fitted.as_ref()?;
            let w = worst(&fitted.nmse_held_out);
            (w * gates.required_cut <= self.before_worst
                && w * gates.beat_recalibration <= self.recal_worst)
                .then_some((s, fitted, w))
        })
    }
}

/// What discovery gave, and the library's combination it leaves standing.
struct Discovery<'s> {
    /// What it found, and its terms and fit when they pass the gates; None when it did not
    /// run.
    found: Option<discover::Discovered>,
    /// The library's combination, unless discovery's passing terms replace it.
    combination: Option<Combination<'s>>,
    /// The library's combination passed but left the model short of good enough.
    combination_short: bool,
}

impl Discovery<'_> {
    /// The discovered terms and their fit, when they pass the gates.
    fn passes(&self) -> Option<&(Vec<Term>, Fitted)> {
        self.found.as_ref().and_then(|d| d.1.as_ref())
    }
}

/// Stage 7, discovery: when neither recalibration nor any combination of library effects
/// explains the error, the missing force by sparse regression on top of the selection's model
/// (see [`discover`]), refitted through FMI as the FMU's `discovered` effect and gated the same
/// way. Also when the library's combination passes but leaves the model short of good enough:
/// then discovery on the twin's own physics (`base_run`) competes with it, and replaces it when
/// its held-out error is lower by the step gate. What it found goes into the diagnosis.
fn discovery<'s>(
    ctx: &select::Context,
    base_run: &PhysicsRun,
    search: &'s Search,
    diagnosis: &mut Diagnosis,
) -> Result<Discovery<'s>> {
    let combination = search.combination();
    let combination_short =
        combination.is_some_and(|(_, fitted, _)| !ctx.good_enough(&fitted.nmse_held_out));
    let found = match &search.selection {
        Some(s) if combination.is_none() && !search.recal_explains => {
            ctx.options
                .tell("discovering the missing force by sparse regression");
            let run = s.fitted.as_ref().map(|f| &f.run).unwrap_or(base_run);
            Some(discover::missing(
                ctx,
                &s.chosen,
                &s.values,
                run,
                search.before_worst,
                search.recal_worst,
            )?)
        }
        Some(_) if combination_short => {
            ctx.options
                .tell("the library's answer leaves more than the noise: discovering");
            let d = discover::missing(
                ctx,
                &[],
                &BTreeMap::new(),
                base_run,
                search.before_worst,
                search.recal_worst,
            )?;
            let better = |(_, fitted): &(Vec<_>, Fitted)| {
                combination.is_some_and(|(_, _, w)| {
                    worst(&fitted.nmse_held_out) * search.gates.step_cut <= w
                })
            };
            Some((d.0, d.1.filter(better)))
        }
        _ => None,
    };
    let replaced = found.as_ref().is_some_and(|d| d.1.is_some());
    diagnosis.discovery = found.as_ref().map(|d| d.0.clone());
    Ok(Discovery {
        combination: if replaced { None } else { combination },
        found,
        combination_short,
    })
}

/// The views the stages after the baseline read of it.
impl Baseline {
    /// What round 1's stages share, on `data` under `options`.
    /// The record's fitted and held-out samples as the fits take them.
    fn split(&self) -> Split<'_> {
        Split {
            mask: &self.samples.mask,
            held_out: &self.samples.held_out,
            first: self.samples.first,
            climb: self.climb,
        }
    }

    fn ground<'a>(&'a self, data: &'a Measurement, options: &'a DiagnoseOptions) -> Ground<'a> {
        Ground {
            data,
            options,
            physics: &self.physics,
            storeys: self.storeys,
            split: self.split(),
            channels: &self.channels,
            reals: &self.reals,
            scales: &self.scales,
            base_run: &self.base_run,
        }
    }

    /// What the forward selection and discovery read; a full round tries `candidates`.
    fn selection_context<'a>(
        &'a self,
        data: &'a Measurement,
        options: &'a DiagnoseOptions,
        baseline_evidence: f64,
        candidates: &'a [Candidate],
    ) -> select::Context<'a> {
        select::Context {
            physics: &self.physics,
            data,
            options,
            scales: &self.scales,
            reals: &self.reals,
            split: self.split(),
            baseline_evidence,
            explained_held_out: (0..self.nc)
                .map(|c| self.scores.noise_nmse_held_out[c] + self.scores.band_nmse[c])
                .collect(),
            channels: &self.channels,
            candidates,
            tolerance: self.scores.tolerance.value,
        }
    }

    /// The decision's stage on this record (sampled every `dt`), with the twin's and the
    /// recalibration's worst-floor held-out NMSE.
    fn verdict(&self, dt: f64, before_worst: f64, recal_worst: f64) -> Verdict<'_> {
        Verdict {
            channels: &self.channels,
            mass: &self.mass,
            reals: &self.reals,
            scales: &self.scales,
            storeys: self.storeys,
            dt,
            before_worst,
            recal_worst,
        }
    }
}

/// The diagnosis's first stage: the record checked against the twin, the twin as given and its
/// physics alone run on it, and the scores every later stage is measured against.
struct Baseline {
    /// The record's samples: after the transient, fitted and held out.
    samples: Samples,
    /// The building's storeys.
    storeys: usize,
    /// The record's responses.
    channels: Channels,
    /// How many.
    nc: usize,
    /// The library's candidates, or the ones given.
    candidates: Vec<Candidate>,
    /// The twin's physics alone.
    physics: Twin,
    /// Its run on the record (accelerations, velocities, displacements, drifts).
    base_run: PhysicsRun,
    /// The twin as given on the record.
    scores: Scores,
    /// The physics' parameter values.
    reals: PhysicsReals,
    /// Floor masses, floor 1 first.
    mass: Vec<f64>,
    /// What the candidates' priors are scaled by.
    scales: Scales,
    /// Whether the fits climb the ladder of the record's heads (see [`climbs`]).
    climb: bool,
}

/// The record's samples and their split into fitted and held-out blocks.
struct Samples {
    /// Samples in the record.
    n: usize,
    /// The first sample after the transient.
    first: usize,
    /// The fitted blocks' samples.
    mask: Vec<bool>,
    /// The held-out blocks' samples.
    held_out: Vec<usize>,
    /// Every sample after the transient.
    after: Vec<usize>,
}

/// The twin as given on the record: its prediction, its NMSE per channel and what noise and
/// parameter uncertainty explain of it, and the practical bar.
struct Scores {
    /// The twin's prediction per channel.
    predicted: Vec<Vec<f64>>,
    /// NMSE per channel after the transient (%).
    nmse_before: Vec<f64>,
    /// On the held-out samples.
    nmse_before_held_out: Vec<f64>,
    /// The noise's share (%).
    noise_nmse: Vec<f64>,
    /// On the held-out samples.
    noise_nmse_held_out: Vec<f64>,
    /// The parameter uncertainty's share (%).
    band_nmse: Vec<f64>,
    /// Noise and band together (%).
    explained_nmse: Vec<f64>,
    /// The practical bar.
    tolerance: Tolerance,
}

/// What the first report shows beside the scores.
struct Shown {
    /// The comparison's failing windows.
    failing_windows: Vec<FailingWindow>,
    /// The corrector's latent variance, when it has one.
    latent_variance: Option<LatentVariance>,
    /// The storey shear the twin misses, per storey, and where it points.
    missing_shear: Vec<Vec<f64>>,
    localisation: Localisation,
    /// The record's modes beside the twin's, or why they could not be identified.
    modes: Option<crate::workflows::modal::ModalEvidence>,
    modes_error: Option<String>,
}

/// The first stage of [`diagnose`]: check the record and the options, run the twin and its
/// physics on the record, score them, locate the residual and identify the record's modes.
/// Also the report so far: the scores, the localisation and the modes, no verdict.
fn baseline(
    twin: &Twin,
    data: &Measurement,
    options: &DiagnoseOptions,
) -> Result<(Baseline, Diagnosis)> {
    let noise = twin.noise_variance.clone().ok_or_else(|| {
        DiagnoseError::Setup(
            "the twin has no noise variances, so the noise level is unknown: diagnose a twin \
             made by `twin calibrate`"
                .into(),
        )
    })?;
    let samples = samples(data, options)?;
    let storeys = storeys_of(twin)?;
    let channels = Channels::of(data, storeys)?;
    let noise_variance = channel_noise(&noise, &channels, twin, data)?;
    let candidates = candidates_to_try(options, storeys)?;

    // 1. The twin as given, and its physics alone with drifts and velocities.
    let compared = compare_twin(twin, data, options)?;
    let physics = physics_only(twin);
    let base_run = run_physics(&physics, data, &BTreeMap::new(), &[], &[])?;
    let scores = Scores::of(&compared, &channels, &noise_variance, &samples);

    // Scales of the candidates' priors.
    let reals = PhysicsReals::of(&physics)?;
    let mass = (1..=storeys)
        .map(|f| reals.get(&format!("m{f}")))
        .collect::<Result<Vec<f64>>>()?;
    let scales = prior_scales(&reals, &base_run, data, samples.first)?;
    let mut baseline = Baseline {
        samples,
        storeys,
        nc: channels.len(),
        channels,
        candidates,
        physics,
        base_run,
        scores,
        reals,
        mass,
        scales,
        climb: false,
    };
    let shown = baseline.shown(twin, data, compared);
    baseline.climb = climbs(data.len(), &data.time, &shown.failing_windows);
    let diagnosis = baseline.report(twin, data, options, shown);
    Ok((baseline, diagnosis))
}

/// The record's samples under `options`: the block length checked, enough samples after the
/// transient, the fitted and held-out blocks.
fn samples(data: &Measurement, options: &DiagnoseOptions) -> Result<Samples> {
    if !(options.block > 0.0 && options.block.is_finite()) {
        return Err(DiagnoseError::Setup(format!(
            "the block length must be a positive number of seconds, was {}",
            options.block
        )));
    }
    let n = data.len();
    let first = first_after_transient(&data.time, options.transient);
    if n - first < 20 {
        return Err(DiagnoseError::Setup(format!(
            "{}: {} samples after the {} s transient; a diagnosis needs more",
            data.path.display(),
            n - first,
            options.transient
        )));
    }
    let (mask, held_out) = blocks(&data.time, first, options.block);
    Ok(Samples {
        n,
        first,
        mask,
        held_out,
        after: (first..n).collect(),
    })
}

/// The twin's noise variance of each of the record's channels; Err names a channel it has none
/// for.
fn channel_noise(
    noise: &NoiseVariances,
    channels: &Channels,
    twin: &Twin,
    data: &Measurement,
) -> Result<Vec<f64>> {
    channels
        .names
        .iter()
        .map(|name| {
            ::structure::channel::Channel::parse(name)
                .and_then(|c| noise.get(c))
                .ok_or_else(|| {
                    DiagnoseError::Setup(format!(
                        "{}: column '{name}': {} has no noise variance for it (calibrate the \
                         twin on a record that measures {name})",
                        data.path.display(),
                        twin.describe()
                    ))
                })
        })
        .collect()
}

/// The candidates given, checked against the building's `storeys`, else the whole library.
fn candidates_to_try(options: &DiagnoseOptions, storeys: usize) -> Result<Vec<Candidate>> {
    Ok(match &options.candidates {
        Some(given) => {
            check_sites(given, storeys).map_err(DiagnoseError::Setup)?;
            given.clone()
        }
        None => Candidate::library(storeys),
    })
}

/// The twin as given run on the record and compared with it; its noise variances are known
/// here, so the comparison's band is theirs.
fn compare_twin(twin: &Twin, data: &Measurement, options: &DiagnoseOptions) -> Result<Compared> {
    run_and_compare_with(twin, data, options.transient, options.tolerance, |_, _| {}).map_err(|e| {
        DiagnoseError::In {
            context: format!("running the twin on {}", data.path.display()),
            source: Box::new(e.into()),
        }
    })
}

impl Scores {
    /// The scores of the twin's comparison `compared` with the record, each channel's noise's
    /// share from its `noise_variance`.
    fn of(
        compared: &Compared,
        channels: &Channels,
        noise_variance: &[f64],
        samples: &Samples,
    ) -> Scores {
        // The twin's results per channel: the comparison's are in the record's order, as
        // `channels` (Channels::of reads the record's responses in order).
        let predicted: Vec<Vec<f64>> = compared
            .prediction
            .channels
            .iter()
            .map(|c| c.values.clone())
            .collect();
        let noise_nmse_on = |idx: &[usize]| -> Vec<f64> {
            (0..channels.len())
                .map(|c| {
                    let y: Vec<f64> = idx.iter().map(|&k| channels.measured[c][k]).collect();
                    100.0 * noise_variance[c] / variance(&y)
                })
                .collect()
        };
        let noise_nmse = noise_nmse_on(&samples.after);
        let band_nmse = compared.band_nmse.clone();
        Scores {
            nmse_before: compared.comparison.nmse.clone(),
            nmse_before_held_out: channels.nmse_on(&predicted, &samples.held_out),
            noise_nmse_held_out: noise_nmse_on(&samples.held_out),
            explained_nmse: (0..channels.len())
                .map(|c| noise_nmse[c] + band_nmse[c])
                .collect(),
            predicted,
            noise_nmse,
            band_nmse,
            tolerance: compared.tolerance.clone(),
        }
    }
}

impl Baseline {
    /// What the first report shows beside the scores: the comparison's failing windows and
    /// the corrector's latent variance (of the twin's comparison `compared`), the missing storey
    /// shear localised from the twin's residual, the record's modes beside the twin's.
    fn shown(&self, twin: &Twin, data: &Measurement, compared: Compared) -> Shown {
        let Samples { n, first, .. } = self.samples;
        let latent_variance = compared
            .prediction
            .channels
            .iter()
            .map(|c| c.latent_var.as_ref())
            .collect::<Option<Vec<&Vec<f64>>>>()
            .map(|v| LatentVariance {
                max: v
                    .iter()
                    .map(|v| v[first..].iter().copied().fold(0.0, f64::max))
                    .collect(),
                mean: v
                    .iter()
                    .map(|v| v[first..].iter().sum::<f64>() / (n - first) as f64)
                    .collect(),
            });
        // Localisation from the residual of the twin as given.
        let floor_force = missing_floor_force(
            &self.channels,
            &self.mass,
            &self.scores.predicted,
            self.storeys,
            data.dt,
        );
        let missing_shear = missing_shear(&floor_force);
        let localisation = localise(&missing_shear, &floor_force, &self.base_run, first);
        // The record's modes beside the twin's: shown with the verdict, and a `none` says so
        // when they moved beyond the twin's band. Without LSCF's sweep past its orders, which
        // finds a tall tower's top modes for `twin modal` and `compare --modes` at 2–8 s for
        // ten channels: a 10-storey diagnosis 9.8–10.8 → 6.4 s, its evidence 2 of the 10 modes
        // (8 with the sweep).
        let sweep = crate::workflows::modal::IdentifyOptions {
            extend_orders: false,
            ..Default::default()
        };
        let (modes, modes_error) = match crate::workflows::modal::modal_evidence_with(
            twin,
            data,
            crate::workflows::modal::ModalBand::default(),
            &sweep,
        ) {
            Ok(e) => (Some(e), None),
            Err(e) => (None, Some(e.to_string())),
        };
        Shown {
            failing_windows: compared.comparison.failing_windows,
            latent_variance,
            missing_shear,
            localisation,
            modes,
            modes_error,
        }
    }

    /// The report before any verdict: the record, the twin's scores and what `shown` has; the
    /// twin's prediction stands as the prediction after.
    fn report(
        &self,
        twin: &Twin,
        data: &Measurement,
        options: &DiagnoseOptions,
        shown: Shown,
    ) -> Diagnosis {
        let s = &self.scores;
        Diagnosis {
            record: data.path.display().to_string(),
            changed_at: None,
            channels: self.channels.names.clone(),
            twin: twin
                .source
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| "(default twin)".into()),
            nmse_before: s.nmse_before.clone(),
            noise_nmse: s.noise_nmse.clone(),
            band_nmse: s.band_nmse.clone(),
            explained_nmse: s.explained_nmse.clone(),
            tolerance: s.tolerance.value,
            tolerance_source: s.tolerance.source.clone(),
            statistically_significant: false,
            practically_significant: false,
            nmse_before_held_out: s.nmse_before_held_out.clone(),
            noise_nmse_held_out: s.noise_nmse_held_out.clone(),
            failing_windows: shown.failing_windows,
            latent_variance: shown.latent_variance,
            action: Action::None,
            reason: String::new(),
            effect: None,
            effects: Vec::new(),
            physics_moved: Vec::new(),
            selection: Vec::new(),
            discovery: None,
            sensor: None,
            sensor_candidates: Vec::new(),
            nmse_after: s.nmse_before.clone(),
            recalibration: None,
            candidates: Vec::new(),
            failed_candidates: Vec::new(),
            screened_out: Vec::new(),
            localisation: shown.localisation,
            sensing: self.channels.sensing(),
            modes: shown.modes,
            modes_error: shown.modes_error,
            gates: options.gates,
            block_seconds: options.block,
            seconds: 0.0,
            series: Series {
                time: data.time.clone(),
                first: self.samples.first,
                floors: self.channels.floors.iter().map(|f| f + 1).collect(),
                measured: self.channels.measured.clone(),
                before: s.predicted.clone(),
                after: s.predicted.clone(),
                drift: self.base_run.drift.clone(),
                missing_shear: shown.missing_shear,
                effect_force: None,
                evidence_axis: None,
            },
        }
    }
}

/// What the stages after the baseline share: the record and its split into fitted and
/// held-out blocks, the structure, and the twin's physics with its run on the record.
#[derive(Clone, Copy)]
struct Ground<'a> {
    data: &'a Measurement,
    options: &'a DiagnoseOptions,
    physics: &'a Twin,
    storeys: usize,
    split: Split<'a>,
    channels: &'a Channels,
    reals: &'a PhysicsReals,
    scales: &'a Scales,
    base_run: &'a PhysicsRun,
}

/// Round 1's fits: the recalibration (and its worst-floor held-out NMSE) and every candidate
/// fitted alone that did not fail.
struct RoundOne {
    recal: Fitted,
    recal_worst: f64,
    fitted: Vec<(Candidate, Fitted)>,
}

/// Round 1's screen: the default library only at the sites whose force, linearised through
/// the structure, explains most of the residual (see `screen_sites`); given candidates as
/// they are. The screened-out go into the diagnosis with their scores.
fn screened(
    g: &Ground,
    diagnosis: &mut Diagnosis,
    candidates: Vec<Candidate>,
) -> Result<Vec<Candidate>> {
    let Ground {
        data,
        options,
        storeys,
        split:
            Split {
                first,
                mask,
                held_out,
                ..
            },
        channels,
        reals,
        base_run,
        ..
    } = *g;
    let fitted_idx: Vec<usize> = (0..data.len()).filter(|&k| mask[k]).collect();
    Ok(if options.candidates.is_none() {
        options.tell(&format!("screening {} candidates", candidates.len()));
        let values = |p: char| -> Result<Vec<f64>> {
            (1..=storeys)
                .map(|i| reals.get(&format!("{p}{i}")))
                .collect()
        };
        let sensors = channels.sensors();
        let problem = discover::Problem {
            linear: discover::LinearPart {
                mass: values('m')?,
                damping: values('c')?,
                stiffness: values('k')?,
            },
            states: discover::States {
                drift: &base_run.drift,
                velocity: &base_run.velocity,
                acceleration: &base_run.acc,
            },
            sensors: &sensors,
            residual: channels.residuals(base_run),
            variance: channels
                .measured
                .iter()
                .map(|m| variance(&m[first..]))
                .collect(),
            dt: data.dt,
            fitted: &fitted_idx,
            held_out,
            first,
        };
        let scores = discover::screen(&problem, &candidates, options.threads);
        let (kept, dropped) = screen_sites(candidates, scores);
        diagnosis.screened_out = dropped.iter().map(|(c, s)| (c.label(), *s)).collect();
        kept
    } else {
        candidates
    })
}

/// Round 1's fits, in parallel: the recalibration first, then every candidate alone; each
/// with the seconds it took.
fn fit_round_one(
    g: &Ground,
    candidates: &[Candidate],
    baseline_evidence: f64,
) -> Result<Vec<Result<(Fitted, f64)>>> {
    let Ground {
        data,
        options,
        physics,
        storeys,
        split,
        reals,
        scales,
        ..
    } = *g;
    let current = parameter_names(storeys)
        .into_iter()
        .map(|name| Ok((name.clone(), reals.get(&name)?)))
        .collect::<Result<BTreeMap<String, f64>>>()?;
    let mut jobs = vec![Job::Recalibrate];
    jobs.extend(candidates.iter().map(|c| Job::Effect(*c)));
    let done = AtomicUsize::new(0);
    let total = jobs.len();
    options.tell(&format!(
        "round 1: recalibration and {} candidates",
        total - 1
    ));
    // The dearest fits first, so that none starts last and runs alone: a smooth effect steps
    // RK4 sub-steps where a contact steps its exact maps (on dataset3 a friction fit took
    // 0.9–1.0 s, a cubic 0.4–0.5 s, the recalibration 0.5 s, a contact 0.1–0.7 s).
    let mut ordered: Vec<(usize, Job)> = jobs.iter().copied().enumerate().collect();
    ordered.sort_by_key(|(_, job)| job.cost_rank());
    let results = crate::parallel::on_threads(
        &ordered,
        options.threads,
        |&(_, job)| -> Result<(Fitted, f64)> {
            let t = Instant::now();
            let _told = Told(|| {
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                options.tell(&format!(
                    "round 1: {k}/{total} fits (recalibration and candidates)"
                ));
            });
            let fitted = match &job {
                // The prior's mean and random draws as a calibration starts, and one more start
                // at the twin's own values: a change near them (a storey's stiffness loss) is
                // found from there whatever the number of parameters, where random starts of a
                // tall building's 3N parameters rarely come near.
                Job::Recalibrate => fit(
                    &physics,
                    data,
                    parameter_names(storeys),
                    BTreeMap::new(),
                    split,
                    options.recalibration_starts + 1,
                    1,
                    crate::workflows::calibrate::SIMULATIONS_PER_START,
                    options,
                    baseline_evidence,
                    &BTreeMap::new(),
                    vec![current.clone()],
                ),
                Job::Effect(c) => {
                    let twin = with_switches(&physics, Some(c))?;
                    let params = c.parameters(&scales);
                    fit(
                        &twin,
                        data,
                        params.iter().map(|p| p.0.clone()).collect(),
                        params.iter().map(|p| (p.0.clone(), p.2)).collect(),
                        split,
                        options.starts,
                        1,
                        options.simulations_per_start,
                        options,
                        baseline_evidence,
                        &BTreeMap::new(),
                        c.starts_at(&scales),
                    )
                }
            }?;
            Ok((fitted, t.elapsed().as_secs_f64()))
        },
    );
    // Back in the jobs' order.
    let mut slots: Vec<Option<Result<(Fitted, f64)>>> = jobs.iter().map(|_| None).collect();
    for ((i, _), r) in ordered.iter().zip(results) {
        slots[*i] = Some(r);
    }
    Ok(slots.into_iter().flatten().collect())
}

/// Round 1's results into the diagnosis: the recalibration's report and every candidate's
/// (or its failure), the candidates' gates against `before_worst`, the twin's worst-floor
/// held-out NMSE.
fn report_round_one(
    g: &Ground,
    diagnosis: &mut Diagnosis,
    candidates: &[Candidate],
    results: Vec<Result<(Fitted, f64)>>,
    before_worst: f64,
) -> Result<RoundOne> {
    let Ground {
        options,
        reals,
        scales,
        ..
    } = *g;
    let gates = options.gates;
    let mut results = results.into_iter();
    let (recal, recal_seconds) = results
        .next()
        .ok_or_else(|| DiagnoseError::Setup("no recalibration result".into()))?
        .map_err(|e| DiagnoseError::In {
            context: "recalibrating".into(),
            source: Box::new(e),
        })?;
    let recal_worst = worst(&recal.nmse_held_out);
    let mut moved: Vec<MovedParameter> = recal
        .calibration
        .parameters
        .iter()
        .map(|p| {
            let before = reals.get(&p.name).unwrap_or(f64::NAN);
            MovedParameter {
                name: p.name.clone(),
                before,
                after: p.value,
                sd: p.sd,
                change_in_sd: (p.value - before) / p.sd,
                relative_change: (p.value - before) / before,
            }
        })
        .collect();
    moved.sort_by(|a, b| b.change_in_sd.abs().total_cmp(&a.change_in_sd.abs()));
    diagnosis.recalibration = Some(RecalibrationReport {
        evidence: recal.evidence,
        nmse_after: recal.nmse_after.clone(),
        nmse_held_out: recal.nmse_held_out.clone(),
        parameters: moved,
        noise_variance: recal.calibration.noise_variance.clone(),
        simulations: recal.calibration.simulations,
        seconds: recal_seconds,
    });

    let mut fitted_candidates = Vec::new();
    for (c, r) in candidates.iter().zip(results) {
        let (fitted, seconds) = match r {
            Ok(x) => x,
            Err(e) => {
                diagnosis
                    .failed_candidates
                    .push((c.label(), format!("{e:#}")));
                continue;
            }
        };
        let w = worst(&fitted.nmse_held_out);
        let passes =
            w * gates.required_cut <= before_worst && w * gates.beat_recalibration <= recal_worst;
        let short = c.parameters(&scales);
        diagnosis.candidates.push(CandidateReport {
            name: EffectName::of(c),
            evidence: fitted.evidence,
            nmse_after: fitted.nmse_after.clone(),
            nmse_held_out: fitted.nmse_held_out.clone(),
            parameters: fitted
                .calibration
                .parameters
                .iter()
                .zip(&short)
                .map(|(p, s)| Estimate {
                    name: s.1.to_string(),
                    value: p.value,
                    sd: p.sd,
                })
                .collect(),
            passes,
            simulations: fitted.calibration.simulations,
            seconds,
        });
        fitted_candidates.push((*c, fitted));
    }
    Ok(RoundOne {
        recal,
        recal_worst,
        fitted: fitted_candidates,
    })
}

/// The decision's stage: what each verdict's explanation reads (the round's results come as
/// arguments), and one method per verdict that writes its action, reason, scores and evidence
/// into the diagnosis.
struct Verdict<'a> {
    channels: &'a Channels,
    mass: &'a [f64],
    reals: &'a PhysicsReals,
    scales: &'a Scales,
    storeys: usize,
    /// The record's sampling interval.
    dt: f64,
    /// Worst-floor held-out NMSE of the twin as given, and after recalibration.
    before_worst: f64,
    recal_worst: f64,
}

impl Verdict<'_> {
    /// Stage 6, when the error is to be explained and no sensor explains it: the library's
    /// combination, else the recalibration `recal`, else discovery's terms, else
    /// `update_data_model`. `order`: the candidates, best evidence first.
    fn decide(
        &self,
        diagnosis: &mut Diagnosis,
        recal: &Fitted,
        search: &Search,
        discovery: &Discovery,
        order: &[usize],
    ) {
        if let Some((selection, fitted, w)) = discovery.combination {
            self.add_library(diagnosis, selection, fitted, w);
        } else if search.recal_explains {
            self.recalibrate(diagnosis, recal, &search.gates);
        } else if let (Some(s), Some((terms, fitted))) = (&search.selection, discovery.passes()) {
            self.add_discovered(diagnosis, s, terms, fitted, discovery.combination_short);
        } else {
            self.update_data_model(diagnosis, order);
        }
    }

    /// `add_physics` with the library's effects the forward selection chose.
    fn add_library(
        &self,
        diagnosis: &mut Diagnosis,
        selection: &select::Selection,
        fitted: &Fitted,
        w: f64,
    ) {
        diagnosis.action = Action::AddPhysics;
        let labels: Vec<String> = selection.chosen.iter().map(|c| c.label()).collect();
        diagnosis.effects = selection
            .chosen
            .iter()
            .map(|c| effect_report(&Addition::Library(*c), &selection.values, self.scales))
            .collect();
        diagnosis.effect = diagnosis.effects.first().cloned();
        diagnosis.physics_moved = moved_physics(self.reals, &selection.values, self.storeys);
        let moved: Vec<String> = diagnosis
            .physics_moved
            .iter()
            .map(|p| format!("{} {:+.1} %", p.name, 100.0 * p.relative_change))
            .collect();
        let plural = if labels.len() == 1 { "s" } else { "" };
        diagnosis.reason =
            format!(
            "{} cut{plural} the worst-floor held-out NMSE from {:.3} % to {:.3} % ({:.1}×) and \
             beat{plural} recalibration ({:.3} %) by {:.1}×{}",
            labels.join(" + "),
            self.before_worst,
            w,
            self.before_worst / w,
            self.recal_worst,
            self.recal_worst / w,
            if moved.is_empty() {
                String::new()
            } else {
                format!("; refitted jointly, the physics moved: {}", moved.join(", "))
            }
        );
        diagnosis.nmse_after = fitted.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&fitted.run);
        // The evidence: along the fitted model's drift (which follows the structure), the
        // storey shear the linear part misses = the effect's force plus what is still missed.
        let c = &selection.chosen[0];
        if let Some(force) = effect_force(c, &selection.values, self.scales, &fitted.run) {
            self.evidence_panel(diagnosis, &fitted.run, c.at - 1, force);
        }
    }

    /// `recalibrate`: the recalibration explains the error and no effect beats it.
    fn recalibrate(&self, diagnosis: &mut Diagnosis, recal: &Fitted, gates: &Gates) {
        diagnosis.action = Action::Recalibrate;
        let top: Vec<String> = diagnosis
            .recalibration
            .iter()
            .flat_map(|r| r.parameters.iter().take(3))
            .map(|p| {
                format!(
                    "{} {:+.1} % ({:+.1} sd)",
                    p.name,
                    100.0 * p.relative_change,
                    p.change_in_sd
                )
            })
            .collect();
        diagnosis.reason = format!(
            "recalibration cuts the worst-floor held-out NMSE from {:.3} % to {:.3} % ({:.1}×), \
             within {}× of the noise level on every floor, and no effect beats it by {}×; moved \
             most: {}",
            self.before_worst,
            self.recal_worst,
            self.before_worst / self.recal_worst,
            gates.recalibration_noise_factor,
            gates.beat_recalibration,
            top.join(", ")
        );
        diagnosis.nmse_after = recal.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&recal.run);
    }

    /// `add_physics` with the terms discovery found, on top of the selection's effects unless
    /// they replaced them (`replaced`: the library's answer left more than the noise).
    fn add_discovered(
        &self,
        diagnosis: &mut Diagnosis,
        selection: &select::Selection,
        terms: &[Term],
        fitted: &Fitted,
        replaced: bool,
    ) {
        diagnosis.action = Action::AddPhysics;
        let (chosen, mut values) = if replaced {
            (Vec::new(), BTreeMap::new())
        } else {
            (selection.chosen.clone(), selection.values.clone())
        };
        let mut additions: Vec<Addition> = chosen.into_iter().map(Addition::Library).collect();
        additions.push(Addition::Discovered(terms.to_vec()));
        values.extend(estimates(&fitted.calibration));
        diagnosis.effects = additions
            .iter()
            .map(|a| effect_report(a, &values, self.scales))
            .collect();
        diagnosis.effect = diagnosis.effects.first().cloned();
        diagnosis.physics_moved = moved_physics(self.reals, &values, self.storeys);
        let w = worst(&fitted.nmse_held_out);
        let found = diagnosis
            .effects
            .last()
            .map(discover::describe_terms)
            .unwrap_or_default();
        let library = if replaced {
            let best = diagnosis
                .selection
                .iter()
                .map(|s| s.added.as_str())
                .collect::<Vec<_>>()
                .join(" + ");
            format!("the library's best ({best}) leaves more than the noise")
        } else {
            "nothing in the library explains the error".to_string()
        };
        diagnosis.reason = format!(
            "{library} (recalibration leaves {:.3} % held out); sparse regression found {found}, \
             which, refitted through the FMU, cuts the worst-floor held-out NMSE from {:.3} % \
             to {:.3} % ({:.1}×) and beats recalibration by {:.1}×",
            self.recal_worst,
            self.before_worst,
            w,
            self.before_worst / w,
            self.recal_worst / w
        );
        diagnosis.nmse_after = fitted.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&fitted.run);
        // The evidence panel: at a storey, the discovered terms' storey force along the fitted
        // model's drift or drift rate, beside the shear the linear part still misses.
        if let Some((force, axis)) = discover::storey_force(terms, &fitted.run) {
            diagnosis.series.evidence_axis = Some(axis);
            self.evidence_panel(diagnosis, &fitted.run, terms[0].site.at() - 1, force);
        }
    }

    /// `update_data_model`: neither recalibration, the library nor discovery explains the
    /// error. `order`: the candidates, best evidence first.
    fn update_data_model(&self, diagnosis: &mut Diagnosis, order: &[usize]) {
        diagnosis.action = Action::UpdateDataModel;
        let best = order.first().map(|&i| &diagnosis.candidates[i]);
        let discovery = match &diagnosis.discovery {
            Some(d) if d.terms.is_empty() => {
                "; no sparse model of a few candidate functions at one storey or floor fits it \
                 either"
                    .to_string()
            }
            Some(d) => format!(
                "; the sparse model found ({}) leaves {} held out, short of the gates",
                d.terms
                    .iter()
                    .map(|t| t.function.as_str())
                    .collect::<Vec<_>>()
                    .join(" + "),
                d.nmse_held_out
                    .as_ref()
                    .map(|x| format!("{:.3} %", worst(x)))
                    .unwrap_or_else(|| "?".into())
            ),
            None => String::new(),
        };
        diagnosis.reason = format!(
            "neither recalibration (worst-floor held-out NMSE {:.3} % from {:.3} %) nor any \
             effect of the library (best: {}) explains the error{discovery}: the corrector \
             should learn it",
            self.recal_worst,
            self.before_worst,
            best.map(|b| format!("{} at {:.3} %", b.name.label, worst(&b.nmse_held_out)))
                .unwrap_or_else(|| "none tried".into())
        );
    }

    /// The evidence panel at storey `s` (0-based): along the fitted model's drift, the storey
    /// shear the linear part still misses plus the added `force`, beside that force.
    fn evidence_panel(
        &self,
        diagnosis: &mut Diagnosis,
        run: &PhysicsRun,
        s: usize,
        force: Vec<f64>,
    ) {
        diagnosis.series.drift = run.drift.clone();
        let still = missing_floor_force(
            self.channels,
            self.mass,
            &self.channels.predicted(run),
            self.storeys,
            self.dt,
        );
        diagnosis.series.missing_shear[s] = storey_shear(&still, s)
            .iter()
            .zip(&force)
            .map(|(still, force)| still - force)
            .collect();
        diagnosis.series.effect_force = Some(force);
    }
}

/// A sensor fault: exactly one floor's channel candidate cuts that floor's held-out NMSE by
/// [`Gates::required_cut`] and brings it within [`Gates::recalibration_noise_factor`] × its
/// explained level (or the tolerance), while every other floor is already fine: within
/// [`Gates::none_factor`] × its explained level, or the tolerance. A structural change moves
/// several floors' residuals coherently; a faulty sensor only its own.
fn sensor_decision(
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

/// Why `none`: within the explained level, or below the tolerance, or both.
fn none_reason(
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
fn per_channel(x: &[f64]) -> String {
    let values: Vec<String> = x.iter().map(|v| format!("{v:.3}")).collect();
    format!("{} %", values.join(" / "))
}

/// `floor 2` for `acc2`: how the reasons name a channel's floor.
fn floor_of(name: &str) -> String {
    let digits = name.trim_start_matches(|c: char| !c.is_ascii_digit());
    if digits.is_empty() {
        name.to_string()
    } else {
        format!("floor {digits}")
    }
}

/// The physics parameters in `values` that moved from the twin's by more than 3 posterior sd
/// and 1 %, largest move (in sd) first.
fn moved_physics(reals: &PhysicsReals, values: &Estimates, storeys: usize) -> Vec<MovedParameter> {
    let mut moved: Vec<MovedParameter> = parameter_names(storeys)
        .into_iter()
        .filter_map(|name| {
            let &(after, sd) = values.get(&name)?;
            let before = reals.get(&name).ok()?;
            Some(MovedParameter {
                name,
                before,
                after,
                sd,
                change_in_sd: (after - before) / sd,
                relative_change: (after - before) / before,
            })
        })
        .filter(|p| p.change_in_sd.abs() > 3.0 && p.relative_change.abs() > 0.01)
        .collect();
    moved.sort_by(|a, b| b.change_in_sd.abs().total_cmp(&a.change_in_sd.abs()));
    moved
}

/// Fitted values and posterior sds by FMU parameter name.
pub(crate) type Estimates = BTreeMap<String, (f64, f64)>;

fn estimates(calibration: &Calibration) -> Estimates {
    calibration
        .parameters
        .iter()
        .map(|p| (p.name.clone(), (p.value, p.sd)))
        .collect()
}

fn effect_report(a: &Addition, fitted: &Estimates, scales: &Scales) -> EffectReport {
    let mut parameters = BTreeMap::new();
    let mut sd = BTreeMap::new();
    for (name, short, _) in a.parameters(scales) {
        if let Some(&(value, s)) = fitted.get(&name) {
            parameters.insert(short.clone(), value);
            sd.insert(short, s);
        }
    }
    let mut terms = Vec::new();
    match a {
        Addition::Library(c) if c.kind.has_side() => {
            parameters.insert("side".into(), f64::from(c.side.code()));
        }
        Addition::Library(_) => {}
        Addition::Discovered(found) => {
            for (i, t) in found.iter().enumerate() {
                let key = format!("term{}", i + 1);
                terms.push(TermReport {
                    function: t.function.name().to_string(),
                    coefficient: parameters.get(&key).copied().unwrap_or(t.coefficient),
                    sd: sd.get(&key).copied().unwrap_or(f64::NAN),
                    scale: t.function.uses_scale().then_some(t.scale),
                });
            }
        }
    }
    EffectReport {
        name: EffectName::of_addition(a),
        parameters,
        sd,
        terms,
    }
}

/// The fitted effect's storey force along the run's drift (contact and cubic), or its floor
/// force along the velocity (friction): what the evidence panel draws. The force law is the
/// library's own; its parameters are read from `fitted` by name.
fn effect_force(
    c: &Candidate,
    fitted: &Estimates,
    scales: &Scales,
    run: &PhysicsRun,
) -> Option<Vec<f64>> {
    let values = c
        .parameters(scales)
        .iter()
        .map(|(name, _, _)| fitted.get(name).map(|v| v.0))
        .collect::<Option<Vec<f64>>>()?;
    let law = Law::new(c.kind, &values, c.side)?;
    let along = match c.placement() {
        Placement::Storey => &run.drift[c.at - 1],
        Placement::Floor => &run.velocity[c.at - 1],
    };
    Some(along.iter().map(|&x| law.force_at(x)).collect())
}

/// The force per floor the twin misses: each measured floor's mass times its residual
/// acceleration ([`Channels::residual_acceleration`]: an accelerometer's as it is, a velocity
/// or displacement sensor's differentiated; of a floor's sensors the one fewest
/// differentiations away); 0 on a floor without a sensor (what it misses there is not seen).
fn missing_floor_force(
    channels: &Channels,
    mass: &[f64],
    predicted: &[Vec<f64>],
    storeys: usize,
    dt: f64,
) -> Vec<Vec<f64>> {
    let n = channels.measured.first().map_or(0, Vec::len);
    let order = |q: Quantity| match q {
        Quantity::Acceleration => 0,
        Quantity::Velocity => 1,
        _ => 2,
    };
    let mut force = vec![vec![0.0; n]; storeys];
    let mut read_from: Vec<Option<Quantity>> = vec![None; storeys];
    for c in 0..channels.len() {
        let (f, q) = (channels.floors[c], channels.quantities[c]);
        if read_from[f].is_some_and(|r| order(r) <= order(q)) {
            continue;
        }
        read_from[f] = Some(q);
        force[f] = channels
            .residual_acceleration(c, &predicted[c], dt)
            .into_iter()
            .map(|a| mass[f] * a)
            .collect();
    }
    force
}

/// The storey shear the twin misses at storey `s` (from 0): the missing floor forces summed
/// from the top down to floor `s + 1`.
fn storey_shear(floor_force: &[Vec<f64>], s: usize) -> Vec<f64> {
    let n = floor_force.first().map_or(0, Vec::len);
    (0..n)
        .map(|k| (s..floor_force.len()).map(|j| floor_force[j][k]).sum())
        .collect()
}

/// Every storey's missing shear, storey 1 first.
fn missing_shear(floor_force: &[Vec<f64>]) -> Vec<Vec<f64>> {
    (0..floor_force.len())
        .map(|s| storey_shear(floor_force, s))
        .collect()
}

fn localise(
    missing_shear: &[Vec<f64>],
    floor_force: &[Vec<f64>],
    run: &PhysicsRun,
    first: usize,
) -> Localisation {
    let storeys = run.drift.len();
    let cut = |x: &[f64]| x[first..].to_vec();
    let shear_vs_drift: Vec<f64> = (0..storeys)
        .map(|s| correlation(&cut(&missing_shear[s]), &cut(&run.drift[s])))
        .collect();
    let shear_vs_drift_cubed: Vec<f64> = (0..storeys)
        .map(|s| {
            let d3: Vec<f64> = run.drift[s][first..].iter().map(|d| d * d * d).collect();
            correlation(&cut(&missing_shear[s]), &d3)
        })
        .collect();
    let shear_vs_drift_beyond: Vec<f64> = (0..storeys)
        .map(|s| {
            let d = &run.drift[s][first..];
            let mut abs: Vec<f64> = d.iter().map(|x| x.abs()).collect();
            abs.sort_by(f64::total_cmp);
            let g = abs[(abs.len() * 8) / 10];
            let beyond: Vec<f64> = d
                .iter()
                .map(|&x| {
                    if x > g {
                        x - g
                    } else if x < -g {
                        x + g
                    } else {
                        0.0
                    }
                })
                .collect();
            correlation(&cut(&missing_shear[s]), &beyond)
        })
        .collect();
    let force_vs_velocity_sign: Vec<f64> = (0..storeys)
        .map(|f| {
            let sign: Vec<f64> = run.velocity[f][first..]
                .iter()
                .map(|v| v.signum())
                .collect();
            correlation(&cut(&floor_force[f]), &sign)
        })
        .collect();
    let mut strongest = (0.0, String::new());
    for s in 0..storeys {
        for c in [
            shear_vs_drift[s],
            shear_vs_drift_cubed[s],
            shear_vs_drift_beyond[s],
        ] {
            if c.abs() > strongest.0 {
                strongest = (c.abs(), format!("storey {}", s + 1));
            }
        }
        if force_vs_velocity_sign[s].abs() > strongest.0 {
            strongest = (force_vs_velocity_sign[s].abs(), format!("floor {}", s + 1));
        }
    }
    Localisation {
        shear_vs_drift,
        shear_vs_drift_cubed,
        shear_vs_drift_beyond,
        force_vs_velocity_sign,
        strongest: strongest.1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fits' sub-steps follow the structure's fastest mode: the rig at 51.2 Hz keeps all
    /// eight, the 4-storey frame sampled at 322.58 Hz takes two, a building whose fastest mode
    /// is unknown keeps all, and none takes fewer than one or more than asked.
    #[test]
    fn the_fits_sub_steps_follow_the_fastest_mode() {
        let rig = ::structure::building::Structure::default().natural_frequencies();
        let fastest = *rig.last().unwrap();
        assert!((fastest - 7.97).abs() < 0.01, "{fastest}");
        assert_eq!(
            fit_substeps(FIT_SUBSTEPS, fastest, 1.0 / 51.2),
            FIT_SUBSTEPS
        );
        assert_eq!(fit_substeps(FIT_SUBSTEPS, 8.4, 1.0 / 322.58), 2);
        assert_eq!(fit_substeps(FIT_SUBSTEPS, f64::NAN, 0.01), FIT_SUBSTEPS);
        assert_eq!(fit_substeps(FIT_SUBSTEPS, 0.01, 0.001), 1);
        assert_eq!(fit_substeps(4, 100.0, 0.01), 4);
    }

    /// The fits climb only on records long enough for a ladder, and only when the error shows
    /// on its first rung: a window failing from the start of the record, not one that opens
    /// after the head the starts are screened on.
    #[test]
    fn the_fits_climb_only_where_the_error_shows_on_the_first_rung() {
        let dt = 0.01;
        let time = |n: usize| (0..n).map(|k| k as f64 * dt).collect::<Vec<f64>>();
        let window = |start: f64, end: f64| FailingWindow {
            start,
            end,
            channels: vec!["acc1".into()],
            floors: vec![1],
            nmse: vec![10.0],
        };
        let head_end = (crate::workflows::calibrate::ladder::STRETCH - 1) as f64 * dt;
        let long = 3 * crate::workflows::calibrate::ladder::STRETCH;
        assert!(climbs(long, &time(long), &[window(2.0, 5.0)]));
        assert!(climbs(
            long,
            &time(long),
            &[window(head_end - 0.5, head_end + 9.0)]
        ));
        assert!(!climbs(
            long,
            &time(long),
            &[window(head_end + 0.5, head_end + 9.0)]
        ));
        assert!(!climbs(long, &time(long), &[]));
        let short = 2 * crate::workflows::calibrate::ladder::STRETCH;
        assert!(!climbs(short, &time(short), &[window(2.0, 5.0)]));
    }

    /// The localisation reads a velocity sensor's residual differentiated once and a
    /// displacement sensor's twice (a residual sin(ωt) gives ω·cos and −ω²·sin within the
    /// central differences' error at 100 samples per period, 0.07 % and 0.13 %; 0.2 % allowed),
    /// and of a floor's sensors
    /// the one fewest differentiations away: the accelerometer where there is one.
    #[test]
    fn each_sensor_enters_the_missing_force_as_an_acceleration() {
        let dt = 0.01;
        let n = 400;
        let w = 2.0 * std::f64::consts::PI; // 1 Hz: 100 samples per period
        let sine: Vec<f64> = (0..n).map(|k| (w * k as f64 * dt).sin()).collect();
        let channels = Channels {
            names: vec!["vel1".into(), "disp2".into(), "disp3".into(), "acc3".into()],
            floors: vec![0, 1, 2, 2],
            quantities: vec![
                Quantity::Velocity,
                Quantity::Displacement,
                Quantity::Displacement,
                Quantity::Acceleration,
            ],
            measured: vec![sine.clone(), sine.clone(), sine.clone(), sine.clone()],
        };
        let predicted = vec![vec![0.0; n]; 4];
        let mass = [2.0, 3.0, 4.0];
        let force = missing_floor_force(&channels, &mass, &predicted, 3, dt);
        for k in 1..n - 1 {
            let t = w * k as f64 * dt;
            assert!(
                (force[0][k] - 2.0 * w * t.cos()).abs() < 2e-3 * 2.0 * w,
                "vel at {k}"
            );
            if k > 1 && k < n - 2 {
                let expected = -3.0 * w * w * t.sin();
                assert!(
                    (force[1][k] - expected).abs() < 2e-3 * 3.0 * w * w,
                    "disp at {k}"
                );
            }
            assert_eq!(force[2][k], 4.0 * sine[k], "the accelerometer, as measured");
        }
    }

    /// A decisive screen (its best site at most SCREEN_DECISIVE of the residual) keeps every
    /// candidate at its SCREEN_SITES best sites, and only those; an undecided one keeps the
    /// best SCREEN_KEEP; nothing is lost either way.
    #[test]
    fn a_decisive_screen_keeps_the_best_sites_candidates() {
        let library = Candidate::library(5);
        let site = |c: &Candidate| (c.placement() == Placement::Floor, c.at);
        // Storey 4's contact scores best, then storey 2's cubic, then friction on floor 1;
        // everything else explains little.
        let scores: Vec<f64> = library
            .iter()
            .map(|c| match (c.kind, c.at) {
                (Kind::Contact, 4) => 0.2,
                (Kind::Cubic, 2) => 0.6,
                (Kind::Friction, 1) => 0.7,
                _ => 0.95,
            })
            .collect();
        let (kept, dropped) = screen_sites(library.clone(), scores.clone());
        assert_eq!(kept.len() + dropped.len(), library.len());
        let best_sites: Vec<(bool, usize)> = [Kind::Contact, Kind::Cubic, Kind::Friction]
            .iter()
            .zip([4, 2, 1])
            .filter_map(|(k, at)| library.iter().find(|c| c.kind == *k && c.at == at))
            .map(site)
            .collect();
        assert_eq!(best_sites.len(), 3);
        for c in &library {
            assert_eq!(
                kept.contains(c),
                best_sites.contains(&site(c)),
                "{} kept: {}",
                c.label(),
                kept.contains(c)
            );
        }
        // Undecided: the best screen score above the bar keeps the best SCREEN_KEEP.
        let undecided: Vec<f64> = scores.iter().map(|s| s + SCREEN_DECISIVE).collect();
        let (kept, dropped) = screen_sites(library.clone(), undecided);
        assert_eq!(kept.len(), SCREEN_KEEP.min(library.len()));
        assert_eq!(kept.len() + dropped.len(), library.len());
        assert!(
            dropped.windows(2).all(|w| w[0].1 <= w[1].1),
            "dropped by score"
        );
    }
}
