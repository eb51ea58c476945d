//! Active control on the twin (the reference paper's section 6, automated): LQR designs on the
//! twin's calibrated linear structure, the structure (the twin's physics, with whatever effects it
//! has) driven by a record's force passive and under each design, the frequency responses and the
//! attenuation at each resonance, the control effort and the contact initiations; then the twin
//! informs the control: the smallest state weight that keeps the contacts at a target
//! (`retune`), and a gain schedule that switches to the high gain when the estimated drift
//! approaches the gap.

pub mod closed_loop;
pub mod design;
pub mod options;
pub mod ssp;

use numerics::lqr::{Estimator, Schedule, StateSpace};
use serde::Serialize;
use structure::channel::{Channel, Quantity};
use structure::Structure;

use crate::blocks::lqr::SensorNoise;
use crate::cosim::master::MasterError;
use crate::evaluation::frf::{welch_h1, FrequencyResponse, FRF_SEGMENT};
use crate::evaluation::stats::rms;
use crate::twin::data::Measurement;
use crate::twin::{Twin, TwinError};
use closed_loop::{simulate, ContactEvent, Gains, Gap, LoopLaw, LoopSetup, Response, StateSource};
pub use design::{
    design, physics_resource, plant_measuring, plant_of, structure_of, with_actuator_at, Design,
    StateUnit,
};
pub use options::{sensor_noise, twin_for_control};

/// Errors of `twin control`.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    #[error("{0}")]
    Options(String),
    #[error("{0}")]
    Twin(String),
    #[error("the LQR design for q = {q} failed: {message}")]
    Design { q: f64, message: String },
    #[error("{0}")]
    Unstable(String),
    #[error(transparent)]
    Lqr(#[from] numerics::lqr::LqrError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error(transparent)]
    TwinFile(#[from] TwinError),
}

/// Half-width of the band around a resonance in which the peak is read, relative.
pub const RESONANCE_BAND: f64 = 0.1;
/// The grid `--retune` searches, as multiples of the smallest `--q`.
pub const RETUNE_GRID: [f64; 13] = [
    1.0, 1.5, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 70.0, 100.0,
];

/// `--retune`: the smallest q on the grid that keeps the contacts at or below `target` with the
/// peak control force within `max_force`.
#[derive(Clone, Debug)]
pub struct Retune {
    pub target: usize,
    pub max_force: Option<f64>,
}

/// `--schedule`: switch between the smallest and the largest design (or the retuned one).
#[derive(Clone, Debug)]
pub struct ScheduleOptions {
    pub margin: f64,
    pub lookahead: f64,
    pub dwell: f64,
    pub variance: VarianceTrigger,
}

/// Whether the schedule also switches on the corrector's latent variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VarianceTrigger {
    /// When the twin has a corrector: above the twin's noise variance (the threshold active
    /// learning queries at), else 1e-3 of the record's measured variance.
    Auto,
    /// This threshold on every floor, (m/s²)².
    Value(f64),
    Off,
}

#[derive(Clone, Debug)]
pub struct ControlOptions {
    pub qs: Vec<f64>,
    pub r: f64,
    pub unit: StateUnit,
    pub estimator: EstimatorChoice,
    /// Corner of the integrating estimator's drift removal, Hz.
    pub highpass_hz: f64,
    /// Controller samples per record sample (None: from the fastest closed-loop pole).
    pub substeps: Option<usize>,
    /// Accelerometer noise sd the controller reads, per floor, or one for every floor (None:
    /// the twin's calibrated noise).
    pub sensor_noise: Option<Vec<f64>>,
    pub seed: u64,
    /// Gaps to watch besides the twin's own contacts.
    pub gaps: Vec<Gap>,
    pub retune: Option<Retune>,
    pub schedule: Option<ScheduleOptions>,
    /// Compare the estimators' cost on the first design.
    pub estimator_costs: bool,
    /// The floor the control force acts on (1-based).
    pub actuator_floor: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorChoice {
    /// Integrate the measured accelerations twice with drift removal (the paper's).
    Integrate,
    /// A steady-state Kalman observer on the twin's linear model.
    Kalman,
}

impl crate::choice::Choice for EstimatorChoice {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        (
            "integrate",
            "integrate the measured accelerations twice with drift removal",
            EstimatorChoice::Integrate,
        ),
        (
            "kalman",
            "a steady-state Kalman observer on the twin's linear model",
            EstimatorChoice::Kalman,
        ),
    ];
}

crate::choice::display_by_name!(EstimatorChoice);

/// Attenuation at one resonance: passive peak over controlled peak, per floor, dB.
#[derive(Clone, Debug, Serialize)]
pub struct Attenuation {
    pub mode: usize,
    pub frequency_hz: f64,
    pub floors_db: Vec<f64>,
}

/// A design run on the structure.
#[derive(Clone, Debug, Serialize)]
pub struct DesignRun {
    #[serde(flatten)]
    pub design: Design,
    /// "requested", "retuned".
    pub role: String,
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub contact_events: Vec<ContactEvent>,
    pub attenuation_db: Vec<Attenuation>,
    pub mean_attenuation_db: f64,
    pub control_rms: f64,
    pub control_peak: f64,
    pub acc_rms: Vec<f64>,
    /// Why the run stopped, when the closed loop went unstable (then no figures).
    pub unstable: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Passive {
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub contact_events: Vec<ContactEvent>,
    pub acc_rms: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RetuneRow {
    pub q: f64,
    pub contacts: Option<usize>,
    pub control_rms: Option<f64>,
    pub control_peak: Option<f64>,
    pub mean_attenuation_db: Option<f64>,
    pub unstable: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RetuneReport {
    pub target_contacts: usize,
    pub max_force: Option<f64>,
    pub grid: Vec<RetuneRow>,
    /// The smallest q that met the target (None: none on the grid did).
    pub chosen_q: Option<f64>,
    pub verdict: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Switch {
    pub time: f64,
    /// "high" or "low".
    pub to: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct ScheduleReport {
    pub q_low: f64,
    pub q_high: f64,
    pub storey: String,
    pub gap: f64,
    pub margin: f64,
    pub lookahead: f64,
    pub dwell: f64,
    pub switches: Vec<Switch>,
    pub high_fraction: f64,
    /// The corrector's latent variance above which the high gain comes on, per floor (None:
    /// the twin has no corrector, or the trigger is off).
    pub variance_threshold: Option<Vec<f64>>,
    /// Fractions of the time the drift and the latent-variance triggers held.
    pub drift_trigger_fraction: f64,
    pub variance_trigger_fraction: f64,
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub attenuation_db: Vec<Attenuation>,
    pub mean_attenuation_db: f64,
    pub control_rms: f64,
    pub control_peak: f64,
    pub acc_rms: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct EstimatorCost {
    /// "exact" (the structure's true state), "integrate", "kalman".
    pub estimator: String,
    pub mean_attenuation_db: f64,
    pub attenuation_db: Vec<Attenuation>,
    pub control_rms: f64,
    pub contacts: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct GapReport {
    pub storey: String,
    pub gap: f64,
    pub side: i32,
}

/// The report of `twin control` (its JSON is the report contract).
#[derive(Clone, Debug, Serialize)]
pub struct ControlReport {
    pub twin: String,
    pub data: String,
    pub parameters: std::collections::BTreeMap<String, f64>,
    /// What excites the structure: `force:K` or `base`.
    pub excitation: String,
    /// The floor the control force acts on (1-based).
    pub actuator_floor: usize,
    /// The channels the controller reads (the record's responses), in the order of
    /// `sensor_noise_sd` and of a Kalman estimator's `sensor_sd`.
    pub measured: Vec<String>,
    #[serde(rename = "A")]
    pub a: Vec<Vec<f64>>,
    #[serde(rename = "B")]
    pub b: Vec<f64>,
    #[serde(rename = "R")]
    pub r: f64,
    /// Metres per state unit.
    pub state_scale: f64,
    pub state_unit: String,
    pub units_note: String,
    pub estimator: String,
    /// The estimator as the controller runs it (what `twin synth --controller` rebuilds).
    pub estimator_settings: Estimator,
    pub highpass_hz: f64,
    pub substeps: usize,
    pub control_rate_hz: f64,
    pub sensor_noise_sd: Option<Vec<f64>>,
    pub resonances_hz: Vec<f64>,
    pub gaps: Vec<GapReport>,
    pub passive: Passive,
    pub designs: Vec<DesignRun>,
    pub retune: Option<RetuneReport>,
    pub schedule: Option<ScheduleReport>,
    pub estimator_costs: Vec<EstimatorCost>,
}

/// Everything `twin control` computed: the report, and the time histories and frequency
/// responses for the plot.
pub struct ControlOutcome {
    pub report: ControlReport,
    pub passive: Response,
    /// One per entry of `report.designs` (empty when unstable).
    pub designs: Vec<Option<Response>>,
    pub scheduled: Option<Response>,
    pub force: Vec<f64>,
    pub dt: f64,
    /// Per floor, the frequency response from the excitation to the floor's acceleration
    /// ([`floor_frfs`]) of the passive run, of each design's (None when it did not run), of the
    /// gain schedule's.
    pub passive_frf: Vec<Option<FrequencyResponse>>,
    pub design_frfs: Vec<Option<Vec<Option<FrequencyResponse>>>>,
    pub scheduled_frf: Option<Vec<Option<FrequencyResponse>>>,
}

/// Per floor, the Welch H1 estimate from `force` to the run's acceleration (None where the
/// record is too short for a segment).
pub fn floor_frfs(force: &[f64], response: &Response, dt: f64) -> Vec<Option<FrequencyResponse>> {
    let n = force.len();
    response
        .acc
        .iter()
        .map(|acc| welch_h1(force, &acc[..n.min(acc.len())], dt, FRF_SEGMENT))
        .collect()
}

/// Peak of the FRF (dB) in the band around each resonance (rows), per floor (columns).
fn resonance_peaks(
    force: &[f64],
    response: &Response,
    dt: f64,
    resonances: &[f64],
) -> Vec<Vec<f64>> {
    let floors = response.acc.len();
    let mut out = vec![vec![f64::NAN; floors]; resonances.len()];
    for floor in 0..floors {
        let n = force.len().min(response.acc[floor].len());
        let Some(h) = welch_h1(&force[..n], &response.acc[floor][..n], dt, FRF_SEGMENT) else {
            continue;
        };
        for (mode, &fr) in resonances.iter().enumerate() {
            let peak = h
                .frequency
                .iter()
                .zip(&h.magnitude_db)
                .filter(|(f, m)| {
                    (**f - fr).abs() <= RESONANCE_BAND * fr.max(h.frequency[0]) && m.is_finite()
                })
                .map(|(_, m)| *m)
                .fold(f64::NEG_INFINITY, f64::max);
            out[mode][floor] = peak;
        }
    }
    out
}

fn attenuation(
    passive: &[Vec<f64>],
    controlled: &[Vec<f64>],
    resonances: &[f64],
) -> (Vec<Attenuation>, f64) {
    let mut list = Vec::new();
    let mut sum = 0.0;
    let mut count = 0;
    for mode in 0..resonances.len() {
        let floors = passive[mode].len();
        let mut floors_db = vec![f64::NAN; floors];
        for floor in 0..floors {
            floors_db[floor] = passive[mode][floor] - controlled[mode][floor];
            if floors_db[floor].is_finite() {
                sum += floors_db[floor];
                count += 1;
            }
        }
        list.push(Attenuation {
            mode: mode + 1,
            frequency_hz: resonances[mode],
            floors_db,
        });
    }
    (
        list,
        if count > 0 {
            sum / count as f64
        } else {
            f64::NAN
        },
    )
}

fn acc_rms(r: &Response) -> Vec<f64> {
    r.acc.iter().map(|a| rms(a)).collect()
}

/// Controller samples per record sample: the fastest closed-loop pole moves by at most 0.1 rad
/// per sample; a power of two (so that it divides a synthetic record's fine grid), at least 4,
/// at most 4096.
pub fn substeps_for(designs: &[Design], dt: f64) -> usize {
    let fastest = designs
        .iter()
        .flat_map(|d| d.closed_loop_poles.iter())
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0f64, f64::max);
    ((fastest * dt / 0.1).ceil() as usize)
        .clamp(4, 4096)
        .next_power_of_two()
}

struct Runner<'a> {
    twin: &'a Twin,
    data: &'a Measurement,
    setup: LoopSetup,
    estimator: Estimator,
    resonances: Vec<f64>,
    passive_peaks: Vec<Vec<f64>>,
    progress: &'a mut dyn FnMut(u64, u64),
    runs_done: u64,
    runs_total: u64,
}

impl Runner<'_> {
    fn run(&mut self, law: Option<&LoopLaw>) -> Result<Response, ControlError> {
        let (done, total) = (self.runs_done, self.runs_total.max(self.runs_done + 1));
        let progress = &mut *self.progress;
        let mut report = |k: u64, n: u64| progress(done * n + k, total * n);
        let out = simulate(self.twin, self.data, &self.setup, law, &mut report);
        self.runs_done += 1;
        out
    }

    /// Run `gains` with the chosen estimator; an unstable loop is a result, not a failure.
    fn run_law(
        &mut self,
        gains: Gains,
        state: StateSource,
    ) -> Result<Result<Response, String>, ControlError> {
        match self.run(Some(&LoopLaw { gains, state })) {
            Ok(r) => Ok(Ok(r)),
            Err(ControlError::Unstable(message)) => Ok(Err(message)),
            Err(e) => Err(e),
        }
    }

    /// The attenuation of `r` at each resonance against the passive run, and its mean.
    fn attenuation_of(&self, r: &Response) -> (Vec<Attenuation>, f64) {
        let peaks = resonance_peaks(
            &self.data.excitation.values,
            r,
            self.data.dt,
            &self.resonances,
        );
        attenuation(&self.passive_peaks, &peaks, &self.resonances)
    }

    fn design_run(
        &mut self,
        design: Design,
        role: &str,
    ) -> Result<(DesignRun, Option<Response>), ControlError> {
        let state = StateSource::Estimated(self.estimator.clone());
        let outcome = self.run_law(Gains::Fixed(design.gain.clone()), state)?;
        Ok(match outcome {
            Ok(r) => {
                let (att, mean) = self.attenuation_of(&r);
                (
                    DesignRun {
                        design,
                        role: role.into(),
                        contacts: r.contacts.len(),
                        contact_times: r.contacts.iter().map(|c| c.time).collect(),
                        contact_events: r.contacts.clone(),
                        attenuation_db: att,
                        mean_attenuation_db: mean,
                        control_rms: r.control_rms,
                        control_peak: r.control_peak,
                        acc_rms: acc_rms(&r),
                        unstable: None,
                    },
                    Some(r),
                )
            }
            Err(message) => (
                DesignRun {
                    design,
                    role: role.into(),
                    contacts: 0,
                    contact_times: Vec::new(),
                    contact_events: Vec::new(),
                    attenuation_db: Vec::new(),
                    mean_attenuation_db: f64::NAN,
                    control_rms: f64::NAN,
                    control_peak: f64::NAN,
                    acc_rms: vec![f64::NAN; self.setup.plant.floors()],
                    unstable: Some(message),
                },
                None,
            ),
        })
    }
}

fn estimator_of(
    choice: EstimatorChoice,
    options: &ControlOptions,
    noise_sd: Option<&[f64]>,
    data: &Measurement,
    measured: &[Channel],
) -> Estimator {
    match choice {
        EstimatorChoice::Integrate => Estimator::Integrate {
            highpass_hz: options.highpass_hz,
        },
        EstimatorChoice::Kalman => {
            // The model's error as the excitation's: 5 % of the record's excitation RMS per
            // sample; the sensors' noise as the twin calibrated it (else 1 % of each measured
            // channel's RMS, in its own quantity).
            let excitation_rms = rms(&data.excitation.values).max(1e-6);
            let sensor_sd: Vec<f64> = match noise_sd {
                Some(sd) => sd.to_vec(),
                None => measured
                    .iter()
                    .map(|c| (0.01 * rms(data.channel(*c).unwrap_or(&[]))).max(1e-6))
                    .collect(),
            };
            Estimator::Kalman {
                process_sd: 0.05 * excitation_rms,
                sensor_sd: sensor_sd.iter().map(|s| s.max(1e-9)).collect(),
            }
        }
    }
}

/// The record's response channels in the order the controller reads them: accelerations, then
/// velocities, then displacements, each by floor.
pub fn measured_channels(data: &Measurement) -> Vec<Channel> {
    let rank = |q: Quantity| match q {
        Quantity::Acceleration => 0,
        Quantity::Velocity => 1,
        _ => 2,
    };
    let mut channels: Vec<Channel> = data
        .responses
        .iter()
        .map(|s| s.channel)
        .filter(|c| matches!(c, Channel::Response { .. }))
        .collect();
    channels.sort_by_key(|c| match c {
        Channel::Response { quantity, floor } => (rank(*quantity), *floor),
        _ => (3, 0),
    });
    channels.dedup();
    channels
}

fn names(channels: &[Channel]) -> String {
    channels
        .iter()
        .map(Channel::name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether the estimator can run on what the record measures, said before any work: the
/// integrating estimator needs every floor's acceleration; the Kalman observer needs a set of
/// channels from which the state is observable (a mode standing still at every sensor is not).
pub fn check_estimator(
    choice: EstimatorChoice,
    structure: &Structure,
    plant: &numerics::lqr::StateSpace,
    measured: &[Channel],
) -> Result<(), ControlError> {
    match choice {
        EstimatorChoice::Integrate => {
            let every = fmu_lqr::model::every_acceleration(structure.storeys());
            if measured != every.as_slice() {
                return Err(ControlError::Options(format!(
                    "--estimator integrate integrates an accelerometer on every floor ({}); the \
                     record measures {}: use --estimator kalman, which estimates the state from \
                     the channels there are",
                    names(&every),
                    names(measured)
                )));
            }
            Ok(())
        }
        EstimatorChoice::Kalman => {
            let missed = plant.unobservable();
            if missed.is_empty() {
                return Ok(());
            }
            let mut freqs: Vec<f64> = missed
                .iter()
                .map(|e| e[0].hypot(e[1]) / (2.0 * std::f64::consts::PI))
                .collect();
            freqs.sort_by(f64::total_cmp);
            freqs.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs().max(1.0));
            let listed: Vec<String> = freqs.iter().map(|f| format!("{f:.3} Hz")).collect();
            Err(ControlError::Options(format!(
                "the state is not observable from the record's channels {}: the motion at {} \
                 moves none of them (a mode standing still at every sensor); the Kalman \
                 estimator cannot see it, so the controller cannot be designed on it — measure \
                 another floor as well",
                names(measured),
                listed.join(", ")
            )))
        }
    }
}

/// The whole of `twin control`.
pub fn run_control(
    twin: &Twin,
    data: &Measurement,
    options: &ControlOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ControlOutcome, ControlError> {
    check_options(options)?;
    let basis = control_basis(twin, data, options)?;
    let set = design_set(&basis.plant, data, options)?;
    let plan = loop_plan(&basis, data, options)?;
    let mut runner = runner(&basis, data, options, &set, &plan, progress);
    let passive = runner.run(None)?;
    runner.passive_peaks =
        resonance_peaks(&data.excitation.values, &passive, data.dt, &plan.resonances);
    let mut designs = run_designs(&mut runner, set.designs)?;
    let retune = match &options.retune {
        None => None,
        Some(rt) => Some(run_retune(
            &mut runner,
            rt,
            set.retune,
            set.qs[0],
            &mut designs,
        )?),
    };
    let schedule = match &options.schedule {
        None => None,
        Some(so) => Some(run_schedule(
            &mut runner,
            so,
            &basis,
            &plan.gaps,
            &designs.runs,
            retune.as_ref(),
            &set.qs,
        )?),
    };
    let estimator_costs = if options.estimator_costs {
        let choices = estimator_choices(&basis, options, plan.noise_sd.as_deref(), data);
        run_estimator_costs(&mut runner, &designs.runs[0], choices)?
    } else {
        Vec::new()
    };
    let runs = Runs {
        passive,
        designs,
        retune,
        schedule,
        estimator_costs,
    };
    Ok(control_outcome(
        &basis,
        data,
        options,
        set.substeps,
        plan,
        runs,
    ))
}

/// What the control is designed on, all checked before any run: the twin's structure, the
/// channels the record measures, the plant the designs are made on, and the twin with its
/// actuator at the chosen floor.
struct ControlBasis {
    structure: Structure,
    measured: Vec<Channel>,
    plant: StateSpace,
    /// The twin with the actuator at `--actuator-floor`: the one every run drives.
    twin: Twin,
}

/// The designs to run: the requested weights (sorted, without repeats) and their designs, the
/// retune grid's designs (empty without `--retune`), and the controller samples per record
/// sample they fix.
struct DesignSet {
    qs: Vec<f64>,
    designs: Vec<Design>,
    retune: Vec<Design>,
    substeps: usize,
}

/// What every run of the loop shares besides the plant: the sensor noise the controller reads
/// (None: none), the gaps watched, the estimator and the structure's resonances.
struct LoopPlan {
    noise_sd: Option<Vec<f64>>,
    gaps: Vec<Gap>,
    estimator: Estimator,
    resonances: Vec<f64>,
}

/// The design runs so far, in the report's order, each with its response (None when the loop
/// went unstable).
#[derive(Default)]
struct DesignRuns {
    runs: Vec<DesignRun>,
    responses: Vec<Option<Response>>,
}

impl DesignRuns {
    fn push(&mut self, run: DesignRun, response: Option<Response>) {
        self.runs.push(run);
        self.responses.push(response);
    }
}

/// The gain schedule's run: its report and its response.
struct ScheduledRun {
    report: ScheduleReport,
    response: Response,
}

/// Everything the runs gave, for the report.
struct Runs {
    passive: Response,
    designs: DesignRuns,
    retune: Option<RetuneReport>,
    schedule: Option<ScheduledRun>,
    estimator_costs: Vec<EstimatorCost>,
}

/// The options that need nothing else to be checked: at least one q, and a positive corner
/// for the drift removal.
fn check_options(options: &ControlOptions) -> Result<(), ControlError> {
    if options.qs.is_empty() {
        return Err(ControlError::Options("give at least one --q".into()));
    }
    if !(options.highpass_hz.is_finite() && options.highpass_hz > 0.0) {
        return Err(ControlError::Options(format!(
            "--highpass must be a positive frequency (Hz), got {}",
            options.highpass_hz
        )));
    }
    Ok(())
}

/// The twin's structure with the actuator on one of its floors, the record able to drive it,
/// the plant on the record's channels (the estimator able to run on them), and the twin with
/// its actuator at that floor.
fn control_basis(
    twin: &Twin,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<ControlBasis, ControlError> {
    let structure: Structure = structure_of(twin)?;
    design::check_actuator_floor(options.actuator_floor, &structure)?;
    check_record(data, &structure)?;
    let measured = measured_channels(data);
    let plant = plant_measuring(
        &structure,
        options.actuator_floor,
        &measured,
        options.unit.scale(),
    )?;
    check_estimator(options.estimator, &structure, &plant, &measured)?;
    let controlled = with_actuator_at(twin, options.actuator_floor)?;
    Ok(ControlBasis {
        structure,
        measured,
        plant,
        twin: controlled,
    })
}

/// The LQR designs of the requested weights and of the retune grid (multiples of the smallest
/// q), and the controller's rate: `--substeps`, or from the fastest closed-loop pole of them
/// all (all runs share it).
fn design_set(
    plant: &StateSpace,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<DesignSet, ControlError> {
    let mut qs = options.qs.clone();
    qs.sort_by(f64::total_cmp);
    qs.dedup();
    let designs = qs
        .iter()
        .map(|&q| design(plant, q, options.r))
        .collect::<Result<Vec<_>, _>>()?;
    // The retune grid's designs fix the controller's rate too (all runs share it).
    let retune = match &options.retune {
        Some(_) => RETUNE_GRID
            .iter()
            .map(|m| design(plant, qs[0] * m, options.r))
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    let all: Vec<Design> = designs.iter().chain(&retune).cloned().collect();
    let substeps = match options.substeps {
        Some(n) if n >= 1 => n,
        Some(n) => {
            return Err(ControlError::Options(format!(
                "--substeps must be at least 1, got {n}"
            )))
        }
        None => substeps_for(&all, data.dt),
    };
    Ok(DesignSet {
        qs,
        designs,
        retune,
        substeps,
    })
}

/// The sensor noise (`--sensor-noise`, one value or one per measured channel, else the
/// controlled twin's calibrated noise when it has one for every channel read), the gaps watched
/// (the twin's contacts, then `--gap`'s on other storeys), the estimator and the resonances.
fn loop_plan(
    basis: &ControlBasis,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<LoopPlan, ControlError> {
    let twin = &basis.twin;
    let measured = &basis.measured;
    let channels = measured.len();
    let noise_sd: Option<Vec<f64>> = match &options.sensor_noise {
        Some(sd) if sd.len() == 1 => Some(vec![sd[0]; channels]),
        Some(sd) if sd.len() == channels => Some(sd.clone()),
        Some(sd) => {
            return Err(ControlError::Options(format!(
                "the sensor noise has {} values: give one, or one per measured channel \
                 ({channels}: {})",
                sd.len(),
                names(measured)
            )))
        }
        // The twin's calibrated noise, when it has one for every channel read.
        None => measured
            .iter()
            .map(|c| twin.noise_variance_of(*c).map(|x| x.max(0.0).sqrt()))
            .collect(),
    };
    let mut gaps = closed_loop::twin_gaps(twin);
    for g in &options.gaps {
        if !gaps.iter().any(|h| h.storey == g.storey) {
            gaps.push(g.clone());
        }
    }
    let estimator = estimator_of(
        options.estimator,
        options,
        noise_sd.as_deref(),
        data,
        measured,
    );
    Ok(LoopPlan {
        noise_sd,
        gaps,
        estimator,
        resonances: basis.structure.natural_frequencies(),
    })
}

/// The runner of every run: the loop's settings on the controlled twin, and the number of runs
/// the options ask for (the progress counts them).
fn runner<'a>(
    basis: &'a ControlBasis,
    data: &'a Measurement,
    options: &ControlOptions,
    set: &DesignSet,
    plan: &LoopPlan,
    progress: &'a mut dyn FnMut(u64, u64),
) -> Runner<'a> {
    let setup = LoopSetup {
        plant: basis.plant.clone(),
        measured: basis.measured.clone(),
        substeps: set.substeps,
        noise: plan.noise_sd.clone().map(|sd| SensorNoise {
            sd,
            seed: options.seed,
        }),
        gaps: plan.gaps.clone(),
        force_limit: force_limit(&basis.structure, data),
        corrector: false,
    };
    let runs_total = 1
        + set.designs.len()
        + set.retune.len()
        + usize::from(options.schedule.is_some())
        + if options.estimator_costs { 2 } else { 0 };
    Runner {
        twin: &basis.twin,
        data,
        setup,
        estimator: plan.estimator.clone(),
        resonances: plan.resonances.clone(),
        passive_peaks: Vec::new(),
        progress,
        runs_done: 0,
        runs_total: runs_total as u64,
    }
}

/// Run each requested design, in the order of q.
fn run_designs(runner: &mut Runner, designs: Vec<Design>) -> Result<DesignRuns, ControlError> {
    let mut runs = DesignRuns::default();
    for d in designs {
        let (run, response) = runner.design_run(d, "requested")?;
        runs.push(run, response);
    }
    Ok(runs)
}

/// `--retune`: run the grid's designs (multiples of `q0`, the smallest q) in order and choose
/// the first that meets the target; the chosen run joins `designs` unless its q is there.
fn run_retune(
    runner: &mut Runner,
    rt: &Retune,
    grid_designs: Vec<Design>,
    q0: f64,
    designs: &mut DesignRuns,
) -> Result<RetuneReport, ControlError> {
    let mut grid = Vec::new();
    let mut chosen: Option<(DesignRun, Option<Response>)> = None;
    for d in grid_designs {
        let (run, response) = runner.design_run(d, "retuned")?;
        grid.push(RetuneRow {
            q: run.design.q,
            contacts: run.unstable.is_none().then_some(run.contacts),
            control_rms: run.unstable.is_none().then_some(run.control_rms),
            control_peak: run.unstable.is_none().then_some(run.control_peak),
            mean_attenuation_db: run.unstable.is_none().then_some(run.mean_attenuation_db),
            unstable: run.unstable.clone(),
        });
        let ok = run.unstable.is_none()
            && run.contacts <= rt.target
            && rt.max_force.is_none_or(|m| run.control_peak <= m);
        if ok && chosen.is_none() {
            chosen = Some((run, response));
        }
    }
    let verdict = retune_verdict(rt, chosen.as_ref().map(|(run, _)| run), q0);
    let chosen_q = chosen.as_ref().map(|(r, _)| r.design.q);
    if let Some((run, response)) = chosen {
        if !designs.runs.iter().any(|d| d.design.q == run.design.q) {
            designs.push(run, response);
        }
    }
    Ok(RetuneReport {
        target_contacts: rt.target,
        max_force: rt.max_force,
        grid,
        chosen_q,
        verdict,
    })
}

/// The retune's verdict in words: the chosen q and what it keeps, or that no q on the grid
/// (multiples of `q0`) does.
fn retune_verdict(rt: &Retune, chosen: Option<&DesignRun>, q0: f64) -> String {
    match chosen {
        Some(run) => format!(
            "q = {} is the smallest on the grid with at most {} contact initiations ({}){}",
            run.design.q,
            rt.target,
            run.contacts,
            rt.max_force
                .map(|m| format!(
                    " and a peak control force within {m} N ({:.3} N)",
                    run.control_peak
                ))
                .unwrap_or_default()
        ),
        None => format!(
            "no q on the grid ({} … {}) keeps the contact initiations at or below {}{}",
            q0 * RETUNE_GRID[0],
            q0 * RETUNE_GRID[RETUNE_GRID.len() - 1],
            rt.target,
            rt.max_force
                .map(|m| format!(" within {m} N"))
                .unwrap_or_default()
        ),
    }
}

/// `--schedule`: run the gain schedule between the smallest stable design and the highest (the
/// retuned one, else the largest q), watching the first gap, with the corrector beside the
/// physics when the latent variance triggers too.
fn run_schedule(
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
fn schedule_designs(
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
fn variance_threshold(
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

/// The states `--estimator-costs` compares: the exact one, and each estimator that can run on
/// the record's channels (the integrating one needs every floor's acceleration).
fn estimator_choices(
    basis: &ControlBasis,
    options: &ControlOptions,
    noise_sd: Option<&[f64]>,
    data: &Measurement,
) -> Vec<(&'static str, StateSource)> {
    let (structure, plant, measured) = (&basis.structure, &basis.plant, &basis.measured);
    let mut choices = vec![("exact", StateSource::Exact)];
    // The integrating estimator needs every floor's acceleration.
    if check_estimator(EstimatorChoice::Integrate, structure, plant, measured).is_ok() {
        choices.push((
            "integrate",
            StateSource::Estimated(estimator_of(
                EstimatorChoice::Integrate,
                options,
                noise_sd,
                data,
                measured,
            )),
        ));
    }
    if check_estimator(EstimatorChoice::Kalman, structure, plant, measured).is_ok() {
        choices.push((
            "kalman",
            StateSource::Estimated(estimator_of(
                EstimatorChoice::Kalman,
                options,
                noise_sd,
                data,
                measured,
            )),
        ));
    }
    choices
}

/// The first design's cost under each state in `choices`: the chosen estimator's is the
/// design's own run, the others are run; an unstable loop fails, naming the state.
fn run_estimator_costs(
    runner: &mut Runner,
    first: &DesignRun,
    choices: Vec<(&'static str, StateSource)>,
) -> Result<Vec<EstimatorCost>, ControlError> {
    let mut estimator_costs = Vec::new();
    for (name, state) in choices {
        // The chosen estimator's run is the design's own.
        let same = matches!(&state, StateSource::Estimated(e) if *e == runner.estimator);
        let (att, mean, rms_u, contacts) = if same {
            (
                first.attenuation_db.clone(),
                first.mean_attenuation_db,
                first.control_rms,
                first.contacts,
            )
        } else {
            match runner.run_law(Gains::Fixed(first.design.gain.clone()), state)? {
                Ok(r) => {
                    let (att, mean) = runner.attenuation_of(&r);
                    (att, mean, r.control_rms, r.contacts.len())
                }
                Err(message) => {
                    return Err(ControlError::Unstable(format!(
                        "with the {name} state: {message}"
                    )))
                }
            }
        };
        estimator_costs.push(EstimatorCost {
            estimator: name.into(),
            mean_attenuation_db: mean,
            attenuation_db: att,
            control_rms: rms_u,
            contacts,
        });
    }
    Ok(estimator_costs)
}

/// The report and the time histories of the runs.
fn control_outcome(
    basis: &ControlBasis,
    data: &Measurement,
    options: &ControlOptions,
    substeps: usize,
    plan: LoopPlan,
    runs: Runs,
) -> ControlOutcome {
    let (structure, plant) = (&basis.structure, &basis.plant);
    let units_note = match options.unit {
        StateUnit::M => "state in m and m/s; q weighs (m/s)², R weighs N²".to_owned(),
        StateUnit::Mm => "state in mm and mm/s; q weighs (mm/s)², R weighs N²".to_owned(),
    };
    let passive = runs.passive;
    let passive_report = Passive {
        contacts: passive.contacts.len(),
        contact_times: passive.contacts.iter().map(|c| c.time).collect(),
        contact_events: passive.contacts.clone(),
        acc_rms: acc_rms(&passive),
    };
    let (schedule, scheduled) = match runs.schedule {
        Some(s) => (Some(s.report), Some(s.response)),
        None => (None, None),
    };
    let report = ControlReport {
        twin: basis.twin.describe(),
        data: data.path.display().to_string(),
        parameters: design::parameter_map(structure),
        excitation: structure.excitation.name(),
        actuator_floor: options.actuator_floor,
        measured: basis.measured.iter().map(Channel::name).collect(),
        a: design::rows(&plant.a),
        b: plant.b.iter().copied().collect(),
        r: options.r,
        state_scale: plant.state_scale,
        state_unit: options.unit.name().into(),
        units_note,
        estimator: plan.estimator.name().into(),
        estimator_settings: plan.estimator.clone(),
        highpass_hz: options.highpass_hz,
        substeps,
        control_rate_hz: substeps as f64 / data.dt,
        sensor_noise_sd: plan.noise_sd,
        resonances_hz: plan.resonances,
        gaps: plan
            .gaps
            .iter()
            .map(|g| GapReport {
                storey: g.label(),
                gap: g.gap(),
                side: g.side(),
            })
            .collect(),
        passive: passive_report,
        designs: runs.designs.runs,
        retune: runs.retune,
        schedule,
        estimator_costs: runs.estimator_costs,
    };
    let force = &data.excitation.values;
    let frfs = |r: &Response| floor_frfs(force, r, data.dt);
    ControlOutcome {
        report,
        passive_frf: frfs(&passive),
        design_frfs: runs
            .designs
            .responses
            .iter()
            .map(|r| r.as_ref().map(frfs))
            .collect(),
        scheduled_frf: scheduled.as_ref().map(frfs),
        passive,
        designs: runs.designs.responses,
        scheduled,
        force: force.clone(),
        dt: data.dt,
    }
}

/// The record can drive the structure: its excitation is the structure's (a force, or a ground
/// acceleration), and every response it measures is of a floor the structure has; refused
/// naming the column.
pub fn check_record(data: &Measurement, structure: &Structure) -> Result<(), ControlError> {
    for signal in data.channels() {
        let name = signal.channel.name();
        signal
            .channel
            .check(&name, structure)
            .map_err(|e| ControlError::Options(format!("{}: {e}", data.path.display())))?;
    }
    Ok(())
}

/// A control force beyond this stops a run as unstable: a thousand times the record's peak
/// excitation as a force (a ground acceleration times the structure's mass).
fn force_limit(structure: &Structure, data: &Measurement) -> f64 {
    let peak = data
        .excitation
        .values
        .iter()
        .fold(0.0f64, |m, f| m.max(f.abs()));
    let per_unit = match structure.excitation {
        structure::Excitation::Force { .. } => 1.0,
        structure::Excitation::Base => structure.mass.iter().sum(),
    };
    1e3 * (peak * per_unit).max(1e-3)
}

/// A controller read back from a `twin control` report: what `twin synth --controller` puts in
/// the synthetic structure's loop.
#[derive(Clone, Debug, serde::Deserialize)]
pub struct ControllerSpec {
    pub parameters: std::collections::BTreeMap<String, f64>,
    pub state_scale: f64,
    pub estimator_settings: Estimator,
    pub control_rate_hz: f64,
    pub sensor_noise_sd: Option<Vec<f64>>,
    pub designs: Vec<SpecDesign>,
    /// `force:K` or `base` (a report from before excitations were named: a force at floor 1).
    #[serde(default)]
    pub excitation: Option<String>,
    /// The actuator's floor (absent: 1).
    #[serde(default)]
    pub actuator_floor: Option<usize>,
    /// The channels the controller reads (absent: every floor's acceleration).
    #[serde(default)]
    pub measured: Option<Vec<String>>,
}

#[derive(Clone, Debug, serde::Deserialize)]
pub struct SpecDesign {
    pub q: f64,
    pub gain: Vec<f64>,
    pub unstable: Option<String>,
}

impl ControllerSpec {
    /// Read a `twin control` report.
    pub fn load(path: &std::path::Path) -> Result<Self, ControlError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ControlError::Options(format!("cannot read {}: {e}", path.display())))?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// Parse a report's JSON text; `origin` names it in errors.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, ControlError> {
        let de = &mut serde_json::Deserializer::from_str(text);
        serde_path_to_error::deserialize(de).map_err(|e| {
            ControlError::Options(format!(
                "{origin}: not a `twin control` report: at {}: {}",
                e.path(),
                e.inner()
            ))
        })
    }

    /// The design with state weight `q` (None: the first stable one).
    pub fn design(&self, q: Option<f64>) -> Result<&SpecDesign, ControlError> {
        let stable = || self.designs.iter().filter(|d| d.unstable.is_none());
        match q {
            Some(q) => stable().find(|d| d.q == q).ok_or_else(|| {
                let have: Vec<String> = stable().map(|d| d.q.to_string()).collect();
                ControlError::Options(format!(
                    "the report has no stable design with q = {q} (it has {})",
                    have.join(", ")
                ))
            }),
            None => stable()
                .next()
                .ok_or_else(|| ControlError::Options("the report has no stable design".into())),
        }
    }

    /// The structure the design was made on: as many storeys as the report has masses
    /// (m1, m2, … without a gap), each with its c and k.
    pub fn structure(&self) -> Result<Structure, ControlError> {
        let get = |name: String| {
            self.parameters.get(&name).copied().ok_or_else(|| {
                ControlError::Options(format!("the report's parameters lack '{name}'"))
            })
        };
        let storeys = (1..)
            .take_while(|i| self.parameters.contains_key(&format!("m{i}")))
            .count();
        if storeys == 0 {
            return Err(ControlError::Options(
                "the report's parameters lack 'm1'".into(),
            ));
        }
        let excitation = match &self.excitation {
            None => structure::Excitation::default(),
            Some(text) => structure::Excitation::parse(text)
                .map_err(|e| ControlError::Options(format!("the report's excitation: {e}")))?,
        };
        let mut s = Structure::uniform(storeys, 0.0, 0.0, 0.0, excitation);
        for name in s.parameter_names() {
            let value = get(name.clone())?;
            s.set(&name, value);
        }
        s.validate()
            .map_err(|e| ControlError::Options(format!("the report's structure: {e}")))?;
        Ok(s)
    }

    /// The actuator's floor (1 for a report that names none).
    pub fn actuator_floor(&self) -> usize {
        self.actuator_floor.unwrap_or(1)
    }

    /// The channels the controller reads, in its order (every floor's acceleration for a
    /// report that names none).
    pub fn measured(&self) -> Result<Vec<Channel>, ControlError> {
        let storeys = self.structure()?.storeys();
        match &self.measured {
            None => Ok(fmu_lqr::model::every_acceleration(storeys)),
            Some(names) => names
                .iter()
                .map(|n| {
                    Channel::parse(n).ok_or_else(|| {
                        ControlError::Options(format!(
                            "the report's measured channel '{n}' is not acc<i>, vel<i> or disp<i>"
                        ))
                    })
                })
                .collect(),
        }
    }

    /// The design's plant: the report's structure, actuator and measured channels.
    pub fn plant(&self) -> Result<numerics::lqr::StateSpace, ControlError> {
        plant_measuring(
            &self.structure()?,
            self.actuator_floor(),
            &self.measured()?,
            self.state_scale,
        )
    }

    /// The controller for design `q`, sampling every `dt` seconds (the report's rate is
    /// `control_rate_hz`).
    pub fn controller(
        &self,
        q: Option<f64>,
        dt: f64,
    ) -> Result<numerics::lqr::Controller, ControlError> {
        let design = self.design(q)?;
        let plant = self.plant()?;
        if !(self.control_rate_hz.is_finite() && self.control_rate_hz > 0.0) {
            return Err(ControlError::Options(format!(
                "the report's control rate {} Hz is not positive",
                self.control_rate_hz
            )));
        }
        Ok(numerics::lqr::Controller::new(
            &plant,
            &design.gain,
            &self.estimator_settings,
            dt,
        )?)
    }
}

/// The twin's prediction of a controlled record: the twin's physics in the loop with the
/// report's controller (reading the twin's own accelerations, without noise), driven by the
/// record's force — not the record's control force replayed open-loop, which a high-gain loop
/// makes ill-conditioned (the structure answers to the small difference of two large forces).
pub fn predict_controlled(
    twin: &Twin,
    data: &Measurement,
    spec: &ControllerSpec,
    q: Option<f64>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<crate::twin::run::Prediction, ControlError> {
    let design = spec.design(q)?;
    let plant = spec.plant()?;
    let structure = spec.structure()?;
    check_record(data, &structure)?;
    let controlled = with_actuator_at(twin, spec.actuator_floor())?;
    let substeps = (spec.control_rate_hz * data.dt).round().max(1.0) as usize;
    let setup = LoopSetup {
        plant,
        measured: spec.measured()?,
        substeps,
        noise: None,
        gaps: Vec::new(),
        force_limit: force_limit(&structure, data),
        corrector: false,
    };
    let law = LoopLaw {
        gains: Gains::Fixed(design.gain.clone()),
        state: StateSource::Estimated(spec.estimator_settings.clone()),
    };
    let r = simulate(&controlled, data, &setup, Some(&law), progress)?;
    Ok(crate::twin::run::Prediction::of_accelerations(
        r.time, r.acc,
    ))
}
