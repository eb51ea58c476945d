//! The scenario: its types, defaults, JSON form and checks.

mod checks;
mod json;

use std::path::Path;

use super::{Result, SynthError};
use ::structure::channel::{Channel, Quantity, Unit};
use ::structure::effects::{Contact, Cubic, Friction, Kind, Law, Side};
use ::structure::paper::STOREYS as PAPER_STOREYS;
use ::structure::{Excitation, Structure, MAX_STOREYS};
use fmu_shear::ShearParameters;
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};

use super::{
    DEFAULT_DAMPING, DEFAULT_DURATION, DEFAULT_FORCE_RMS, DEFAULT_MASS, DEFAULT_NOISE_FRACTION,
    DEFAULT_OVERSAMPLE, DEFAULT_SAMPLE_RATE, DEFAULT_STIFFNESS,
};
pub use json::header_field;
pub(super) use json::{parse_effect, Loc};

/// Whether the frequency `f` lies strictly inside the force's band (`low`, `band`) Hz.
pub(super) fn in_band(f: f64, low: f64, band: f64) -> bool {
    f > low && f < band
}

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
    /// Floor masses (kg), storey damping (N s/m) and stiffness (N/m): N values each.
    pub mass: Vec<f64>,
    pub damping: Vec<f64>,
    pub stiffness: Vec<f64>,
    /// A force at a floor (the paper's shaker on floor 1 by default) or ground motion.
    pub excitation: Excitation,
    /// The excitation's signal: the force, or under ground motion the ground acceleration's
    /// level (`rms`, m/s²), band and windows.
    pub force: ForceSpec,
    /// The ground motion's spectrum and envelope (used under `excitation` = base).
    pub ground: GroundMotion,
    /// The response channels written, each in its unit (None: `acc1..accN` in m/s²).
    pub channels: Option<Vec<(Channel, Unit)>>,
    pub noise: NoiseSpec,
    pub effects: Vec<EffectSpec>,
    /// The library's effects (contact, cubic stiffness, friction) act from this time (s) on:
    /// the first sample at or after it; before, the structure is linear. 0: from the start.
    /// Hysteresis and quadratic dampers act throughout.
    pub effects_from: f64,
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
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

/// The sensor noise, per response channel (one value for all, or one per channel).
#[derive(Clone, Debug, PartialEq)]
pub enum NoiseLevel {
    /// Of each channel's noise-free RMS.
    Fraction(Vec<f64>),
    /// Absolute, in SI (m/s², m/s or m, as the channel measures).
    Sd(Vec<f64>),
}

impl NoiseLevel {
    /// The level of response channel `i` (a single value serves every channel).
    pub fn at(&self, i: usize) -> f64 {
        let v = match self {
            NoiseLevel::Fraction(v) | NoiseLevel::Sd(v) => v,
        };
        if v.len() == 1 {
            v[0]
        } else {
            v.get(i).copied().unwrap_or(0.0)
        }
    }
}

/// Ground motion (under `excitation` = base): Gaussian white noise shaped by the Kanai–Tajimi
/// filter of a soil layer, `|H(f)|² = (1 + 4ζ²(f/f_g)²) / ((1 − (f/f_g)²)² + 4ζ²(f/f_g)²)`,
/// inside the band (`force.low_hz`, `force.band_hz`), then modulated by the Jennings–Housner–
/// Tsai envelope: `(t/t₁)²` rising to 1 at `t₁`, 1 until `t₂`, then `exp(−decay·(t − t₂))`.
/// Scaled so that the stationary signal (envelope 1) has RMS `force.rms`, m/s².
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroundMotion {
    /// f_g, Hz (default 2.5: firm soil).
    pub soil_hz: f64,
    /// ζ_g (default 0.6).
    pub soil_damping: f64,
    /// t₁, s: end of the rise (default 10 % of the record).
    pub rise_end: f64,
    /// t₂, s: end of the strong phase (default 50 % of the record).
    pub strong_end: f64,
    /// 1/s: the decay rate after t₂ (default 4 / (duration − t₂)).
    pub decay: f64,
}

impl GroundMotion {
    /// The defaults for a record of `duration` s.
    pub fn for_duration(duration: f64) -> GroundMotion {
        GroundMotion {
            soil_hz: DEFAULT_SOIL_HZ,
            soil_damping: DEFAULT_SOIL_DAMPING,
            rise_end: 0.1 * duration,
            strong_end: 0.5 * duration,
            decay: 4.0 / (0.5 * duration),
        }
    }

    /// `|H(f)|` of the Kanai–Tajimi filter.
    pub fn gain(&self, f: f64) -> f64 {
        let r = f / self.soil_hz;
        let z = 4.0 * self.soil_damping * self.soil_damping * r * r;
        ((1.0 + z) / ((1.0 - r * r).powi(2) + z)).sqrt()
    }

    /// The envelope at time `t`.
    pub fn envelope(&self, t: f64) -> f64 {
        if t < self.rise_end {
            (t / self.rise_end).powi(2)
        } else if t <= self.strong_end {
            1.0
        } else {
            (-self.decay * (t - self.strong_end)).exp()
        }
    }
}

/// The Kanai–Tajimi defaults (firm soil).
pub const DEFAULT_SOIL_HZ: f64 = 2.5;
pub const DEFAULT_SOIL_DAMPING: f64 = 0.6;
/// A storey of a building other than the default 3 when the scenario gives no parameters:
/// the paper's prior means for mass and stiffness, and a damping of about 1 % of critical in
/// the first mode of a 5-storey frame.
pub const DEFAULT_FLOOR_MASS: f64 = ::structure::paper::MASS;
pub const DEFAULT_STOREY_DAMPING: f64 = 3.0;
pub const DEFAULT_STOREY_STIFFNESS: f64 = ::structure::paper::STIFFNESS;

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
    /// Quadratic (velocity-squared) damping, **not** in the FMU's library: the force
    /// `c₂ · v |v|` of a storey's relative velocity (applied as a storey force) or of a floor's
    /// velocity (to the ground); see the module docs.
    QuadraticDamping {
        site: DampingSite,
        /// c₂, N s²/m².
        coefficient: f64,
    },
}

/// Where a quadratic damper acts: across a storey (1..3; storey 1 is ground–floor 1), on the
/// storey's relative velocity, or from a floor (1..3) to the ground, on its velocity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DampingSite {
    Storey(usize),
    Floor(usize),
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
            mass: DEFAULT_MASS.to_vec(),
            damping: DEFAULT_DAMPING.to_vec(),
            stiffness: DEFAULT_STIFFNESS.to_vec(),
            excitation: Excitation::default(),
            force: ForceSpec::default(),
            ground: GroundMotion::for_duration(DEFAULT_DURATION),
            channels: None,
            noise: NoiseSpec::default(),
            effects: Vec::new(),
            effects_from: 0.0,
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
            level: NoiseLevel::Fraction(vec![DEFAULT_NOISE_FRACTION]),
            force_fraction: 0.0,
        }
    }
}

impl NoiseSpec {
    /// No noise at all.
    pub fn none() -> Self {
        NoiseSpec {
            level: NoiseLevel::Fraction(vec![0.0]),
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
        let digits = chars.as_str();
        if digits.starts_with('0') || !digits.chars().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let number: usize = digits.parse().ok()?;
        (1..=MAX_STOREYS).contains(&number).then_some(ParamName {
            kind,
            index: number - 1,
        })
    }
    pub fn name(&self) -> String {
        let letter = match self.kind {
            ParamKind::Mass => 'm',
            ParamKind::Damping => 'c',
            ParamKind::Stiffness => 'k',
        };
        format!("{letter}{}", self.index + 1)
    }
    pub(super) fn slot<'a>(&self, p: &'a mut ShearParameters) -> &'a mut f64 {
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
            EffectSpec::Hysteresis { .. } | EffectSpec::QuadraticDamping { .. } => return None,
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
        match self {
            EffectSpec::Hysteresis { .. } => "hysteresis",
            EffectSpec::QuadraticDamping { .. } => "quadratic_damping",
            _ => self.library().map_or("", |(kind, ..)| kind.name()),
        }
    }
    /// Whether the shear FMU's effect library has this kind (hysteresis, quadratic damping: no).
    pub fn in_library(&self) -> bool {
        !matches!(
            self,
            EffectSpec::Hysteresis { .. } | EffectSpec::QuadraticDamping { .. }
        )
    }
    /// Whether two effects of a kind sit at the same place (a quadratic damper across storey
    /// 2 and one on floor 2 do not).
    pub(super) fn same_place(&self, other: &EffectSpec) -> bool {
        let site = |e: &EffectSpec| match *e {
            EffectSpec::QuadraticDamping {
                site: DampingSite::Floor(_),
                ..
            } => 1,
            _ => 0,
        };
        self.kind() == other.kind()
            && self.library_location() == other.library_location()
            && site(self) == site(other)
    }
    /// The parameters by their JSON names (the library's parameter names; contact's side by
    /// name).
    pub(super) fn parameters_json(&self) -> Map<String, Value> {
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
            (None, &EffectSpec::QuadraticDamping { coefficient, .. }) => {
                o.insert("coefficient".into(), json!(coefficient));
            }
            (None, _) => {}
        }
        o
    }
    /// 0-based location in the FMU's effect library (for hysteresis and quadratic damping,
    /// which the library lacks, the 0-based storey or floor).
    pub fn library_location(&self) -> usize {
        match *self {
            EffectSpec::Contact { lower, .. } => lower,
            EffectSpec::Cubic { storey, .. } => storey - 1,
            EffectSpec::Friction { floor, .. } => floor - 1,
            EffectSpec::Hysteresis { storey, .. } => storey - 1,
            EffectSpec::QuadraticDamping { site, .. } => match site {
                DampingSite::Storey(s) | DampingSite::Floor(s) => s - 1,
            },
        }
    }
    /// The location as the scenario writes it.
    pub fn location(&self) -> Vec<usize> {
        match *self {
            EffectSpec::Contact { lower, .. } => vec![lower, lower + 1],
            EffectSpec::Cubic { storey, .. } => vec![storey],
            EffectSpec::Friction { floor, .. } => vec![floor],
            EffectSpec::Hysteresis { storey, .. } => vec![storey],
            EffectSpec::QuadraticDamping { site, .. } => match site {
                DampingSite::Storey(s) | DampingSite::Floor(s) => vec![s],
            },
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
            EffectSpec::QuadraticDamping { site, .. } => match site {
                DampingSite::Storey(s) => format!("of storey {s} ({})", storey(s - 1)),
                DampingSite::Floor(f) => format!("on floor {f} (to the ground)"),
            },
        }
    }
    /// The FMU variables' prefix, e.g. `contact23`, `cubic2`, `friction1`. Hysteresis and
    /// quadratic damping are not in the library: their `hysteresis2`, `quadratic_damping2`
    /// (storey 2) or `quadratic_damping_floor1` (floor 1) name no FMU variable (see
    /// [`EffectSpec::in_library`]).
    pub fn fmu_prefix(&self) -> String {
        match (self.library(), self) {
            (Some((kind, location, _)), _) => kind.prefix(location),
            (
                None,
                EffectSpec::QuadraticDamping {
                    site: DampingSite::Floor(f),
                    ..
                },
            ) => format!("quadratic_damping_floor{f}"),
            (None, _) => format!("{}{}", self.kind(), self.library_location() + 1),
        }
    }
    fn to_json(&self) -> Value {
        let mut o = Map::new();
        o.insert("kind".into(), json!(self.kind()));
        match *self {
            EffectSpec::QuadraticDamping {
                site: DampingSite::Floor(f),
                ..
            } => o.insert("floor".into(), json!(f)),
            _ => o.insert("location".into(), json!(self.location())),
        };
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
        let text = std::fs::read_to_string(path).map_err(|source| SynthError::Read {
            origin: origin.clone(),
            source,
        })?;
        let value: Value = serde_json::from_str(&text)
            .map_err(|e| SynthError::Scenario(format!("{origin}: not valid JSON: {e}")))?;
        let scenario = Scenario::from_json(&value, &origin)?;
        scenario.validate(&origin)?;
        Ok(scenario)
    }

    /// The number of storeys (floors 1..N).
    pub fn storeys(&self) -> usize {
        self.mass.len()
    }

    /// A building of `n` storeys: the default 3 keeps the default parameters, any other count
    /// has equal floors and storeys ([`DEFAULT_FLOOR_MASS`], [`DEFAULT_STOREY_DAMPING`],
    /// [`DEFAULT_STOREY_STIFFNESS`]).
    pub fn set_storeys(&mut self, n: usize) {
        if n == PAPER_STOREYS {
            self.mass = DEFAULT_MASS.to_vec();
            self.damping = DEFAULT_DAMPING.to_vec();
            self.stiffness = DEFAULT_STIFFNESS.to_vec();
        } else {
            self.mass = vec![DEFAULT_FLOOR_MASS; n];
            self.damping = vec![DEFAULT_STOREY_DAMPING; n];
            self.stiffness = vec![DEFAULT_STOREY_STIFFNESS; n];
        }
    }

    /// The structure the record is made of (at the start of the record).
    pub fn structure(&self) -> Structure {
        Structure {
            mass: self.mass.clone(),
            damping: self.damping.clone(),
            stiffness: self.stiffness.clone(),
            excitation: self.excitation,
        }
    }

    /// The response channels written, in order, each with its unit: the scenario's, or an
    /// accelerometer on every floor in m/s².
    pub fn response_channels(&self) -> Vec<(Channel, Unit)> {
        match &self.channels {
            Some(c) => c.clone(),
            None => (1..=self.storeys())
                .map(|floor| {
                    (
                        Channel::Response {
                            quantity: Quantity::Acceleration,
                            floor,
                        },
                        Unit::MetrePerSecond2,
                    )
                })
                .collect(),
        }
    }
}
