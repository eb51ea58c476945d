//! `twin synth`: the synthetic physical twin. It makes measurement records of a simulated
//! three-storey shear frame — any set of effects from the shear FMU's library (and one kind the
//! library deliberately lacks, Bouc–Wen hysteresis, for hidden-effect tests), parameter changes
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
//!      "beta": 0.5, "gamma": 0.5, "exponent": 2}
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
//! * `changes`: `parameter` one of `m1..m3`, `c1..c3`, `k1..k3`; either `factor` (multiplies the
//!   value in force at that time) or `value`; `at` in s, inside the record. Changes apply in time
//!   order.
//!
//! The truth JSON's `scenario` member is the scenario with every default filled in; given back as
//! `--scenario`, it makes the same record.
//!
//! # Flags
//!
//! Flags override the scenario's values and extend its lists: `--seed 3 --force-rms 1.2
//! --force-window 13:17:3[:RAMP] --effect contact@2-3[:gap=5e-4,stiffness=9000,side=both]
//! --effect cubic@2:stiffness=5e9 --effect friction@1:force=0.2
//! --effect hysteresis@2:stiffness=1500,yield=3e-4 --change k2@8:0.85` (factor) or
//! `--change k2@8=3500` (value), `--mass/--damping/--stiffness A,B,C`, `--noise-fraction`,
//! `--noise-sd`, `--force-noise-fraction`, `--band-hz`, `--low-hz`,
//! `--force-between-samples band-limited|linear`, `--duration`,
//! `--sample-rate`, `--oversample`.
//!
//! # Library
//!
//! [`synth_record`] makes a record in-process from a [`Scenario`]: the [`Measurement`] exactly as
//! the written CSV reads back, the noise-free accelerations and the fine-grid force (and the
//! hysteresis states, if any), and the [`Truth`].

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use fmu_shear::effects::contact::{SIDE_NEGATIVE, SIDE_POSITIVE};
use fmu_shear::effects::{
    add_storey_force, drift, Contact, Cubic, Effects, Floors, Friction, Kind, Law, Side,
};
use fmu_shear::{ShearModel, ShearParameters};
use numerics::ode::rk4_with_events;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Serialize;
use serde_json::{json, Map, Value};

use crate::cli::write_atomically;
use crate::data::Measurement;

pub const DEFAULT_SAMPLE_RATE: f64 = 51.2;
pub const DEFAULT_DURATION: f64 = 20.0;
pub const DEFAULT_OVERSAMPLE: u32 = 64;
/// The RMS of `data/dataset1.csv`'s force is 0.2495 N (dataset2: 0.2505 N).
pub const DEFAULT_FORCE_RMS: f64 = 0.25;
pub const DEFAULT_NOISE_FRACTION: f64 = 0.03;
pub const DEFAULT_WINDOW_RAMP: f64 = 0.5;
/// The structure `data/dataset1.csv` suggests: the MAP of `twin calibrate` on it (NMSE 0.05 /
/// 0.10 / 0.06 %), rounded. The reference paper's Table 1 MAP for its dataset one (m = {4.908,
/// 5.577, 5.187}, c = {3.307, 0.002, 0}, k = {4051, 4320, 4964}) has the same k/m ratios but far
/// less damping, and misses this project's dataset1 (NMSE > 100 %).
pub const DEFAULT_MASS: [f64; 3] = [4.637, 5.284, 4.920];
pub const DEFAULT_DAMPING: [f64; 3] = [8.14, 3.65, 2.56];
pub const DEFAULT_STIFFNESS: [f64; 3] = [3850.0, 4100.0, 4681.0];
/// White-noise points per sample interval on which the force is generated.
pub const GENERATOR_OVERSAMPLE: usize = 8;
/// Defaults of the `hysteresis` effect (Bouc–Wen): k_h N/m, z_y m, β, γ, n.
pub const DEFAULT_HYSTERESIS_STIFFNESS: f64 = 1000.0;
pub const DEFAULT_HYSTERESIS_YIELD: f64 = 5e-4;
pub const DEFAULT_HYSTERESIS_BETA: f64 = 0.5;
pub const DEFAULT_HYSTERESIS_GAMMA: f64 = 0.5;
pub const DEFAULT_HYSTERESIS_EXPONENT: f64 = 2.0;
/// Fine steps in one record at most (memory and time guard).
const MAX_FINE_POINTS: usize = 1 << 26;
const MAX_OVERSAMPLE: u32 = 100_000;
const FORCE_STREAM: u64 = 1;
const NOISE_STREAM: u64 = 2;

// ---------------------------------------------------------------------------------------------
// The scenario
// ---------------------------------------------------------------------------------------------

/// Everything that defines a synthetic record. [`Scenario::default`] is a gentle, linear record
/// like `data/dataset1.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    pub seed: u64,
    pub duration: f64,
    pub sample_rate: f64,
    pub oversample: u32,
    pub mass: [f64; 3],
    pub damping: [f64; 3],
    pub stiffness: [f64; 3],
    pub force: ForceSpec,
    pub noise: NoiseSpec,
    pub effects: Vec<EffectSpec>,
    pub changes: Vec<Change>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct ForceSpec {
    /// RMS at envelope 1, N.
    pub rms: f64,
    /// Upper band edge, Hz; `None` = half the sample rate.
    pub band_hz: Option<f64>,
    pub low_hz: f64,
    /// What the structure sees between the sample times.
    pub between_samples: BetweenSamples,
    pub windows: Vec<ForceWindow>,
}

/// The force between the sample times. The written samples are the same either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BetweenSamples {
    /// The band-limited signal itself (a physical force: smooth between samples).
    #[default]
    BandLimited,
    /// Linear between the sample values: exactly what a twin with first-order input hold at the
    /// sample rate (the shear FMU driven by the record) assumes, so its linear model fits the
    /// noise-free record to rounding. Use it when the force's representation must not count as
    /// model error (the examples in `data/` fit a first-order hold that well).
    Linear,
}

impl BetweenSamples {
    pub fn name(self) -> &'static str {
        match self {
            BetweenSamples::BandLimited => "band-limited",
            BetweenSamples::Linear => "linear",
        }
    }
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "band-limited" => Some(BetweenSamples::BandLimited),
            "linear" => Some(BetweenSamples::Linear),
            _ => None,
        }
    }
}

/// The force amplitude is multiplied by `gain` between `start` and `end` (s), with raised-cosine
/// ramps of `ramp` seconds centred on both edges.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ForceWindow {
    pub start: f64,
    pub end: f64,
    pub gain: f64,
    pub ramp: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum NoiseLevel {
    /// Of each floor's noise-free response RMS.
    Fraction([f64; 3]),
    /// Absolute, m/s².
    Sd([f64; 3]),
}

#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSpec {
    pub level: NoiseLevel,
    pub force_fraction: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum EffectSpec {
    /// Gap contact across the storey between floors `lower` and `lower + 1` (0 = the ground).
    Contact {
        lower: usize,
        gap: f64,
        stiffness: f64,
        side: i32,
    },
    /// Cubic stiffness of storey `storey` (1..3; storey 1 is ground–floor 1).
    Cubic { storey: usize, stiffness: f64 },
    /// Coulomb friction on floor `floor` (1..3).
    Friction {
        floor: usize,
        force: f64,
        velocity_scale: f64,
    },
    /// Bouc–Wen hysteresis of storey `storey` (1..3), **not** in the FMU's library:
    /// `ż = δ̇ (1 − (β sign(δ̇ z) + γ) |z / z_y|ⁿ)`, storey force `k_h z` (see the module docs).
    Hysteresis {
        storey: usize,
        /// k_h, N/m.
        stiffness: f64,
        /// z_y, m (the JSON's `yield`).
        yield_drift: f64,
        beta: f64,
        gamma: f64,
        /// n.
        exponent: f64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    Mass,
    Damping,
    Stiffness,
}

/// A structural parameter: `m1..m3`, `c1..c3`, `k1..k3`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamName {
    pub kind: ParamKind,
    /// 0-based floor (mass) or storey (damping, stiffness).
    pub index: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ChangeHow {
    Factor(f64),
    Value(f64),
}

/// A step change of a structural parameter at time `at`.
#[derive(Clone, Debug, PartialEq)]
pub struct Change {
    pub at: f64,
    pub parameter: ParamName,
    pub how: ChangeHow,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            seed: 0,
            duration: DEFAULT_DURATION,
            sample_rate: DEFAULT_SAMPLE_RATE,
            oversample: DEFAULT_OVERSAMPLE,
            mass: DEFAULT_MASS,
            damping: DEFAULT_DAMPING,
            stiffness: DEFAULT_STIFFNESS,
            force: ForceSpec::default(),
            noise: NoiseSpec::default(),
            effects: Vec::new(),
            changes: Vec::new(),
        }
    }
}

impl Default for ForceSpec {
    fn default() -> Self {
        ForceSpec {
            rms: DEFAULT_FORCE_RMS,
            band_hz: None,
            between_samples: BetweenSamples::Linear,
            low_hz: 0.0,
            windows: Vec::new(),
        }
    }
}

impl Default for NoiseSpec {
    fn default() -> Self {
        NoiseSpec {
            level: NoiseLevel::Fraction([DEFAULT_NOISE_FRACTION; 3]),
            force_fraction: 0.0,
        }
    }
}

impl NoiseSpec {
    /// No noise at all.
    pub fn none() -> Self {
        NoiseSpec {
            level: NoiseLevel::Fraction([0.0; 3]),
            force_fraction: 0.0,
        }
    }
}

impl ParamName {
    pub fn parse(text: &str) -> Option<ParamName> {
        let mut chars = text.chars();
        let kind = match chars.next()? {
            'm' => ParamKind::Mass,
            'c' => ParamKind::Damping,
            'k' => ParamKind::Stiffness,
            _ => return None,
        };
        let index = match chars.as_str() {
            "1" => 0,
            "2" => 1,
            "3" => 2,
            _ => return None,
        };
        Some(ParamName { kind, index })
    }
    pub fn name(&self) -> String {
        let letter = match self.kind {
            ParamKind::Mass => 'm',
            ParamKind::Damping => 'c',
            ParamKind::Stiffness => 'k',
        };
        format!("{letter}{}", self.index + 1)
    }
    fn slot<'a>(&self, p: &'a mut ShearParameters) -> &'a mut f64 {
        match self.kind {
            ParamKind::Mass => &mut p.mass[self.index],
            ParamKind::Damping => &mut p.damping[self.index],
            ParamKind::Stiffness => &mut p.stiffness[self.index],
        }
    }
}

impl EffectSpec {
    /// The effect as the shear FMU's library describes it: its kind, 0-based location and force
    /// law. `None` for hysteresis, which the library lacks.
    pub fn library(&self) -> Option<(Kind, usize, Law)> {
        let law = match *self {
            EffectSpec::Contact {
                gap,
                stiffness,
                side,
                ..
            } => Law::Contact(Contact {
                gap,
                stiffness,
                side,
            }),
            EffectSpec::Cubic { stiffness, .. } => Law::Cubic(Cubic { stiffness }),
            EffectSpec::Friction {
                force,
                velocity_scale,
                ..
            } => Law::Friction(Friction {
                force,
                velocity_scale,
            }),
            EffectSpec::Hysteresis { .. } => return None,
        };
        Some((law.kind(), self.library_location(), law))
    }
    /// A library effect at a 0-based location (`lower` floor of a contact, storey − 1, floor − 1).
    pub fn from_library(location: usize, law: Law) -> EffectSpec {
        match law {
            Law::Contact(c) => EffectSpec::Contact {
                lower: location,
                gap: c.gap,
                stiffness: c.stiffness,
                side: c.side,
            },
            Law::Cubic(c) => EffectSpec::Cubic {
                storey: location + 1,
                stiffness: c.stiffness,
            },
            Law::Friction(f) => EffectSpec::Friction {
                floor: location + 1,
                force: f.force,
                velocity_scale: f.velocity_scale,
            },
        }
    }
    pub fn kind(&self) -> &'static str {
        match self.library() {
            Some((kind, ..)) => kind.name(),
            None => "hysteresis",
        }
    }
    /// Whether the shear FMU's effect library has this kind (hysteresis: no).
    pub fn in_library(&self) -> bool {
        !matches!(self, EffectSpec::Hysteresis { .. })
    }
    /// The parameters by their JSON names (the library's parameter names; contact's side by
    /// name).
    fn parameters_json(&self) -> Map<String, Value> {
        let mut o = Map::new();
        match (self.library(), self) {
            (Some((kind, _, law)), _) => {
                for (p, x) in kind.real_params().iter().zip(law.reals()) {
                    o.insert(p.suffix.into(), json!(x));
                }
                if let Law::Contact(c) = law {
                    o.insert("side".into(), json!(side_name(c.side)));
                }
            }
            (
                None,
                &EffectSpec::Hysteresis {
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                    ..
                },
            ) => {
                for (key, x) in [
                    ("stiffness", stiffness),
                    ("yield", yield_drift),
                    ("beta", beta),
                    ("gamma", gamma),
                    ("exponent", exponent),
                ] {
                    o.insert(key.into(), json!(x));
                }
            }
            (None, _) => {}
        }
        o
    }
    /// 0-based location in the FMU's effect library (for hysteresis, which the library lacks,
    /// the 0-based storey).
    pub fn library_location(&self) -> usize {
        match *self {
            EffectSpec::Contact { lower, .. } => lower,
            EffectSpec::Cubic { storey, .. } => storey - 1,
            EffectSpec::Friction { floor, .. } => floor - 1,
            EffectSpec::Hysteresis { storey, .. } => storey - 1,
        }
    }
    /// The location as the scenario writes it.
    pub fn location(&self) -> Vec<usize> {
        match *self {
            EffectSpec::Contact { lower, .. } => vec![lower, lower + 1],
            EffectSpec::Cubic { storey, .. } => vec![storey],
            EffectSpec::Friction { floor, .. } => vec![floor],
            EffectSpec::Hysteresis { storey, .. } => vec![storey],
        }
    }
    /// Where, in words: "between floors 2 and 3", "of storey 2 (floors 1–2)", "on floor 1".
    pub fn describe_location(&self) -> String {
        let storey = |lower: usize| {
            if lower == 0 {
                "between the ground and floor 1".to_string()
            } else {
                format!("between floors {} and {}", lower, lower + 1)
            }
        };
        match *self {
            EffectSpec::Contact { lower, .. } => storey(lower),
            EffectSpec::Cubic { storey: s, .. } | EffectSpec::Hysteresis { storey: s, .. } => {
                format!("of storey {s} ({})", storey(s - 1))
            }
            EffectSpec::Friction { floor, .. } => format!("on floor {floor}"),
        }
    }
    /// The FMU variables' prefix, e.g. `contact23`, `cubic2`, `friction1`. Hysteresis is not in
    /// the library: its `hysteresis2` names no FMU variable (see [`EffectSpec::in_library`]).
    pub fn fmu_prefix(&self) -> String {
        match self.library() {
            Some((kind, location, _)) => kind.prefix(location),
            None => format!("hysteresis{}", self.library_location() + 1),
        }
    }
    fn to_json(&self) -> Value {
        let mut o = Map::new();
        o.insert("kind".into(), json!(self.kind()));
        o.insert("location".into(), json!(self.location()));
        o.extend(self.parameters_json());
        Value::Object(o)
    }
}

fn side_name(side: i32) -> &'static str {
    Side::from_code(side).unwrap_or(Side::Both).name()
}

impl Change {
    fn to_json(&self) -> Value {
        let mut v = json!({"at": self.at, "parameter": self.parameter.name()});
        match self.how {
            ChangeHow::Factor(f) => v["factor"] = json!(f),
            ChangeHow::Value(x) => v["value"] = json!(x),
        }
        v
    }
}

impl Scenario {
    /// Number of samples in the record: `round(duration · sample_rate)`.
    pub fn samples(&self) -> usize {
        let n = (self.duration * self.sample_rate).round();
        if n.is_finite() && n >= 0.0 {
            if n < 1e15 {
                n as usize
            } else {
                usize::MAX
            }
        } else {
            0
        }
    }
    pub fn dt(&self) -> f64 {
        1.0 / self.sample_rate
    }
    /// The force's upper band edge, Hz.
    pub fn band_hz(&self) -> f64 {
        self.force.band_hz.unwrap_or(0.5 * self.sample_rate)
    }

    /// Read and check a scenario file. Errors name the file and the field.
    pub fn load(path: &Path) -> Result<Scenario> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{origin}: cannot read the scenario"))?;
        let value: Value =
            serde_json::from_str(&text).map_err(|e| anyhow!("{origin}: not valid JSON: {e}"))?;
        let scenario = Scenario::from_json(&value, &origin)?;
        scenario.validate(&origin)?;
        Ok(scenario)
    }

    /// The scenario in a JSON value (types and names checked; ranges are [`Scenario::validate`]'s).
    pub fn from_json(value: &Value, origin: &str) -> Result<Scenario> {
        let at = Loc {
            origin,
            path: String::new(),
        };
        let obj = at.object(value)?;
        at.known_keys(
            obj,
            &[
                "seed",
                "duration",
                "sample_rate",
                "oversample",
                "parameters",
                "force",
                "noise",
                "effects",
                "changes",
            ],
        )?;
        let mut s = Scenario::default();
        if let Some(v) = obj.get("seed") {
            s.seed = at.field("seed").u64(v)?;
        }
        if let Some(v) = obj.get("duration") {
            s.duration = at.field("duration").number(v)?;
        }
        if let Some(v) = obj.get("sample_rate") {
            s.sample_rate = at.field("sample_rate").number(v)?;
        }
        if let Some(v) = obj.get("oversample") {
            let o = at.field("oversample").u64(v)?;
            s.oversample = u32::try_from(o)
                .map_err(|_| at.field("oversample").error(format!("{o} is too large")))?;
        }
        if let Some(v) = obj.get("parameters") {
            let at = at.field("parameters");
            let p = at.object(v)?;
            at.known_keys(p, &["m", "c", "k"])?;
            if let Some(v) = p.get("m") {
                s.mass = at.field("m").three(v, false)?;
            }
            if let Some(v) = p.get("c") {
                s.damping = at.field("c").three(v, false)?;
            }
            if let Some(v) = p.get("k") {
                s.stiffness = at.field("k").three(v, false)?;
            }
        }
        if let Some(v) = obj.get("force") {
            let at = at.field("force");
            let f = at.object(v)?;
            at.known_keys(
                f,
                &["rms", "band_hz", "low_hz", "between_samples", "windows"],
            )?;
            if let Some(v) = f.get("rms") {
                s.force.rms = at.field("rms").number(v)?;
            }
            if let Some(v) = f.get("band_hz") {
                s.force.band_hz = Some(at.field("band_hz").number(v)?);
            }
            if let Some(v) = f.get("low_hz") {
                s.force.low_hz = at.field("low_hz").number(v)?;
            }
            if let Some(v) = f.get("between_samples") {
                let at = at.field("between_samples");
                let name = at.string(v)?;
                s.force.between_samples = BetweenSamples::parse(name).ok_or_else(|| {
                    at.error(format!("{name:?} is not \"band-limited\" or \"linear\""))
                })?;
            }
            if let Some(v) = f.get("windows") {
                let at = at.field("windows");
                for (i, w) in at.array(v)?.iter().enumerate() {
                    let at = at.index(i);
                    let o = at.object(w)?;
                    at.known_keys(o, &["start", "end", "gain", "ramp"])?;
                    let ramp = match o.get("ramp") {
                        Some(v) => at.field("ramp").number(v)?,
                        None => DEFAULT_WINDOW_RAMP,
                    };
                    s.force.windows.push(ForceWindow {
                        start: at.field("start").number(at.required(o, "start")?)?,
                        end: at.field("end").number(at.required(o, "end")?)?,
                        gain: at.field("gain").number(at.required(o, "gain")?)?,
                        ramp,
                    });
                }
            }
        }
        if let Some(v) = obj.get("noise") {
            let at = at.field("noise");
            let n = at.object(v)?;
            at.known_keys(n, &["fraction", "sd", "force_fraction"])?;
            match (n.get("fraction"), n.get("sd")) {
                (Some(_), Some(_)) => {
                    return Err(at.error("give either `fraction` or `sd`, not both".into()))
                }
                (Some(v), None) => {
                    s.noise.level = NoiseLevel::Fraction(at.field("fraction").three(v, true)?)
                }
                (None, Some(v)) => s.noise.level = NoiseLevel::Sd(at.field("sd").three(v, true)?),
                (None, None) => {}
            }
            if let Some(v) = n.get("force_fraction") {
                s.noise.force_fraction = at.field("force_fraction").number(v)?;
            }
        }
        if let Some(v) = obj.get("effects") {
            let at = at.field("effects");
            for (i, e) in at.array(v)?.iter().enumerate() {
                s.effects.push(parse_effect(&at.index(i), e)?);
            }
        }
        if let Some(v) = obj.get("changes") {
            let at = at.field("changes");
            for (i, c) in at.array(v)?.iter().enumerate() {
                let at = at.index(i);
                let o = at.object(c)?;
                at.known_keys(o, &["at", "parameter", "factor", "value"])?;
                let time = at.field("at").number(at.required(o, "at")?)?;
                let name_at = at.field("parameter");
                let name = name_at.string(at.required(o, "parameter")?)?;
                let parameter = ParamName::parse(name).ok_or_else(|| {
                    name_at.error(format!(
                        "unknown parameter {name:?}; expected m1..m3, c1..c3 or k1..k3"
                    ))
                })?;
                let how = match (o.get("factor"), o.get("value")) {
                    (Some(v), None) => ChangeHow::Factor(at.field("factor").number(v)?),
                    (None, Some(v)) => ChangeHow::Value(at.field("value").number(v)?),
                    _ => return Err(at.error("give exactly one of `factor` and `value`".into())),
                };
                s.changes.push(Change {
                    at: time,
                    parameter,
                    how,
                });
            }
        }
        Ok(s)
    }

    /// The scenario as JSON, every default filled in: [`Scenario::from_json`] reads it back equal.
    pub fn to_json(&self) -> Value {
        let noise = match &self.noise.level {
            NoiseLevel::Fraction(f) => {
                json!({"fraction": f, "force_fraction": self.noise.force_fraction})
            }
            NoiseLevel::Sd(sd) => json!({"sd": sd, "force_fraction": self.noise.force_fraction}),
        };
        json!({
            "seed": self.seed,
            "duration": self.duration,
            "sample_rate": self.sample_rate,
            "oversample": self.oversample,
            "parameters": {"m": self.mass, "c": self.damping, "k": self.stiffness},
            "force": {
                "rms": self.force.rms,
                "band_hz": self.band_hz(),
                "low_hz": self.force.low_hz,
                "between_samples": self.force.between_samples.name(),
                "windows": self.force.windows,
            },
            "noise": noise,
            "effects": self.effects.iter().map(EffectSpec::to_json).collect::<Vec<_>>(),
            "changes": self.changes.iter().map(Change::to_json).collect::<Vec<_>>(),
        })
    }

    /// Check the ranges; `origin` names the source (a file, or "scenario") in the errors.
    pub fn validate(&self, origin: &str) -> Result<()> {
        let at = Loc {
            origin,
            path: String::new(),
        };
        let positive = |loc: Loc, x: f64, strictly: bool| -> Result<()> {
            let ok = x.is_finite() && if strictly { x > 0.0 } else { x >= 0.0 };
            if ok {
                Ok(())
            } else {
                Err(loc.error(format!(
                    "{x} must be a finite number {} 0",
                    if strictly { ">" } else { "≥" }
                )))
            }
        };
        positive(at.field("sample_rate"), self.sample_rate, true)?;
        positive(at.field("duration"), self.duration, true)?;
        if !(1..=MAX_OVERSAMPLE).contains(&self.oversample) {
            return Err(at.field("oversample").error(format!(
                "{} is outside [1, {MAX_OVERSAMPLE}]",
                self.oversample
            )));
        }
        let n = self.samples();
        if n < 2 {
            return Err(at.field("duration").error(format!(
                "{} s at {} Hz gives {n} samples; at least 2 are needed",
                self.duration, self.sample_rate
            )));
        }
        if n.saturating_mul(GENERATOR_OVERSAMPLE) > MAX_FINE_POINTS {
            return Err(at.field("duration").error(format!(
                "{:?} s at {:?} Hz is too long a record (at most {} samples)",
                self.duration,
                self.sample_rate,
                MAX_FINE_POINTS / GENERATOR_OVERSAMPLE
            )));
        }
        if n.saturating_mul(self.oversample as usize) > MAX_FINE_POINTS {
            return Err(at.field("oversample").error(format!(
                "{n} samples × {} fine steps is more than the {MAX_FINE_POINTS} fine points allowed",
                self.oversample
            )));
        }
        let p = at.field("parameters");
        for i in 0..3 {
            positive(p.field("m").index(i), self.mass[i], true)?;
            positive(p.field("c").index(i), self.damping[i], false)?;
            positive(p.field("k").index(i), self.stiffness[i], false)?;
        }
        let f = at.field("force");
        positive(f.field("rms"), self.force.rms, false)?;
        positive(f.field("low_hz"), self.force.low_hz, false)?;
        let band = self.band_hz();
        let nyquist = 0.5 * self.sample_rate;
        positive(f.field("band_hz"), band, true)?;
        if band > nyquist * (1.0 + 1e-12) {
            return Err(f.field("band_hz").error(format!(
                "{band} Hz is above the Nyquist frequency {nyquist} Hz of the {} Hz sampling",
                self.sample_rate
            )));
        }
        let record = n as f64 / self.sample_rate;
        let bins = (1..=n * GENERATOR_OVERSAMPLE / 2)
            .filter(|&k| in_band(k as f64 / record, self.force.low_hz, band))
            .count();
        if bins == 0 {
            return Err(f.error(format!(
                "no frequency of the {record} s record (resolution {} Hz) lies strictly between low_hz {} and band_hz {band}",
                1.0 / record,
                self.force.low_hz
            )));
        }
        for (i, w) in self.force.windows.iter().enumerate() {
            let at = f.field("windows").index(i);
            for (name, x) in [
                ("start", w.start),
                ("end", w.end),
                ("gain", w.gain),
                ("ramp", w.ramp),
            ] {
                if !x.is_finite() {
                    return Err(at.field(name).error(format!("{x} is not a finite number")));
                }
            }
            if w.end <= w.start {
                return Err(at
                    .field("end")
                    .error(format!("{} must be after start {}", w.end, w.start)));
            }
            positive(at.field("gain"), w.gain, false)?;
            positive(at.field("ramp"), w.ramp, false)?;
            if w.ramp > w.end - w.start {
                return Err(at.field("ramp").error(format!(
                    "{} s is longer than the window ({} s); the ramps are centred on its edges",
                    w.ramp,
                    w.end - w.start
                )));
            }
        }
        let noise = at.field("noise");
        let (name, levels) = match &self.noise.level {
            NoiseLevel::Fraction(x) => ("fraction", x),
            NoiseLevel::Sd(x) => ("sd", x),
        };
        for (i, &x) in levels.iter().enumerate() {
            positive(noise.field(name).index(i), x, false)?;
        }
        positive(
            noise.field("force_fraction"),
            self.noise.force_fraction,
            false,
        )?;
        for (i, e) in self.effects.iter().enumerate() {
            let at = at.field("effects").index(i);
            match *e {
                EffectSpec::Contact { lower, side, .. } => {
                    if lower > 2 {
                        return Err(at.field("location").error(format!(
                            "[{lower}, {}] is not a storey; expected [0, 1], [1, 2] or [2, 3]",
                            lower + 1
                        )));
                    }
                    if Side::from_code(side).is_none() {
                        return Err(at.field("side").error(format!("{side} is not -1, 0 or 1")));
                    }
                }
                EffectSpec::Cubic { storey, .. } => {
                    if !(1..=3).contains(&storey) {
                        return Err(at
                            .field("location")
                            .error(format!("storey {storey} is not 1, 2 or 3")));
                    }
                }
                EffectSpec::Friction { floor, .. } => {
                    if !(1..=3).contains(&floor) {
                        return Err(at
                            .field("location")
                            .error(format!("floor {floor} is not 1, 2 or 3")));
                    }
                }
                EffectSpec::Hysteresis {
                    storey,
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                } => {
                    if !(1..=3).contains(&storey) {
                        return Err(at
                            .field("location")
                            .error(format!("storey {storey} is not 1, 2 or 3")));
                    }
                    positive(at.field("stiffness"), stiffness, true)?;
                    positive(at.field("yield"), yield_drift, true)?;
                    for (name, x) in [("beta", beta), ("gamma", gamma)] {
                        if !x.is_finite() {
                            return Err(at
                                .field(name)
                                .error(format!("{x} is not a finite number")));
                        }
                    }
                    if beta + gamma <= 0.0 {
                        return Err(at.field("gamma").error(format!(
                            "beta + gamma = {beta} + {gamma} must be > 0 (|z| saturates at yield · (1/(beta + gamma))^(1/exponent))"
                        )));
                    }
                    if !(exponent.is_finite() && exponent >= 1.0) {
                        return Err(at
                            .field("exponent")
                            .error(format!("{exponent} must be a finite number ≥ 1")));
                    }
                }
            }
            // A library effect's parameters: the ranges the FMU accepts.
            if let Some((kind, _, law)) = e.library() {
                for (p, x) in kind.real_params().iter().zip(law.reals()) {
                    let at = at.field(p.suffix);
                    if p.min == 0.0 {
                        positive(at, x, p.strictly)?;
                    } else if !x.is_finite() {
                        return Err(at.error(format!("{x} is not a finite number")));
                    } else if x < p.min || (p.strictly && x == p.min) {
                        return Err(at.error(format!(
                            "{x} must be {} {}",
                            if p.strictly { ">" } else { "≥" },
                            p.min
                        )));
                    }
                }
            }
            if let Some(j) = self.effects[..i]
                .iter()
                .position(|o| o.kind() == e.kind() && o.library_location() == e.library_location())
            {
                return Err(at.error(format!(
                    "{} {} is already given as effects[{j}]; one effect of a kind per location",
                    e.kind(),
                    e.describe_location()
                )));
            }
        }
        let last = (n - 1) as f64 / self.sample_rate;
        for (i, c) in self.changes.iter().enumerate() {
            let at = at.field("changes").index(i);
            if !(c.at.is_finite() && c.at >= 0.0 && c.at <= last) {
                return Err(at
                    .field("at")
                    .error(format!("{} s is outside the record [0, {last}] s", c.at)));
            }
            let strictly = c.parameter.kind == ParamKind::Mass;
            match c.how {
                ChangeHow::Factor(x) => positive(at.field("factor"), x, strictly)?,
                ChangeHow::Value(x) => positive(at.field("value"), x, strictly)?,
            }
        }
        Ok(())
    }
}

fn in_band(f: f64, low: f64, band: f64) -> bool {
    f > low && f < band
}

fn parse_effect(at: &Loc, value: &Value) -> Result<EffectSpec> {
    let o = at.object(value)?;
    let kind_at = at.field("kind");
    let kind = kind_at.string(at.required(o, "kind")?)?;
    let location: Vec<u64> = {
        let loc = at.field("location");
        let v = at.required(o, "location")?;
        match v {
            Value::Array(items) => items
                .iter()
                .enumerate()
                .map(|(i, x)| loc.index(i).u64(x))
                .collect::<Result<_>>()?,
            Value::Number(_) => vec![loc.u64(v)?],
            other => {
                return Err(loc.error(format!(
                    "expected a list of floor numbers, found {}",
                    shown(other)
                )))
            }
        }
    };
    let loc = at.field("location");
    let number_or = |key: &str, default: f64| -> Result<f64> {
        match o.get(key) {
            Some(v) => at.field(key).number(v),
            None => Ok(default),
        }
    };
    let small = |x: u64| usize::try_from(x).unwrap_or(usize::MAX);
    let storey_or_adjacent = |location: &[u64]| match location[..] {
        [s] if (1..=3).contains(&s) => Ok(small(s)),
        [a, b] if b == a + 1 && b <= 3 => Ok(small(b)),
        _ => Err(loc.error(format!(
            "{location:?} is not a storey; expected [1], [2] or [3] (storey 1 = ground–floor 1) or two adjacent floors"
        ))),
    };
    // The library's kinds: their parameters, defaults and side come from its description.
    if let Some(library_kind) = Kind::parse(kind) {
        let mut known = vec!["kind", "location"];
        known.extend(library_kind.real_params().iter().map(|p| p.suffix));
        if library_kind.has_side() {
            known.push("side");
        }
        at.known_keys(o, &known)?;
        // 0-based, as the library counts.
        let location = match library_kind {
            Kind::Contact => match location[..] {
                [a, b] if b == a + 1 && b <= 3 => small(a),
                _ => return Err(loc.error(format!(
                    "{location:?} is not a storey; expected two adjacent floors [lower, upper] with 0 = the ground: [0, 1], [1, 2] or [2, 3]"
                ))),
            },
            Kind::Cubic => storey_or_adjacent(&location)? - 1,
            Kind::Friction => match location[..] {
                [f] if (1..=3).contains(&f) => small(f) - 1,
                _ => {
                    return Err(loc.error(format!(
                        "{location:?} is not a floor; expected [1], [2] or [3]"
                    )))
                }
            },
        };
        let side = match o.get("side") {
            None => Side::Both,
            Some(Value::String(s)) => match s.as_str() {
                "both" => Side::Both,
                "positive" => Side::Positive,
                "negative" => Side::Negative,
                _ => {
                    return Err(at.field("side").error(format!(
                        "{s:?} is not \"both\", \"positive\" or \"negative\""
                    )))
                }
            },
            Some(v @ Value::Number(_)) => {
                match v.as_i64().and_then(|x| i32::try_from(x).ok()).and_then(Side::from_code) {
                    Some(side) => side,
                    None => return Err(at.field("side").error(format!("{v} is not -1, 0 or 1"))),
                }
            }
            Some(other) => {
                return Err(at.field("side").error(format!(
                    "expected \"both\", \"positive\" or \"negative\", found {}",
                    shown(other)
                )))
            }
        };
        let reals = library_kind
            .real_params()
            .iter()
            .map(|p| number_or(p.suffix, p.start))
            .collect::<Result<Vec<f64>>>()?;
        let law = Law::new(library_kind, &reals, side)
            .ok_or_else(|| at.error(format!("too few parameters for {kind}")))?;
        return Ok(EffectSpec::from_library(location, law));
    }
    match kind {
        "hysteresis" => {
            at.known_keys(
                o,
                &[
                    "kind",
                    "location",
                    "stiffness",
                    "yield",
                    "beta",
                    "gamma",
                    "exponent",
                ],
            )?;
            let storey = storey_or_adjacent(&location)?;
            Ok(EffectSpec::Hysteresis {
                storey,
                stiffness: number_or("stiffness", DEFAULT_HYSTERESIS_STIFFNESS)?,
                yield_drift: number_or("yield", DEFAULT_HYSTERESIS_YIELD)?,
                beta: number_or("beta", DEFAULT_HYSTERESIS_BETA)?,
                gamma: number_or("gamma", DEFAULT_HYSTERESIS_GAMMA)?,
                exponent: number_or("exponent", DEFAULT_HYSTERESIS_EXPONENT)?,
            })
        }
        other => Err(kind_at.error(format!(
            "unknown effect kind {other:?}; expected \"contact\", \"cubic\", \"friction\" or \"hysteresis\""
        ))),
    }
}

/// Where a value sits: the file and the field path, for error messages.
#[derive(Clone)]
struct Loc<'a> {
    origin: &'a str,
    path: String,
}

fn shown(v: &Value) -> String {
    let kind = match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    };
    let mut text = v.to_string();
    if text.len() > 40 {
        let mut cut = 37;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        text.truncate(cut);
        text.push_str("...");
    }
    format!("{kind} ({text})")
}

impl<'a> Loc<'a> {
    fn field(&self, name: &str) -> Loc<'a> {
        let path = if self.path.is_empty() {
            name.to_string()
        } else {
            format!("{}.{name}", self.path)
        };
        Loc {
            origin: self.origin,
            path,
        }
    }
    fn index(&self, i: usize) -> Loc<'a> {
        Loc {
            origin: self.origin,
            path: format!("{}[{i}]", self.path),
        }
    }
    fn error(&self, message: String) -> anyhow::Error {
        if self.path.is_empty() {
            anyhow!("{}: {message}", self.origin)
        } else {
            anyhow!("{}: field `{}`: {message}", self.origin, self.path)
        }
    }
    fn object<'v>(&self, v: &'v Value) -> Result<&'v Map<String, Value>> {
        v.as_object()
            .ok_or_else(|| self.error(format!("expected an object, found {}", shown(v))))
    }
    fn array<'v>(&self, v: &'v Value) -> Result<&'v Vec<Value>> {
        v.as_array()
            .ok_or_else(|| self.error(format!("expected a list, found {}", shown(v))))
    }
    fn string<'v>(&self, v: &'v Value) -> Result<&'v str> {
        v.as_str()
            .ok_or_else(|| self.error(format!("expected a string, found {}", shown(v))))
    }
    fn number(&self, v: &Value) -> Result<f64> {
        match v.as_f64() {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(self.error(format!("expected a number, found {}", shown(v)))),
        }
    }
    fn u64(&self, v: &Value) -> Result<u64> {
        if let Some(x) = v.as_u64() {
            return Ok(x);
        }
        match v.as_f64() {
            Some(x) if x >= 0.0 && x.fract() == 0.0 && x < 2f64.powi(53) => Ok(x as u64),
            _ => Err(self.error(format!(
                "expected a non-negative whole number, found {}",
                shown(v)
            ))),
        }
    }
    /// Three numbers; with `scalar`, a single number stands for all three.
    fn three(&self, v: &Value, scalar: bool) -> Result<[f64; 3]> {
        match v {
            Value::Number(_) if scalar => Ok([self.number(v)?; 3]),
            Value::Array(items) if items.len() == 3 => Ok([
                self.index(0).number(&items[0])?,
                self.index(1).number(&items[1])?,
                self.index(2).number(&items[2])?,
            ]),
            _ => Err(self.error(format!(
                "expected {}a list of 3 numbers (floors/storeys 1..3), found {}",
                if scalar { "a number or " } else { "" },
                shown(v)
            ))),
        }
    }
    fn required<'v>(&self, o: &'v Map<String, Value>, key: &str) -> Result<&'v Value> {
        o.get(key)
            .ok_or_else(|| self.field(key).error("is missing".into()))
    }
    fn known_keys(&self, o: &Map<String, Value>, known: &[&str]) -> Result<()> {
        for key in o.keys() {
            if !known.contains(&key.as_str()) {
                return Err(self.field(key).error(format!(
                    "unknown field; expected one of {}",
                    known.join(", ")
                )));
            }
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Making a record
// ---------------------------------------------------------------------------------------------

/// A synthetic record.
#[derive(Debug, Clone)]
pub struct SynthRecord {
    /// Exactly what the CSV holds and [`Measurement::read`] gives back (`path` = `<synthetic>`
    /// until written).
    pub measurement: Measurement,
    /// The accelerations before noise and rounding, at the sample times.
    pub clean_acc: [Vec<f64>; 3],
    /// The force before noise and rounding, at the sample times.
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
    /// 1..3.
    pub storey: usize,
    /// The hysteretic variable z, m (the storey force is `k_h · z`).
    pub z: Vec<f64>,
    /// The storey drift δ (upper floor minus lower), m.
    pub drift: Vec<f64>,
    /// `∫₀ᵗ k_h z dδ`, J, integrated with the structure on the fine grid.
    pub work: Vec<f64>,
}

/// How the record was made: the resolved scenario and what came out of it.
#[derive(Debug, Clone, Serialize)]
pub struct Truth {
    pub generator: String,
    /// The scenario with every default filled in (valid `--scenario` input).
    pub scenario: Value,
    pub record: RecordTruth,
    pub structure: StructureTruth,
    pub effects: Vec<EffectTruth>,
    pub changes: Vec<ChangeTruth>,
    pub force: ForceTruth,
    pub noise: NoiseTruth,
    pub response: ResponseTruth,
    pub random_numbers: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct RecordTruth {
    pub columns: Vec<String>,
    pub samples: usize,
    pub sample_rate: f64,
    pub sample_interval: f64,
    pub first_time: f64,
    pub last_time: f64,
    pub fine_step: f64,
    pub oversample: u32,
    pub integrator: String,
    pub initial_state: String,
    pub sampling: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct StructureTruth {
    pub model: String,
    /// Parameters at the start of the record.
    pub m: [f64; 3],
    pub c: [f64; 3],
    pub k: [f64; 3],
    /// Parameters at the end of the record (after every change).
    pub final_m: [f64; 3],
    pub final_c: [f64; 3],
    pub final_k: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct EffectTruth {
    pub kind: String,
    /// As the scenario writes it: `[lower, upper]` for contact, `[storey]` for cubic, `[floor]`
    /// for friction.
    pub location: Vec<usize>,
    /// The floors the effect acts between / on (0 = the ground).
    pub floors: Vec<usize>,
    pub description: String,
    /// The shear FMU's variable prefix, e.g. `contact23` (for an effect not in the library, as
    /// `hysteresis2`, no FMU variable has it).
    pub fmu_prefix: String,
    /// Whether the shear FMU's effect library has this kind (false for hysteresis).
    pub in_library: bool,
    /// 0-based location in the FMU's effect library (hysteresis: the 0-based storey).
    pub library_location: usize,
    pub parameters: Value,
    /// Contact only: closings of the gap (open → closed on the fine grid).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact_events: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_in_contact: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_contact: Option<f64>,
    /// Contact only: largest |drift| − gap while closed, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_penetration: Option<f64>,
    /// Largest |drift| (storey effects) or |velocity| (friction) over the record.
    pub max_drift_or_velocity: f64,
    /// Hysteresis only: the bound of |z|, `yield · (1/(beta + gamma))^(1/exponent)`, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub z_saturation: Option<f64>,
    /// Hysteresis only: largest |z| on the fine grid, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_abs_z: Option<f64>,
    /// Hysteresis only: `∫ k_h z dδ` over the record, J (dissipated, plus what z stores at the
    /// end).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hysteretic_work: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ChangeTruth {
    pub at: f64,
    pub parameter: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    pub before: f64,
    pub after: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ForceTruth {
    pub kind: String,
    pub rms_requested: f64,
    /// RMS of the force samples written (before noise).
    pub rms_record: f64,
    pub band_hz: [f64; 2],
    pub frequency_resolution: f64,
    pub bins: usize,
    pub windows: Vec<ForceWindow>,
    /// RMS of the force samples inside each window's plateau (between the ramps).
    pub rms_in_windows: Vec<Option<f64>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct NoiseTruth {
    pub kind: String,
    /// The sd added to acc1..acc3, m/s².
    pub acc_sd: [f64; 3],
    pub force_sd: f64,
    /// The noise-free accelerations' RMS, m/s².
    pub response_rms: [f64; 3],
}

#[derive(Debug, Clone, Serialize)]
pub struct ResponseTruth {
    /// Largest |inter-storey drift| of storeys 1..3 on the fine grid, m.
    pub max_abs_drift: [f64; 3],
    pub max_abs_displacement: [f64; 3],
    pub max_abs_acceleration: [f64; 3],
}

impl Truth {
    pub fn to_json(&self) -> Value {
        serde_json::to_value(self).unwrap_or(Value::Null)
    }
}

/// The force on the fine grid (`samples · oversample` points over one period of the record):
/// see the module documentation. Also returns the number of frequency bins used.
pub fn band_limited_force(s: &Scenario) -> Result<(Vec<f64>, usize)> {
    s.validate("scenario")?;
    let n = s.samples();
    let period = n as f64 / s.sample_rate;
    let ng = n * GENERATOR_OVERSAMPLE;
    let hg = period / ng as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(FORCE_STREAM);
    let envelope: Vec<f64> = (0..ng)
        .map(|j| envelope(&s.force.windows, j as f64 * hg))
        .collect();
    let mut spectrum: Vec<Complex<f64>> = envelope
        .iter()
        .map(|e| {
            let w: f64 = StandardNormal.sample(&mut rng);
            Complex::new(w * e, 0.0)
        })
        .collect();
    let mut planner = FftPlanner::<f64>::new();
    planner.plan_fft_forward(ng).process(&mut spectrum);
    let (low, band) = (s.force.low_hz, s.band_hz());
    let keep: Vec<usize> = (1..=ng / 2)
        .filter(|&k| in_band(k as f64 / period, low, band))
        .collect();
    // The band-limited signal on the generator grid, for the scale.
    let mut z = vec![Complex::new(0.0, 0.0); ng];
    for &k in &keep {
        z[k] = spectrum[k];
        if k != ng - k {
            z[ng - k] = spectrum[ng - k];
        }
    }
    planner.plan_fft_inverse(ng).process(&mut z);
    let power: f64 = z.iter().map(|c| (c.re / ng as f64).powi(2)).sum();
    let envelope_power: f64 = envelope.iter().map(|e| e * e).sum();
    if !(power > 0.0 && envelope_power > 0.0) {
        bail!("the force has no power: check force.windows' gains");
    }
    let scale = s.force.rms / (power / envelope_power).sqrt();
    // The same trigonometric polynomial on the fine grid.
    let nf = n * s.oversample as usize;
    let mut fine = vec![Complex::new(0.0, 0.0); nf];
    for &k in &keep {
        // k < nf / 2 because band ≤ sample_rate / 2 and the band edge is excluded.
        fine[k] = spectrum[k];
        fine[nf - k] = spectrum[ng - k];
    }
    planner.plan_fft_inverse(nf).process(&mut fine);
    let norm = scale / ng as f64;
    let mut fine: Vec<f64> = fine.iter().map(|c| c.re * norm).collect();
    if s.force.between_samples == BetweenSamples::Linear {
        let os = s.oversample as usize;
        for k in 0..n {
            let (a, b) = (fine[k * os], fine[((k + 1) % n) * os]);
            for i in 1..os {
                fine[k * os + i] = a + (b - a) * (i as f64 / os as f64);
            }
        }
    }
    Ok((fine, keep.len()))
}

/// The amplitude envelope at time `t`.
pub fn envelope(windows: &[ForceWindow], t: f64) -> f64 {
    windows
        .iter()
        .map(|w| 1.0 + (w.gain - 1.0) * window_shape(w, t))
        .product()
}

/// 0 outside the window, 1 inside, raised-cosine ramps centred on the edges.
fn window_shape(w: &ForceWindow, t: f64) -> f64 {
    let edge = |t0: f64, rising: bool| -> f64 {
        // 0 before t0 − ramp/2, 1 after t0 + ramp/2.
        let x = if w.ramp > 0.0 {
            ((t - (t0 - 0.5 * w.ramp)) / w.ramp).clamp(0.0, 1.0)
        } else if t >= t0 {
            1.0
        } else {
            0.0
        };
        let up = 0.5 - 0.5 * (std::f64::consts::PI * x).cos();
        if rising {
            up
        } else {
            1.0 - up
        }
    };
    edge(w.start, true).min(edge(w.end, false))
}

/// Make a record: see the module documentation.
pub fn synth_record(s: &Scenario) -> Result<(SynthRecord, Truth)> {
    s.validate("scenario")?;
    let n = s.samples();
    let os = s.oversample as usize;
    let dt = s.dt();
    let hf = dt / os as f64;
    let (fine_force, bins) = band_limited_force(s)?;

    // The structure.
    let mut effects = Effects::default();
    for e in &s.effects {
        // Hysteresis is not in the library: integrated here, beside the model (see `Hysteretic`).
        if let Some((_, location, law)) = e.library() {
            effects.switch_on(location, law);
        }
    }
    let hysteretic = Hysteretic::new(&s.effects);
    let params = ShearParameters {
        mass: s.mass,
        damping: s.damping,
        stiffness: s.stiffness,
        substeps: 1,
    };
    let mut model = ShearModel::new(params, effects);

    // Changes in time order (stable: equal times keep the scenario's order).
    let mut changes: Vec<&Change> = s.changes.iter().collect();
    changes.sort_by(|a, b| a.at.total_cmp(&b.at));
    let mut change_truth = Vec::new();
    let mut next_change = 0;
    let mut apply = |model: &mut ShearModel, c: &Change| {
        let slot = c.parameter.slot(&mut model.params);
        let before = *slot;
        *slot = match c.how {
            ChangeHow::Factor(f) => before * f,
            ChangeHow::Value(x) => x,
        };
        change_truth.push(ChangeTruth {
            at: c.at,
            parameter: c.parameter.name(),
            factor: match c.how {
                ChangeHow::Factor(f) => Some(f),
                ChangeHow::Value(_) => None,
            },
            before,
            after: *slot,
        });
    };

    let mut stats = Stats::new(&s.effects);
    let mut clean_acc = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    let mut clean_force = vec![0.0; n];
    let mut hysteretic = hysteretic;
    let mut traces: Vec<HysteresisTrace> = hysteretic
        .laws
        .iter()
        .map(|law| HysteresisTrace {
            effect: law.effect,
            storey: law.storey + 1,
            z: Vec::with_capacity(n),
            drift: Vec::with_capacity(n),
            work: Vec::with_capacity(n),
        })
        .collect();
    for k in 0..n {
        let j0 = k * os;
        while next_change < changes.len() && changes[next_change].at <= j0 as f64 * hf {
            apply(&mut model, changes[next_change]);
            next_change += 1;
        }
        let a = hysteretic.acceleration(&model, fine_force[j0]);
        for f in 0..3 {
            clean_acc[f][k] = a[f];
            stats.max_acc[f] = stats.max_acc[f].max(a[f].abs());
        }
        for (i, trace) in traces.iter_mut().enumerate() {
            trace.z.push(hysteretic.z[i]);
            trace
                .drift
                .push(drift(&model.displacement, trace.storey - 1));
            trace.work.push(hysteretic.work[i]);
        }
        clean_force[k] = fine_force[j0];
        if k + 1 == n {
            break;
        }
        for j in j0..j0 + os {
            let (t0, t1) = (j as f64 * hf, (j + 1) as f64 * hf);
            let next = if j + 1 < fine_force.len() {
                fine_force[j + 1]
            } else {
                fine_force[0]
            };
            model.force.value = fine_force[j];
            model.force.slope = (next - fine_force[j]) / hf;
            let mut t = t0;
            while next_change < changes.len() && changes[next_change].at <= t1 {
                let at = changes[next_change].at;
                if at > t {
                    hysteretic.advance(&mut model, at - t);
                    t = at;
                }
                apply(&mut model, changes[next_change]);
                next_change += 1;
            }
            if t1 > t {
                hysteretic.advance(&mut model, t1 - t);
            }
            let finite = model
                .displacement
                .iter()
                .chain(&model.velocity)
                .chain(&hysteretic.z)
                .all(|x| x.is_finite());
            if !finite {
                bail!(
                    "the synthetic structure diverged at t = {t1:.6} s (non-finite state); check the parameters and effects, or raise oversample (now {})",
                    s.oversample
                );
            }
            stats.observe(&model, t1, hf);
            hysteretic.observe();
        }
    }

    // Noise.
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    let response_rms = [rms(&clean_acc[0]), rms(&clean_acc[1]), rms(&clean_acc[2])];
    let acc_sd = match &s.noise.level {
        NoiseLevel::Fraction(f) => [
            f[0] * response_rms[0],
            f[1] * response_rms[1],
            f[2] * response_rms[2],
        ],
        NoiseLevel::Sd(sd) => *sd,
    };
    let force_rms = rms(&clean_force);
    let force_sd = s.noise.force_fraction * force_rms;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(NOISE_STREAM);
    let mut gauss = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut acc: [Vec<f64>; 3] = Default::default();
    for f in 0..3 {
        acc[f] = clean_acc[f]
            .iter()
            .map(|a| round9(a + acc_sd[f] * gauss()))
            .collect();
    }
    let force: Vec<f64> = clean_force
        .iter()
        .map(|x| round9(x + force_sd * gauss()))
        .collect();
    let time: Vec<f64> = (0..n).map(|k| round_time(k as f64 * dt)).collect();
    let measurement = Measurement {
        path: PathBuf::from("<synthetic>"),
        time,
        force,
        acc,
        dt,
        extra: HashMap::new(),
    };

    // The truth.
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
    let effects = s
        .effects
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let mut truth = stats.effect_truth(i, e);
            if let Some(h) = hysteretic.laws.iter().position(|law| law.effect == i) {
                truth.z_saturation = Some(hysteretic.laws[h].saturation());
                truth.max_abs_z = Some(hysteretic.max_abs_z[h]);
                truth.hysteretic_work = Some(hysteretic.work[h]);
            }
            truth
        })
        .collect();
    let mut integrator = String::from(
        "fmu_shear::ShearModel, classical RK4 at the fine step, force linear between fine samples",
    );
    if !hysteretic.laws.is_empty() {
        integrator.push_str(
            "; with each hysteresis effect's Bouc–Wen z (and its work) in the same RK4 state, steps split where a storey's drift rate × z or a contact's gap changes sign",
        );
    }
    let truth = Truth {
        generator: format!("twin synth (shear-twin orchestrator {})", env!("CARGO_PKG_VERSION")),
        scenario: s.to_json(),
        record: RecordTruth {
            columns: crate::data::REQUIRED_COLUMNS.iter().map(|c| c.to_string()).collect(),
            samples: n,
            sample_rate: s.sample_rate,
            sample_interval: dt,
            first_time: 0.0,
            last_time: (n - 1) as f64 * dt,
            fine_step: hf,
            oversample: s.oversample,
            integrator,
            initial_state: "at rest (zero displacements and velocities)".into(),
            sampling: "point samples of the force and of ÿ at each sample time (no anti-aliasing filter); 6-decimal times, 9 significant digits".into(),
        },
        structure: StructureTruth {
            model: "3-DOF shear frame of eq. (1): m = floor masses (kg), c = storey damping (N s/m), k = storey stiffness (N/m)".into(),
            m: s.mass,
            c: s.damping,
            k: s.stiffness,
            final_m: model.params.mass,
            final_c: model.params.damping,
            final_k: model.params.stiffness,
        },
        effects,
        changes: change_truth,
        force: ForceTruth {
            kind: "white Gaussian noise × amplitude envelope, FFT band mask, periodic over the record".into(),
            rms_requested: s.force.rms,
            rms_record: force_rms,
            band_hz: [s.force.low_hz, s.band_hz()],
            frequency_resolution: 1.0 / period,
            bins,
            windows: s.force.windows.clone(),
            rms_in_windows,
        },
        noise: NoiseTruth {
            kind: match s.noise.level {
                NoiseLevel::Fraction(_) => "Gaussian, sd = fraction × the floor's noise-free RMS".into(),
                NoiseLevel::Sd(_) => "Gaussian, absolute sd".into(),
            },
            acc_sd,
            force_sd,
            response_rms,
        },
        response: ResponseTruth {
            max_abs_drift: stats.max_drift,
            max_abs_displacement: stats.max_disp,
            max_abs_acceleration: stats.max_acc,
        },
        random_numbers: format!(
            "rand_chacha ChaCha8Rng::seed_from_u64({}), stream {FORCE_STREAM} force, stream {NOISE_STREAM} noise; rand_distr StandardNormal",
            s.seed
        ),
    };
    let record = SynthRecord {
        measurement,
        clean_acc,
        clean_force,
        fine_force,
        fine_step: hf,
        hysteresis: traces,
    };
    Ok((record, truth))
}

// ---------------------------------------------------------------------------------------------
// Hysteresis (Bouc–Wen): not in the FMU's library, integrated here beside the model
// ---------------------------------------------------------------------------------------------

/// One storey's Bouc–Wen law (see the module documentation).
#[derive(Clone, Copy, Debug)]
struct BoucWen {
    /// Index in the scenario's effects.
    effect: usize,
    /// 0-based storey (0 = ground–floor 1).
    storey: usize,
    stiffness: f64,
    yield_drift: f64,
    beta: f64,
    gamma: f64,
    exponent: f64,
}

impl BoucWen {
    /// `ż = δ̇ (1 − (β sign(δ̇ z) + γ) |z / z_y|ⁿ)`.
    #[inline]
    fn z_rate(&self, drift_rate: f64, z: f64) -> f64 {
        let product = drift_rate * z;
        let sign = if product > 0.0 {
            1.0
        } else if product < 0.0 {
            -1.0
        } else {
            0.0
        };
        let ratio = (z / self.yield_drift).abs();
        let power = if self.exponent == 2.0 {
            ratio * ratio
        } else {
            ratio.powf(self.exponent)
        };
        drift_rate * (1.0 - (self.beta * sign + self.gamma) * power)
    }
    /// The bound of |z|: `z_y (1 / (β + γ))^(1/n)`.
    fn saturation(&self) -> f64 {
        self.yield_drift * (1.0 / (self.beta + self.gamma)).powf(1.0 / self.exponent)
    }
}

/// At most one hysteresis effect per storey (validation refuses two at one storey).
const MAX_LAWS: usize = 3;
/// The state with hysteresis: `[y1..y3, ẏ1..ẏ3, z per law, ∫ k_h z dδ per law]`.
type HState = [f64; 6 + 2 * MAX_LAWS];
const Z0: usize = 6;
const W0: usize = 6 + MAX_LAWS;

/// The hysteresis effects' states, and the structure's steps with them. Without hysteresis it
/// steps the model by [`ShearModel::advance`], exactly as before it existed.
struct Hysteretic {
    laws: Vec<BoucWen>,
    z: [f64; MAX_LAWS],
    work: [f64; MAX_LAWS],
    max_abs_z: [f64; MAX_LAWS],
}

impl Hysteretic {
    fn new(effects: &[EffectSpec]) -> Self {
        let laws = effects
            .iter()
            .enumerate()
            .filter_map(|(effect, e)| match *e {
                EffectSpec::Hysteresis {
                    storey,
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                } => Some(BoucWen {
                    effect,
                    storey: storey - 1,
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                }),
                _ => None,
            })
            .take(MAX_LAWS)
            .collect();
        Hysteretic {
            laws,
            z: [0.0; MAX_LAWS],
            work: [0.0; MAX_LAWS],
            max_abs_z: [0.0; MAX_LAWS],
        }
    }

    /// Subtract the hysteretic storey forces `k_h z` from the accelerations `a`.
    #[inline]
    fn add_to(&self, model: &ShearModel, z: &[f64], a: &mut Floors) {
        let mut g = [0.0; 3];
        for (law, &z) in self.laws.iter().zip(z) {
            add_storey_force(law.storey, law.stiffness * z, &mut g);
        }
        for f in 0..3 {
            a[f] -= g[f] / model.params.mass[f];
        }
    }

    /// The floor accelerations of the model's state and these z.
    fn acceleration(&self, model: &ShearModel, input: f64) -> Floors {
        let mut a = model.acceleration(&model.displacement, &model.velocity, input);
        if !self.laws.is_empty() {
            self.add_to(model, &self.z, &mut a);
        }
        a
    }

    #[inline]
    fn rhs(&self, model: &ShearModel, x: &HState, input: f64) -> HState {
        let y = [x[0], x[1], x[2]];
        let v = [x[3], x[4], x[5]];
        let mut a = model.acceleration(&y, &v, input);
        self.add_to(model, &x[Z0..Z0 + self.laws.len()], &mut a);
        let mut dx = [0.0; 6 + 2 * MAX_LAWS];
        dx[..3].copy_from_slice(&v);
        dx[3..6].copy_from_slice(&a);
        for (i, law) in self.laws.iter().enumerate() {
            let z = x[Z0 + i];
            let rate = drift(&v, law.storey);
            dx[Z0 + i] = law.z_rate(rate, z);
            dx[W0 + i] = law.stiffness * z * rate;
        }
        dx
    }

    /// Where the vector field has kinks: the contacts' gaps and each law's `δ̇ z`.
    fn switches(&self, model: &ShearModel, x: &HState) -> ([f64; 6 + MAX_LAWS], usize) {
        let contact = model.effects.switches(&[x[0], x[1], x[2]]);
        let mut out = [0.0; 6 + MAX_LAWS];
        out[..contact.len].copy_from_slice(&contact.values[..contact.len]);
        let mut len = contact.len;
        for (i, law) in self.laws.iter().enumerate() {
            out[len] = drift(&[x[3], x[4], x[5]], law.storey) * x[Z0 + i];
            len += 1;
        }
        (out, len)
    }

    /// RK4 over `[0, h]` with the input `u0 + slope·τ`, `substeps` sub-steps, each split just
    /// past every sign change of a switch (numerics' stepper, as the shear FMU's contact steps).
    fn step(&self, model: &ShearModel, x: &HState, u0: f64, slope: f64, h: f64) -> HState {
        rk4_with_events(
            |tau: f64, x: &HState| self.rhs(model, x, u0 + slope * tau),
            |x: &HState| {
                let (values, len) = self.switches(model, x);
                SwitchList { values, len }
            },
            x,
            h,
            model.params.substeps,
        )
    }

    /// [`ShearModel::advance`] with the hysteresis: the same inputs, the same end-of-step
    /// bookkeeping (the input ends at its ramp's end value, slope 0).
    fn advance(&mut self, model: &mut ShearModel, h: f64) {
        if self.laws.is_empty() {
            model.advance(h);
            return;
        }
        let u0 = model.force.value - model.control_force.value;
        let slope = model.force.slope - model.control_force.slope;
        let mut x = [0.0; 6 + 2 * MAX_LAWS];
        x[..3].copy_from_slice(&model.displacement);
        x[3..6].copy_from_slice(&model.velocity);
        x[Z0..W0].copy_from_slice(&self.z);
        x[W0..].copy_from_slice(&self.work);
        let x = self.step(model, &x, u0, slope, h);
        model.displacement = [x[0], x[1], x[2]];
        model.velocity = [x[3], x[4], x[5]];
        self.z.copy_from_slice(&x[Z0..W0]);
        self.work.copy_from_slice(&x[W0..]);
        for input in [&mut model.force, &mut model.control_force] {
            input.value += input.slope * h;
            input.slope = 0.0;
        }
    }

    fn observe(&mut self) {
        for i in 0..self.laws.len() {
            self.max_abs_z[i] = self.max_abs_z[i].max(self.z[i].abs());
        }
    }
}

/// The switch values of [`Hysteretic::switches`], as numerics' stepper reads them.
struct SwitchList {
    values: [f64; 6 + MAX_LAWS],
    len: usize,
}

impl AsRef<[f64]> for SwitchList {
    fn as_ref(&self) -> &[f64] {
        &self.values[..self.len]
    }
}

/// What the fine grid saw: drifts, contacts.
struct Stats {
    max_drift: [f64; 3],
    max_disp: [f64; 3],
    max_vel: [f64; 3],
    max_acc: [f64; 3],
    contacts: Vec<ContactStats>,
}

#[derive(Default, Clone)]
struct ContactStats {
    /// Index in the scenario's effects, storey, gap, side.
    effect: usize,
    storey: usize,
    gap: f64,
    side: i32,
    closed: bool,
    events: usize,
    time: f64,
    first: Option<f64>,
    max_penetration: f64,
}

impl Stats {
    fn new(effects: &[EffectSpec]) -> Self {
        let contacts = effects
            .iter()
            .enumerate()
            .filter_map(|(i, e)| match *e {
                EffectSpec::Contact {
                    lower, gap, side, ..
                } => Some(ContactStats {
                    effect: i,
                    storey: lower,
                    gap,
                    side,
                    ..ContactStats::default()
                }),
                _ => None,
            })
            .collect();
        Stats {
            max_drift: [0.0; 3],
            max_disp: [0.0; 3],
            max_vel: [0.0; 3],
            max_acc: [0.0; 3],
            contacts,
        }
    }

    fn observe(&mut self, model: &ShearModel, t: f64, h: f64) {
        let y = &model.displacement;
        for i in 0..3 {
            self.max_drift[i] = self.max_drift[i].max(drift(y, i).abs());
            self.max_disp[i] = self.max_disp[i].max(y[i].abs());
            self.max_vel[i] = self.max_vel[i].max(model.velocity[i].abs());
        }
        for c in &mut self.contacts {
            let d = drift(y, c.storey);
            let penetration = match c.side {
                SIDE_POSITIVE => d - c.gap,
                SIDE_NEGATIVE => -d - c.gap,
                _ => d.abs() - c.gap,
            };
            let closed = penetration > 0.0;
            if closed {
                if !c.closed {
                    c.events += 1;
                    c.first.get_or_insert(t);
                }
                c.time += h;
                c.max_penetration = c.max_penetration.max(penetration);
            }
            c.closed = closed;
        }
    }

    fn effect_truth(&self, i: usize, e: &EffectSpec) -> EffectTruth {
        let (floors, max) = match *e {
            EffectSpec::Contact { lower, .. } => (vec![lower, lower + 1], self.max_drift[lower]),
            EffectSpec::Cubic { storey, .. } | EffectSpec::Hysteresis { storey, .. } => {
                (vec![storey - 1, storey], self.max_drift[storey - 1])
            }
            EffectSpec::Friction { floor, .. } => (vec![floor], self.max_vel[floor - 1]),
        };
        let mut parameters = e.parameters_json();
        if let EffectSpec::Contact { side, .. } = *e {
            parameters.insert("side_fmu".into(), json!(side));
        }
        let parameters = Value::Object(parameters);
        let contact = self.contacts.iter().find(|c| c.effect == i);
        EffectTruth {
            kind: e.kind().into(),
            location: e.location(),
            floors,
            description: format!("{} {}", e.kind(), e.describe_location()),
            fmu_prefix: e.fmu_prefix(),
            in_library: e.in_library(),
            library_location: e.library_location(),
            parameters,
            contact_events: contact.map(|c| c.events),
            time_in_contact: contact.map(|c| c.time),
            first_contact: contact.and_then(|c| c.first),
            max_penetration: contact.map(|c| c.max_penetration),
            max_drift_or_velocity: max,
            z_saturation: None,
            max_abs_z: None,
            hysteretic_work: None,
        }
    }
}

/// A value as the CSV writes it (9 significant digits), read back.
fn round9(x: f64) -> f64 {
    format_g9(x).parse().unwrap_or(x)
}

fn round_time(t: f64) -> f64 {
    format!("{t:.6}").parse().unwrap_or(t)
}

/// `%.9g`: 9 significant digits, trailing zeros removed, exponent form below 1e-4 or from 1e9.
pub fn format_g9(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return if x == 0.0 { "0".into() } else { format!("{x}") };
    }
    let e = format!("{x:.8e}");
    let (mantissa, exponent) = e.split_once('e').unwrap_or((&e, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if !(-4..9).contains(&exponent) {
        let sign = if exponent < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mantissa), exponent.abs())
    } else {
        let decimals = (8 - exponent) as usize;
        trim(&format!("{x:.decimals$}"))
    }
}

/// The record as CSV text: `time,force,acc1,acc2,acc3`.
pub fn csv_text(m: &Measurement) -> String {
    let mut text = String::with_capacity(64 * (m.len() + 1));
    text.push_str("time,force,acc1,acc2,acc3\n");
    for k in 0..m.len() {
        text.push_str(&format!(
            "{:.6},{},{},{},{}\n",
            m.time[k],
            format_g9(m.force[k]),
            format_g9(m.acc[0][k]),
            format_g9(m.acc[1][k]),
            format_g9(m.acc[2][k])
        ));
    }
    text
}

// ---------------------------------------------------------------------------------------------
// The command
// ---------------------------------------------------------------------------------------------

const AFTER_HELP: &str = "\
Scenario JSON (every field optional; see the orchestrator::synth documentation):
  {\"seed\": 7, \"duration\": 20.0, \"sample_rate\": 51.2, \"oversample\": 64,
   \"parameters\": {\"m\": [3], \"c\": [3], \"k\": [3]},
   \"force\": {\"rms\": 0.25, \"band_hz\": 25.6, \"low_hz\": 0, \"between_samples\": \"band-limited\" | \"linear\",
              \"windows\": [{\"start\": 13, \"end\": 17, \"gain\": 3, \"ramp\": 0.5}]},
   \"noise\": {\"fraction\": 0.03 | \"sd\": [3], \"force_fraction\": 0},
   \"effects\": [{\"kind\": \"contact\", \"location\": [2, 3], \"gap\": 5e-4, \"stiffness\": 9000, \"side\": \"both\"},
               {\"kind\": \"cubic\", \"location\": [2], \"stiffness\": 5e9},
               {\"kind\": \"friction\", \"location\": [1], \"force\": 0.2, \"velocity_scale\": 1e-3},
               {\"kind\": \"hysteresis\", \"location\": [2], \"stiffness\": 1000, \"yield\": 5e-4,
                \"beta\": 0.5, \"gamma\": 0.5, \"exponent\": 2}],
   \"changes\": [{\"at\": 8.0, \"parameter\": \"k2\", \"factor\": 0.85}]}
Locations: contact [lower, upper] floors (0 = ground); cubic and hysteresis [storey]
(1 = ground-floor 1); friction [floor]. Hysteresis (Bouc-Wen) is NOT in the shear FMU's
library. Flags override the scenario and extend its lists.";

#[derive(clap::Args, Debug, Default, Clone)]
#[command(after_help = AFTER_HELP)]
pub struct SynthArgs {
    /// Scenario JSON; flags override and extend it.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Measurement CSV to write: time,force,acc1,acc2,acc3.
    #[arg(long)]
    pub out: PathBuf,
    /// Truth JSON to write: everything about how the record was made.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Random seed (default 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Record length, s.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Hz.
    #[arg(long)]
    pub sample_rate: Option<f64>,
    /// Fine RK4 steps per sample interval.
    #[arg(long)]
    pub oversample: Option<u32>,
    /// Floor masses, kg.
    #[arg(long, value_name = "M1,M2,M3")]
    pub mass: Option<String>,
    /// Storey damping, N s/m.
    #[arg(long, value_name = "C1,C2,C3")]
    pub damping: Option<String>,
    /// Storey stiffness, N/m.
    #[arg(long, value_name = "K1,K2,K3")]
    pub stiffness: Option<String>,
    /// Force RMS at envelope 1, N.
    #[arg(long)]
    pub force_rms: Option<f64>,
    /// Upper band edge of the force, Hz.
    #[arg(long)]
    pub band_hz: Option<f64>,
    /// Lower band edge of the force, Hz.
    #[arg(long)]
    pub low_hz: Option<f64>,
    /// The force the structure sees between samples: band-limited (default) or linear.
    #[arg(long, value_name = "band-limited|linear")]
    pub force_between_samples: Option<String>,
    /// Amplitude window: ×GAIN between START and END s (repeatable).
    #[arg(long = "force-window", value_name = "START:END:GAIN[:RAMP]")]
    pub force_windows: Vec<String>,
    /// Sensor noise sd as a fraction of each floor's response RMS.
    #[arg(long)]
    pub noise_fraction: Option<f64>,
    /// Sensor noise sd, m/s², every floor.
    #[arg(long)]
    pub noise_sd: Option<f64>,
    /// Noise on the force, fraction of its RMS.
    #[arg(long)]
    pub force_noise_fraction: Option<f64>,
    /// Effect (repeatable): contact@2-3[:gap=5e-4,stiffness=9000,side=both], cubic@2[:stiffness=5e9],
    /// friction@1[:force=0.2,velocity_scale=1e-3],
    /// hysteresis@2[:stiffness=1000,yield=5e-4,beta=0.5,gamma=0.5,exponent=2] (not in the FMU).
    #[arg(long = "effect", value_name = "KIND@LOCATION[:KEY=VALUE,...]")]
    pub effects: Vec<String>,
    /// Parameter change (repeatable): k2@8:0.85 (factor) or k2@8=3500 (value).
    #[arg(long = "change", value_name = "PARAM@TIME:FACTOR|PARAM@TIME=VALUE")]
    pub changes: Vec<String>,
}

impl SynthArgs {
    /// The scenario: the file's (or the default), then the flags.
    pub fn scenario(&self) -> Result<Scenario> {
        let (mut s, origin) = match &self.scenario {
            Some(path) => (Scenario::load(path)?, path.display().to_string()),
            None => (Scenario::default(), "scenario".to_string()),
        };
        let number = |flag: &str, text: &str| -> Result<f64> {
            match text.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(anyhow!(
                    "--{flag} {text:?}: {:?} is not a finite number",
                    text.trim()
                )),
            }
        };
        let three = |flag: &str, text: &str| -> Result<[f64; 3]> {
            let parts: Vec<&str> = text.split(',').collect();
            if parts.len() != 3 {
                bail!("--{flag} {text:?}: expected three comma-separated numbers");
            }
            Ok([
                number(flag, parts[0])?,
                number(flag, parts[1])?,
                number(flag, parts[2])?,
            ])
        };
        if let Some(x) = self.seed {
            s.seed = x;
        }
        if let Some(x) = self.duration {
            s.duration = x;
        }
        if let Some(x) = self.sample_rate {
            s.sample_rate = x;
        }
        if let Some(x) = self.oversample {
            s.oversample = x;
        }
        if let Some(t) = &self.mass {
            s.mass = three("mass", t)?;
        }
        if let Some(t) = &self.damping {
            s.damping = three("damping", t)?;
        }
        if let Some(t) = &self.stiffness {
            s.stiffness = three("stiffness", t)?;
        }
        if let Some(x) = self.force_rms {
            s.force.rms = x;
        }
        if let Some(x) = self.band_hz {
            s.force.band_hz = Some(x);
        }
        if let Some(x) = self.low_hz {
            s.force.low_hz = x;
        }
        if let Some(x) = &self.force_between_samples {
            s.force.between_samples = BetweenSamples::parse(x).ok_or_else(|| {
                anyhow!("--force-between-samples {x:?}: expected band-limited or linear")
            })?;
        }
        for w in &self.force_windows {
            let parts: Vec<&str> = w.split(':').collect();
            if !(3..=4).contains(&parts.len()) {
                bail!("--force-window {w:?}: expected START:END:GAIN or START:END:GAIN:RAMP");
            }
            s.force.windows.push(ForceWindow {
                start: number("force-window", parts[0])?,
                end: number("force-window", parts[1])?,
                gain: number("force-window", parts[2])?,
                ramp: if parts.len() == 4 {
                    number("force-window", parts[3])?
                } else {
                    DEFAULT_WINDOW_RAMP
                },
            });
        }
        match (self.noise_fraction, self.noise_sd) {
            (Some(_), Some(_)) => bail!("give either --noise-fraction or --noise-sd, not both"),
            (Some(f), None) => s.noise.level = NoiseLevel::Fraction([f; 3]),
            (None, Some(sd)) => s.noise.level = NoiseLevel::Sd([sd; 3]),
            (None, None) => {}
        }
        if let Some(x) = self.force_noise_fraction {
            s.noise.force_fraction = x;
        }
        for e in &self.effects {
            s.effects.push(parse_effect_flag(e)?);
        }
        for c in &self.changes {
            s.changes.push(parse_change_flag(c)?);
        }
        let origin = if self.scenario.is_some() {
            format!("{origin} (with the command-line flags)")
        } else {
            "the command-line flags".into()
        };
        s.validate(&origin)?;
        Ok(s)
    }
}

/// `contact@2-3:gap=5e-4,stiffness=9000,side=both`, `cubic@2`, `friction@1:force=0.2`,
/// `hysteresis@2:stiffness=1500,yield=3e-4`.
pub fn parse_effect_flag(text: &str) -> Result<EffectSpec> {
    let bad = |why: String| anyhow!("--effect {text:?}: {why}");
    let (head, params) = match text.split_once(':') {
        Some((h, p)) => (h, Some(p)),
        None => (text, None),
    };
    let (kind, location) = head
        .split_once('@')
        .ok_or_else(|| bad("expected KIND@LOCATION, e.g. contact@2-3".into()))?;
    let floors: Vec<Value> = location
        .split('-')
        .map(|p| {
            p.trim()
                .parse::<u64>()
                .map(Value::from)
                .map_err(|_| bad(format!("location {location:?} is not N or N-M")))
        })
        .collect::<Result<_>>()?;
    let mut o = Map::new();
    o.insert("kind".into(), Value::from(kind.trim()));
    o.insert("location".into(), Value::Array(floors));
    for pair in params
        .into_iter()
        .flat_map(|p| p.split(','))
        .filter(|p| !p.trim().is_empty())
    {
        let (key, value) = pair
            .split_once('=')
            .ok_or_else(|| bad(format!("{pair:?} is not KEY=VALUE")))?;
        let (key, value) = (key.trim(), value.trim());
        let v = match value.parse::<f64>() {
            Ok(x) if x.is_finite() => Value::from(x),
            _ if key == "side" => Value::from(value),
            _ => return Err(bad(format!("{key}={value:?}: not a finite number"))),
        };
        o.insert(key.into(), v);
    }
    let origin = format!("--effect {text:?}");
    parse_effect(
        &Loc {
            origin: &origin,
            path: String::new(),
        },
        &Value::Object(o),
    )
}

/// `k2@8:0.85` (factor) or `k2@8=3500` (value).
pub fn parse_change_flag(text: &str) -> Result<Change> {
    let bad = |why: String| anyhow!("--change {text:?}: {why}");
    let (name, rest) = text
        .split_once('@')
        .ok_or_else(|| bad("expected PARAM@TIME:FACTOR or PARAM@TIME=VALUE".into()))?;
    let parameter = ParamName::parse(name.trim()).ok_or_else(|| {
        bad(format!(
            "unknown parameter {name:?}; expected m1..m3, c1..c3 or k1..k3"
        ))
    })?;
    let (time, how) = if let Some((t, f)) = rest.split_once(':') {
        (t, f.trim().parse::<f64>().map(ChangeHow::Factor))
    } else if let Some((t, v)) = rest.split_once('=') {
        (t, v.trim().parse::<f64>().map(ChangeHow::Value))
    } else {
        return Err(bad("expected PARAM@TIME:FACTOR or PARAM@TIME=VALUE".into()));
    };
    let at = time
        .trim()
        .parse::<f64>()
        .map_err(|_| bad(format!("time {time:?} is not a number")))?;
    let how = how.map_err(|_| bad("the factor or value is not a number".into()))?;
    Ok(Change { at, parameter, how })
}

pub fn synth_command(args: &SynthArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let scenario = args.scenario()?;
    let (record, truth) = synth_record(&scenario)?;
    let elapsed = started.elapsed();
    // Everything is computed before anything is written.
    let text = csv_text(&record.measurement);
    write_atomically(&args.out, |f| {
        f.write_all(text.as_bytes())?;
        Ok(())
    })?;
    if let Some(path) = &args.truth {
        let json = serde_json::to_string_pretty(&truth).context("serialising the truth")?;
        write_atomically(path, |f| {
            f.write_all(json.as_bytes())?;
            f.write_all(b"\n")?;
            Ok(())
        })?;
    }
    println!(
        "wrote {} ({} samples at {} Hz, seed {}, force RMS {:.4} N, made in {:.0} ms)",
        args.out.display(),
        truth.record.samples,
        scenario.sample_rate,
        scenario.seed,
        truth.force.rms_record,
        elapsed.as_secs_f64() * 1e3
    );
    for e in &truth.effects {
        match e.contact_events {
            Some(events) => println!(
                "  {} (gap {} m): {events} contact events, {:.3} s in contact",
                e.description,
                e.parameters["gap"],
                e.time_in_contact.unwrap_or(0.0)
            ),
            None => match (e.max_abs_z, e.z_saturation) {
                (Some(z), Some(bound)) => println!(
                    "  {} (not in the FMU's library): max |z| {z:.3e} m of {bound:.3e} m, work ∫k·z dδ {:.3e} J",
                    e.description,
                    e.hysteretic_work.unwrap_or(0.0)
                ),
                _ => println!("  {}", e.description),
            },
        }
    }
    for c in &truth.changes {
        println!("  {} {} → {} at {} s", c.parameter, c.before, c.after, c.at);
    }
    if let Some(path) = &args.truth {
        println!("wrote {}", path.display());
    }
    Ok(())
}
