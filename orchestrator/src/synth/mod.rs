//! `twin synth`: the synthetic physical twin. It makes measurement records of a simulated
//! three-storey shear frame — any set of effects from the shear FMU's library (and two kinds the
//! library deliberately lacks, Bouc–Wen hysteresis and quadratic (velocity-squared) damping, for
//! hidden-effect tests), parameter changes
//! at given times, a band-limited random force with optional amplitude windows, and Gaussian
//! sensor noise — for tests, demos and teaching.
//!
//! Outputs: the measurement CSV (`time,force,acc1,acc2,acc3`, the format of `data/dataset1.csv`:
//! times with 6 decimals, values with 9 significant digits; nothing in it says how it was made)
//! and a truth JSON that says everything about how it was made.
//!
//! # How a record is made
//!
//! * **Structure**: [`fmu_shear::ShearModel`] in-process, integrated by RK4 with its own fine step
//!   `h = 1 / (sample_rate · oversample)` (default 64 steps per sample interval), independent of the
//!   FMU's `substeps`. The force is linear between the fine samples. Parameter changes take effect
//!   exactly at their time (the fine step is split there). The record starts from rest.
//! * **Hysteresis** (not in the FMU's library): each `hysteresis` effect adds a state `z` (m,
//!   starting at 0) to the RK4 state, integrated at the same fine step together with the
//!   structure (and, per effect, the work `∫ k_h z dδ`). Its steps are split where a storey's
//!   `δ̇·z` changes sign (the Bouc–Wen law switches branch there), as the library's contact is
//!   split where its gap closes. Records without hysteresis are made exactly as before (the
//!   structure alone, by [`fmu_shear::ShearModel::advance`]).
//! * **Quadratic damping** (not in the FMU's library either): each `quadratic_damping` effect's
//!   force `c₂·u|u|` enters the accelerations in the same RK4 state and step (with, per effect,
//!   the energy it dissipated, `∫ c₂|u|³ dt`, as one more state). The force is C¹ in u, so no
//!   step is split for it. Records with neither of these two effects are made exactly as before
//!   them.
//! * **Force**: white Gaussian noise on a generator grid of 8 points per sample interval,
//!   multiplied by the amplitude envelope (1 outside windows, `gain` inside, raised-cosine ramps of
//!   `ramp` seconds centred on each window edge; overlapping windows multiply), then low-passed by
//!   an FFT mask that keeps the bins with `low_hz < f < band_hz` (DC is always removed). The
//!   result is a trigonometric polynomial, periodic over the record length `samples / sample_rate`,
//!   evaluated exactly on the fine grid: the force, and so the written force samples, do not
//!   depend on `oversample`. By default (`"between_samples": "linear"`) the structure sees the
//!   force linear between the sample values (the same samples): what a twin driving the shear FMU
//!   with first-order hold at the sample rate assumes, and what the bundled examples look like
//!   (a linear model fits them to 0.05 % NMSE). With `"band-limited"` it sees the band-limited
//!   signal itself, and the noise-free linear twin then misses the record by NMSE ≈ 0.2–0.5 % per
//!   floor (measured in `tests/synth.rs`), whatever the band: linear interpolation at 51.2 Hz is
//!   coarse for the structure's modes. That default keeps the twin's input convention from
//!   looking like missing physics in the hidden-effect tests. It is scaled so that its RMS at envelope 1 is `rms`
//!   (`rms / √(Σ z² / Σ envelope²)` on the generator grid, exact when there is no window).
//! * **Outputs**: at each sample time the force and the floor accelerations `ÿ(t_k)` of the state
//!   at `t_k` (point samples, no anti-aliasing filter), plus Gaussian noise of sd
//!   `fraction_i × RMS(ÿ_i)` (the noise-free record's RMS) or an absolute sd per floor, and
//!   optionally on the force (`force_fraction × RMS(force)`).
//! * **Random numbers**: `rand_chacha::ChaCha8Rng::seed_from_u64(seed)`, stream 1 for the force,
//!   stream 2 for the noise, Gaussians from `rand_distr::StandardNormal`; the same scenario gives
//!   the same files bit for bit, and the force does not depend on the effects, changes or noise.
//!
//! # Scenario JSON
//!
//! Every field is optional; unknown fields are refused.
//!
//! ```json
//! {
//!   "seed": 7,                     // u64, default 0
//!   "duration": 20.0,              // s, default 20; samples = round(duration · sample_rate)
//!   "sample_rate": 51.2,           // Hz, default 51.2
//!   "oversample": 64,              // fine RK4 steps per sample interval, default 64
//!   "parameters": {                // each a list of 3; default: dataset1.csv's calibrated MAP
//!     "m": [4.637, 5.284, 4.920],  // floor masses, kg (> 0)
//!     "c": [8.14, 3.65, 2.56],     // storey damping, N s/m (≥ 0)
//!     "k": [3850, 4100, 4681]      // storey stiffness, N/m (≥ 0)
//!   },
//!   "force": {
//!     "rms": 0.25,                 // N at envelope 1, default 0.25 (dataset1.csv: 0.2495 N)
//!     "band_hz": 25.6,             // upper band edge, ≤ sample_rate / 2, default sample_rate / 2
//!     "low_hz": 0.0,               // lower band edge, default 0 (DC is removed anyway)
//!     "between_samples": "linear",  // or "band-limited" (the structure sees the band-limited signal)
//!     "windows": [{"start": 13, "end": 17, "gain": 3.0, "ramp": 0.5}]  // ramp default 0.5 s
//!   },
//!   "noise": {                     // one of fraction | sd; default fraction 0.03
//!     "fraction": 0.03,            // of each floor's response RMS: a number or a list of 3
//!     "sd": [0.004, 0.003, 0.003], // absolute, m/s²: a number or a list of 3
//!     "force_fraction": 0.0        // noise on the force, fraction of its RMS, default 0
//!   },
//!   "effects": [
//!     {"kind": "contact", "location": [2, 3], "gap": 5e-4, "stiffness": 9000, "side": "both"},
//!     {"kind": "cubic", "location": [2], "stiffness": 5e9},
//!     {"kind": "friction", "location": [1], "force": 0.2, "velocity_scale": 1e-3},
//!     {"kind": "hysteresis", "location": [2], "stiffness": 1000, "yield": 5e-4,
//!      "beta": 0.5, "gamma": 0.5, "exponent": 2},
//!     {"kind": "quadratic_damping", "location": [2], "coefficient": 400},
//!     {"kind": "quadratic_damping", "floor": 1, "coefficient": 400}
//!   ],
//!   "changes": [{"at": 8.0, "parameter": "k2", "factor": 0.85}]
//! }
//! ```
//!
//! * `contact`: `location` = `[lower, upper]` adjacent floors, 0 = the ground (`[0, 1]`, `[1, 2]`,
//!   `[2, 3]`); `gap` m (default 5e-4), `stiffness` N/m (default 9000), `side` `"both"` (default),
//!   `"positive"` (upper floor ahead of the lower one closes it) or `"negative"`, or 0 / 1 / −1.
//! * `cubic`: `location` = `[storey]` (storey 1 = ground–floor 1, 2 = floors 1–2, 3 = floors 2–3,
//!   the FMU's `cubic1..3`) or `[lower, upper]`; `stiffness` N/m³ (default 1e9; negative softens).
//! * `friction`: `location` = `[floor]` (1..3); `force` N (default 0.1), `velocity_scale` m/s
//!   (default 1e-3).
//! * `hysteresis` (**not** in the shear FMU's library: no twin configuration reproduces it):
//!   a Bouc–Wen hysteretic restoring force in a storey. `location` = `[storey]` or
//!   `[lower, upper]` as for `cubic`; `stiffness` k_h N/m (default 1000, > 0), `yield` z_y m
//!   (default 5e-4, > 0), `beta` and `gamma` (default 0.5 each, β + γ > 0), `exponent` n
//!   (default 2, ≥ 1). With δ the storey drift (upper floor minus lower, 0 = the ground) and the
//!   hysteretic variable z (m, 0 at the start), `ż = δ̇ · (1 − (β·sign(δ̇·z) + γ)·|z/z_y|^n)`,
//!   and the storey carries the force `k_h·z`, applied as a storey spring of extension δ would
//!   be (positive resists a positive drift, like `cubic`). For |z| ≪ z_y it is an extra linear
//!   storey stiffness k_h; |z| saturates at `z_y·(1/(β+γ))^(1/n)`; the loops dissipate energy.
//!   Several may be given, one per storey. The truth reports, per hysteresis effect,
//!   `in_library: false`, `z_saturation`, `max_abs_z` and `hysteretic_work` (`∫ k_h z dδ` over
//!   the record, J: the energy dissipated plus what z stores at the end, `k_h·z²/2`
//!   when β = γ); [`SynthRecord::hysteresis`] has z, δ and that work at the sample times.
//! * `quadratic_damping` (**not** in the shear FMU's library either): a velocity-squared damping
//!   force `c₂·u|u|` ([`EffectSpec::QuadraticDamping`], site a [`DampingSite`]). Either across a
//!   storey, `location` = `[storey]` or `[lower, upper]` as for `cubic`, with u the storey's
//!   relative velocity `v_s − v_{s−1}` (0 = the ground) and the force applied as the library's
//!   storey forces (positive resists: `+f` on the upper floor, `−f` on the lower); or on a floor,
//!   `"floor": f` (1..3) instead of `location`, with u the floor's velocity and the force to the
//!   ground. `coefficient` c₂ N s²/m² (default 400, finite and > 0). On the default structure
//!   and force (relative velocities up to ~0.01 m/s) c₂ = 400 at storey 2 is about half the
//!   storey's linear damping force (RMS) and changes ÿ by NMSE 0.5 / 1.6 / 0.5 % per floor over
//!   20 s (measured in `tests/synth.rs`); c₂ = 40 only by ~0.02 %. One per storey and one per
//!   floor. Its `fmu_prefix` (`quadratic_damping2`, `quadratic_damping_floor1`) names no FMU
//!   variable; the truth reports `in_library: false`, `dissipated_energy` (`∫ c₂|u|³ dt` over
//!   the record, J) and the largest |u| as `max_drift_or_velocity`.
//! * `effects_from` (s, default 0): the library's effects (contact, cubic, friction) act from the
//!   first sample at or after it — an effect that appears; hysteresis and dampers act throughout.
//! * `changes`: `parameter` one of `m1..m3`, `c1..c3`, `k1..k3`; either `factor` (multiplies the
//!   value in force at that time) or `value`; `at` in s, inside the record. Changes apply in time
//!   order.
//!
//! * Any building (written in the JSON only when it is not the paper's rig, whose scenarios read
//!   as they always have): `"storeys": N` (the parameters' lists then have N values; without
//!   them equal floors of [`DEFAULT_FLOOR_MASS`] kg and storeys of [`DEFAULT_STOREY_DAMPING`]
//!   N s/m and [`DEFAULT_STOREY_STIFFNESS`] N/m), `"excitation": "force:K" | "base"`, and
//!   `"channels": ["acc1 (g)", "acc3 (g)", "vel5 (mm/s)"]` (a record's header fields: the
//!   responses written, each in its unit; default an accelerometer per floor in m/s²; the noise
//!   `fraction`/`sd` one value or one per channel, `sd` in SI). Effects at any site of the
//!   building (`contact` `[L, L+1]` for L = 0..N−1, `cubic` storeys 1..N, `friction` floors
//!   1..N, hysteresis and quadratic damping at any storey or floor); a controller in the loop is
//!   written for the paper's layout (its force at the shaker's floor) and refused elsewhere.
//!   Under `"base"` the excitation column
//!   is `ground_acc` (m/s²), accelerometers read the absolute acceleration, and the signal is
//!   [`ground_motion`]: Gaussian white noise shaped by the Kanai–Tajimi filter
//!   (`"ground_motion": {"soil_hz": 2.5, "soil_damping": 0.6, ...}`: firm soil) in the force's
//!   band, scaled to `force.rms` m/s² when stationary, under the Jennings–Housner–Tsai envelope
//!   (`rise_end` 10 % of the record, `strong_end` 50 %, `decay` 4 / (duration − strong_end)).
//!
//! The truth JSON's `scenario` member is the scenario with every default filled in; given back as
//! `--scenario`, it makes the same record.
//!
//! # Flags
//!
//! Flags override the scenario's values and extend its lists: `--seed 3 --force-rms 1.2
//! --force-window 13:17:3[:RAMP] --effect contact@2-3[:gap=5e-4,stiffness=9000,side=both]
//! --effect cubic@2:stiffness=5e9 --effect friction@1:force=0.2
//! --effect hysteresis@2:stiffness=1500,yield=3e-4 --effect quadratic-damping@2:coefficient=400
//! --effect quadratic-damping@floor1:coefficient=400 --change k2@8:0.85` (factor) or
//! `--change k2@8=3500` (value), `--mass/--damping/--stiffness A,B,C`, `--noise-fraction`,
//! `--noise-sd`, `--force-noise-fraction`, `--band-hz`, `--low-hz`,
//! `--force-between-samples band-limited|linear`, `--duration`,
//! `--sample-rate`, `--oversample`.
//!
//! # Library
//!
//! [`synth_record`] makes a record in-process from a [`Scenario`]: the [`Measurement`] exactly as
//! the written CSV reads back, the noise-free accelerations and the fine-grid force (and the
//! hysteresis states, if any), and the [`Truth`] (with, per quadratic damper, the energy it
//! dissipated).

mod flags;
mod force;
mod integrate;
mod scenario;
mod structure;
mod truth;

pub use crate::record::{csv_text, format_g9};
pub use flags::{parse_change_flag, parse_effect_flag, parse_effect_flag_for};
pub use force::{band_limited_force, envelope, ground_motion};
pub use scenario::{
    header_field, BetweenSamples, Change, ChangeHow, DampingSite, EffectSpec, ForceSpec,
    ForceWindow, GroundMotion, NoiseLevel, NoiseSpec, ParamKind, ParamName, Scenario,
    DEFAULT_FLOOR_MASS, DEFAULT_SOIL_DAMPING, DEFAULT_SOIL_HZ, DEFAULT_STOREY_DAMPING,
    DEFAULT_STOREY_STIFFNESS,
};
pub use truth::{
    ChangeTruth, EffectTruth, ForceTruth, NoiseTruth, RecordTruth, ResponseTruth, StructureTruth,
    Truth,
};

use std::collections::HashMap;
use std::path::PathBuf;

use ::structure::channel::{Channel, ExcitationKind, Unit};
use ::structure::Excitation;
use fmu_shear::ShearModel;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use self::structure::Hysteretic;
use crate::record::write::{round9, round_time};
use crate::record::{Measurement, Signal};
use integrate::{FineGrid, Integrated, Integration};

/// What can go wrong making a synthetic record. The messages say where (the scenario file and
/// field, or the command-line flag).
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The scenario (a file, a field, a flag) is not valid.
    #[error("{0}")]
    Scenario(String),
    #[error("{origin}: cannot read the scenario")]
    Read {
        origin: String,
        #[source]
        source: std::io::Error,
    },
    /// A valid scenario whose record cannot be made.
    #[error("{0}")]
    Record(String),
}

pub(crate) type Result<T, E = SynthError> = std::result::Result<T, E>;

pub const DEFAULT_SAMPLE_RATE: f64 = 51.2;
pub const DEFAULT_DURATION: f64 = 20.0;
pub const DEFAULT_OVERSAMPLE: u32 = 64;
/// The RMS of `data/dataset1.csv`'s force is 0.2495 N (dataset2: 0.2505 N).
pub const DEFAULT_FORCE_RMS: f64 = 0.25;
pub const DEFAULT_NOISE_FRACTION: f64 = 0.03;
pub const DEFAULT_WINDOW_RAMP: f64 = 0.5;
/// The paper rig's scenario is made of the structure `data/dataset1.csv` shows (the rig's
/// [`::structure::paper::DATASET1_MASS`] and the rest).
pub use ::structure::paper::{
    DATASET1_DAMPING as DEFAULT_DAMPING, DATASET1_MASS as DEFAULT_MASS,
    DATASET1_STIFFNESS as DEFAULT_STIFFNESS,
};
/// White-noise points per sample interval on which the force is generated.
pub const GENERATOR_OVERSAMPLE: usize = 8;
/// Defaults of the `hysteresis` effect (Bouc–Wen): k_h N/m, z_y m, β, γ, n.
pub const DEFAULT_HYSTERESIS_STIFFNESS: f64 = 1000.0;
pub const DEFAULT_HYSTERESIS_YIELD: f64 = 5e-4;
pub const DEFAULT_HYSTERESIS_BETA: f64 = 0.5;
pub const DEFAULT_HYSTERESIS_GAMMA: f64 = 0.5;
pub const DEFAULT_HYSTERESIS_EXPONENT: f64 = 2.0;
/// Default of the `quadratic_damping` effect's c₂, N s²/m².
pub const DEFAULT_QUADRATIC_DAMPING: f64 = 400.0;
/// Fine steps in one record at most (memory and time guard).
const MAX_FINE_POINTS: usize = 1 << 26;
const MAX_OVERSAMPLE: u32 = 100_000;
const FORCE_STREAM: u64 = 1;
const NOISE_STREAM: u64 = 2;
const CONTROL_SENSOR_STREAM: u64 = 3;

// ---------------------------------------------------------------------------------------------
// Making a record
// ---------------------------------------------------------------------------------------------

/// A synthetic record.
#[derive(Debug, Clone)]
pub struct SynthRecord {
    /// Exactly what the CSV holds and [`Measurement::read`] gives back (`path` = `<synthetic>`
    /// until written).
    pub measurement: Measurement,
    /// The response channels before noise and rounding, at the sample times, in the record's
    /// order and in SI (the default channels: the floor accelerations).
    pub clean_acc: Vec<Vec<f64>>,
    /// The excitation (the force, or the ground acceleration) before noise and rounding, at
    /// the sample times.
    pub clean_force: Vec<f64>,
    /// The force on the fine grid: `fine_force[j]` at `t = j · fine_step`, `samples · oversample`
    /// points (one period of the force). The structure sees it linearly interpolated.
    pub fine_force: Vec<f64>,
    pub fine_step: f64,
    /// One per `hysteresis` effect, in the scenario's order: its states at the sample times.
    pub hysteresis: Vec<HysteresisTrace>,
}

/// A hysteresis effect's noise-free internals at the sample times `k / sample_rate`.
#[derive(Debug, Clone)]
pub struct HysteresisTrace {
    /// Index in the scenario's effects.
    pub effect: usize,
    /// 1..N.
    pub storey: usize,
    /// The hysteretic variable z, m (the storey force is `k_h · z`).
    pub z: Vec<f64>,
    /// The storey drift δ (upper floor minus lower), m.
    pub drift: Vec<f64>,
    /// `∫₀ᵗ k_h z dδ`, J, integrated with the structure on the fine grid.
    pub work: Vec<f64>,
}

/// The floor accelerations an accelerometer reads at the model's state under the excitation
/// `excitation` (and the model's control force), through the effects beside the model: relative
/// to the ground, plus the ground acceleration under ground motion.
fn floor_accelerations(
    s: &Scenario,
    hysteretic: &Hysteretic,
    model: &ShearModel,
    excitation: f64,
) -> Vec<f64> {
    let mut a = hysteretic.acceleration(model, excitation);
    if s.excitation == Excitation::Base {
        for x in &mut a {
            *x += excitation;
        }
    }
    a
}

/// Make a record: see the module documentation.
pub fn synth_record(s: &Scenario) -> Result<(SynthRecord, Truth)> {
    synth_controlled(s, None)
}

/// Builds the controller for the interval it will sample at (s).
pub type ControllerFactory =
    Box<dyn FnOnce(f64) -> std::result::Result<numerics::lqr::Controller, String>>;

/// A controller in the synthetic structure's loop: about every `interval` seconds (a whole
/// number of fine steps) it reads the floor accelerations (with its own sensor noise:
/// `sensor_sd`, m/s², drawn from `seed`) and the force, and holds its control force until the
/// next reading.
pub struct InLoopController {
    pub make: ControllerFactory,
    pub interval: f64,
    /// Per floor.
    pub sensor_sd: Vec<f64>,
    pub seed: u64,
}

/// Make a record with a controller in the loop (`None`: passive, as [`synth_record`]). The
/// record gets a `control` column: the control force at each sample, as the controller set it
/// there.
pub fn synth_controlled(
    s: &Scenario,
    control: Option<InLoopController>,
) -> Result<(SynthRecord, Truth)> {
    s.validate("scenario")?;
    if control.is_some()
        && !::structure::paper::is_paper_rig(&::structure::paper::Layout {
            storeys: s.storeys(),
            excitation: s.excitation,
            control_floor: ::structure::paper::CONTROL_FLOOR,
        })
    {
        return Err(SynthError::Scenario(format!(
            "a controller in the loop is written for the paper's layout (3 storeys, a force at floor 1), not {} storeys under {}",
            s.storeys(),
            s.excitation.describe()
        )));
    }
    let grid = FineGrid::of(s);
    let (fine_force, bins) = if s.excitation == Excitation::Base {
        ground_motion(s)?
    } else {
        band_limited_force(s)?
    };
    let channels = s.response_channels();
    let run = Integration::new(s, grid, &fine_force, &channels, control)?.run()?;
    let levels = NoiseLevels::of(s, &run);
    let measurement = noisy_measurement(s, grid, &channels, &run, &levels);
    let truth = truth_of(s, grid, &channels, bins, levels, &run);
    let record = SynthRecord {
        measurement,
        clean_acc: run.clean_acc,
        clean_force: run.clean_force,
        fine_force,
        fine_step: grid.hf,
        hysteresis: run.traces,
    };
    Ok((record, truth))
}

/// Root mean square.
fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// The record's noise: each response channel's noise-free RMS and the sd added to it (a
/// fraction of that RMS, or absolute), the force's RMS and its noise sd.
struct NoiseLevels {
    response_rms: Vec<f64>,
    acc_sd: Vec<f64>,
    force_rms: f64,
    force_sd: f64,
}

impl NoiseLevels {
    fn of(s: &Scenario, run: &Integrated) -> NoiseLevels {
        let response_rms: Vec<f64> = run.clean_acc.iter().map(|c| rms(c)).collect();
        let acc_sd: Vec<f64> = (0..run.clean_acc.len())
            .map(|c| match &s.noise.level {
                NoiseLevel::Fraction(_) => s.noise.level.at(c) * response_rms[c],
                NoiseLevel::Sd(_) => s.noise.level.at(c),
            })
            .collect();
        let force_rms = rms(&run.clean_force);
        NoiseLevels {
            response_rms,
            acc_sd,
            force_rms,
            force_sd: s.noise.force_fraction * force_rms,
        }
    }
}

/// The measurement as the CSV holds it: the noisy responses and excitation, each value rounded
/// as the CSV writes it in its channel's unit, the times, and the control force (if any).
fn noisy_measurement(
    s: &Scenario,
    grid: FineGrid,
    channels: &[(Channel, Unit)],
    run: &Integrated,
    levels: &NoiseLevels,
) -> Measurement {
    let (n, dt) = (grid.n, grid.dt);
    let base = s.excitation == Excitation::Base;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(NOISE_STREAM);
    let mut gauss = || -> f64 { StandardNormal.sample(&mut rng) };
    // Each value rounded as the CSV writes it, in the channel's unit, then back in SI: exactly
    // what reading the file gives.
    let written = |x: f64, unit: Unit| {
        let scale = unit.to_si();
        if scale == 1.0 {
            round9(x)
        } else {
            round9(x / scale) * scale
        }
    };
    let mut acc: Vec<Vec<f64>> = Vec::with_capacity(channels.len());
    for (c, (_, unit)) in channels.iter().enumerate() {
        acc.push(
            run.clean_acc[c]
                .iter()
                .map(|a| written(a + levels.acc_sd[c] * gauss(), *unit))
                .collect(),
        );
    }
    let force: Vec<f64> = run
        .clean_force
        .iter()
        .map(|x| round9(x + levels.force_sd * gauss()))
        .collect();
    let time: Vec<f64> = (0..n).map(|k| round_time(k as f64 * dt)).collect();
    let mut extra = HashMap::new();
    if let Some(cs) = &run.control {
        extra.insert(
            "control".to_owned(),
            cs.iter().copied().map(round9).collect(),
        );
    }
    Measurement {
        path: PathBuf::from("<synthetic>"),
        time,
        dt,
        excitation: Signal {
            channel: Channel::Excitation(if base {
                ExcitationKind::GroundAcc
            } else {
                ExcitationKind::Force
            }),
            unit: if base {
                Unit::MetrePerSecond2
            } else {
                Unit::Newton
            },
            values: force,
        },
        responses: channels
            .iter()
            .zip(acc)
            .map(|(&(channel, unit), values)| Signal {
                channel,
                unit,
                values,
            })
            .collect(),
        extra,
        header_line: None,
    }
}

/// The truth: everything about how the record was made.
fn truth_of(
    s: &Scenario,
    grid: FineGrid,
    channels: &[(Channel, Unit)],
    bins: usize,
    levels: NoiseLevels,
    run: &Integrated,
) -> Truth {
    Truth {
        generator: format!("twin synth (shear-twin orchestrator {})", env!("CARGO_PKG_VERSION")),
        scenario: s.to_json(),
        record: record_truth(s, grid, channels, &run.hysteretic),
        structure: structure_truth(s, &run.model),
        effects: effect_truths(s, run),
        changes: run.changes.clone(),
        force: force_truth(s, grid, bins, &levels, &run.clean_force),
        noise: NoiseTruth {
            kind: match s.noise.level {
                NoiseLevel::Fraction(_) => "Gaussian, sd = fraction × the floor's noise-free RMS".into(),
                NoiseLevel::Sd(_) => "Gaussian, absolute sd".into(),
            },
            acc_sd: levels.acc_sd,
            force_sd: levels.force_sd,
            response_rms: levels.response_rms,
        },
        response: ResponseTruth {
            max_abs_drift: run.stats.max_drift.clone(),
            max_abs_displacement: run.stats.max_disp.clone(),
            max_abs_acceleration: run.stats.max_acc.clone(),
        },
        random_numbers: format!(
            "rand_chacha ChaCha8Rng::seed_from_u64({}), stream {FORCE_STREAM} force, stream {NOISE_STREAM} noise; rand_distr StandardNormal",
            s.seed
        ),
    }
}

/// The record's columns, sampling and integrator.
fn record_truth(
    s: &Scenario,
    grid: FineGrid,
    channels: &[(Channel, Unit)],
    hysteretic: &Hysteretic,
) -> RecordTruth {
    let (n, dt) = (grid.n, grid.dt);
    let mut integrator = String::from(
        "fmu_shear::ShearModel, classical RK4 at the fine step, force linear between fine samples",
    );
    if !hysteretic.laws.is_empty() {
        integrator.push_str(
            "; with each hysteresis effect's Bouc–Wen z (and its work) in the same RK4 state, steps split where a storey's drift rate × z or a contact's gap changes sign",
        );
    }
    if !hysteretic.dampers.is_empty() {
        integrator.push_str(
            "; with each quadratic damper's force c₂·v|v| in the accelerations and its dissipated energy ∫ c₂|v|³ dt in the same RK4 state (smooth: no step splitting)",
        );
    }
    RecordTruth {
        columns: std::iter::once("time".to_owned())
            .chain(std::iter::once(s.excitation.input_name().to_owned()))
            .chain(channels.iter().map(|&(c, u)| header_field(c, u)))
            .collect(),
        samples: n,
        sample_rate: s.sample_rate,
        sample_interval: dt,
        first_time: 0.0,
        last_time: (n - 1) as f64 * dt,
        fine_step: grid.hf,
        oversample: s.oversample,
        integrator,
        initial_state: "at rest (zero displacements and velocities)".into(),
        sampling: "point samples of the force and of ÿ at each sample time (no anti-aliasing filter); 6-decimal times, 9 significant digits".into(),
    }
}

/// The structure's model and its parameters at the start and (after the changes) at the end.
fn structure_truth(s: &Scenario, model: &ShearModel) -> StructureTruth {
    let storeys = s.storeys();
    let base = s.excitation == Excitation::Base;
    StructureTruth {
        model: format!(
            "{storeys}-DOF shear frame of eq. (1){}: m = floor masses (kg), c = storey damping (N s/m), k = storey stiffness (N/m)",
            if base {
                " under ground acceleration, in coordinates relative to the ground (accelerometers read the absolute acceleration)"
            } else {
                ""
            }
        ),
        excitation: (s.excitation != Excitation::default()).then(|| s.excitation.name()),
        m: s.mass.clone(),
        c: s.damping.clone(),
        k: s.stiffness.clone(),
        final_m: model.params.mass.clone(),
        final_c: model.params.damping.clone(),
        final_k: model.params.stiffness.clone(),
    }
}

/// Each effect's truth: what the fine grid saw of it, with a hysteresis effect's saturation,
/// largest |z| and work, and a quadratic damper's largest |u| and dissipated energy.
fn effect_truths(s: &Scenario, run: &Integrated) -> Vec<EffectTruth> {
    let hysteretic = &run.hysteretic;
    s.effects
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let mut truth = run.stats.effect_truth(i, e);
            if let Some(h) = hysteretic.laws.iter().position(|law| law.effect == i) {
                truth.z_saturation = Some(hysteretic.laws[h].saturation());
                truth.max_abs_z = Some(hysteretic.max_abs_z[h]);
                truth.hysteretic_work = Some(hysteretic.work[h]);
            }
            if let Some(d) = hysteretic.dampers.iter().position(|d| d.effect == i) {
                truth.max_drift_or_velocity = hysteretic.max_abs_velocity[d];
                truth.dissipated_energy = Some(hysteretic.dissipated[d]);
            }
            truth
        })
        .collect()
}

/// The force (or ground acceleration): how it was made, its band and windows, and its RMS
/// over the record and inside each window's plateau.
fn force_truth(
    s: &Scenario,
    grid: FineGrid,
    bins: usize,
    levels: &NoiseLevels,
    clean_force: &[f64],
) -> ForceTruth {
    let (n, dt) = (grid.n, grid.dt);
    let period = n as f64 / s.sample_rate;
    let rms_in_windows = s
        .force
        .windows
        .iter()
        .map(|w| {
            let inside: Vec<f64> = (0..n)
                .filter(|&k| {
                    let t = k as f64 * dt;
                    t >= w.start + 0.5 * w.ramp && t <= w.end - 0.5 * w.ramp
                })
                .map(|k| clean_force[k])
                .collect();
            (!inside.is_empty()).then(|| rms(&inside))
        })
        .collect();
    ForceTruth {
        kind: if s.excitation == Excitation::Base {
            format!(
                "ground acceleration (m/s²): white Gaussian noise, FFT band mask × Kanai–Tajimi gain (f_g {} Hz, ζ_g {}), scaled to rms_requested when stationary, × Jennings–Housner–Tsai envelope (rise to {} s, strong to {} s, decay {} /s)",
                s.ground.soil_hz, s.ground.soil_damping, s.ground.rise_end, s.ground.strong_end, s.ground.decay
            )
        } else {
            "white Gaussian noise × amplitude envelope, FFT band mask, periodic over the record"
                .into()
        },
        rms_requested: s.force.rms,
        rms_record: levels.force_rms,
        band_hz: [s.force.low_hz, s.band_hz()],
        frequency_resolution: 1.0 / period,
        bins,
        windows: s.force.windows.clone(),
        rms_in_windows,
    }
}
