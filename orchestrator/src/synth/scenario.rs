//! The scenario: its types, defaults, JSON form and checks.

use std::path::Path;

use super::{Result, SynthError};
use ::structure::channel::{parse_header_field, Channel, Quantity, Unit};
use ::structure::effects::{Contact, Cubic, Friction, Kind, Law, Location, Side};
use ::structure::paper::STOREYS as PAPER_STOREYS;
use ::structure::{Excitation, Structure, MAX_STOREYS};
use fmu_shear::ShearParameters;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};
use serde_path_to_error::Segment;

use super::{
    DEFAULT_DAMPING, DEFAULT_DURATION, DEFAULT_FORCE_RMS, DEFAULT_HYSTERESIS_BETA,
    DEFAULT_HYSTERESIS_EXPONENT, DEFAULT_HYSTERESIS_GAMMA, DEFAULT_HYSTERESIS_STIFFNESS,
    DEFAULT_HYSTERESIS_YIELD, DEFAULT_MASS, DEFAULT_NOISE_FRACTION, DEFAULT_OVERSAMPLE,
    DEFAULT_QUADRATIC_DAMPING, DEFAULT_SAMPLE_RATE, DEFAULT_STIFFNESS, DEFAULT_WINDOW_RAMP,
    GENERATOR_OVERSAMPLE, MAX_FINE_POINTS, MAX_OVERSAMPLE,
};

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

    /// The scenario in a JSON value (types and names checked; ranges are [`Scenario::validate`]'s).
    pub fn from_json(value: &Value, origin: &str) -> Result<Scenario> {
        let at = Loc {
            origin,
            path: String::new(),
        };
        let file: ScenarioFile = read(&at, value)?;
        let mut s = Scenario::default();
        s.seed = file.seed.unwrap_or(s.seed);
        s.duration = file.duration.unwrap_or(s.duration);
        s.sample_rate = file.sample_rate.unwrap_or(s.sample_rate);
        s.oversample = file.oversample.unwrap_or(s.oversample);
        // The storey count: `storeys`, else the masses' length, else the default 3 (damping
        // and stiffness lists must then match it).
        let given = file
            .parameters
            .as_ref()
            .and_then(|p| p.m.as_ref())
            .map(Vec::len);
        if let Some(n) = file.storeys.or(given) {
            if !(1..=MAX_STOREYS).contains(&n) {
                return Err(at
                    .field("storeys")
                    .error(format!("{n} storeys; a structure has 1 to {MAX_STOREYS}")));
            }
            s.set_storeys(n);
        }
        if let Some(p) = file.parameters {
            s.mass = p.m.unwrap_or(s.mass);
            s.damping = p.c.unwrap_or(s.damping);
            s.stiffness = p.k.unwrap_or(s.stiffness);
        }
        if let Some(text) = &file.excitation {
            s.excitation = Excitation::parse(text).map_err(|e| {
                at.field("excitation")
                    .error(format!("{e}; expected \"force:K\" or \"base\""))
            })?;
        }
        s.ground = GroundMotion::for_duration(s.duration);
        if let Some(g) = file.ground_motion {
            s.ground.soil_hz = g.soil_hz.unwrap_or(s.ground.soil_hz);
            s.ground.soil_damping = g.soil_damping.unwrap_or(s.ground.soil_damping);
            s.ground.rise_end = g.rise_end.unwrap_or(s.ground.rise_end);
            s.ground.strong_end = g.strong_end.unwrap_or(s.ground.strong_end);
            s.ground.decay = g.decay.unwrap_or(s.ground.decay);
        }
        if let Some(channels) = &file.channels {
            let list = at.field("channels");
            s.channels = Some(
                channels
                    .iter()
                    .enumerate()
                    .map(|(i, text)| {
                        parse_header_field(text).map_err(|e| list.index(i).error(e.to_string()))
                    })
                    .collect::<Result<Vec<_>>>()?,
            );
        }
        if let Some(f) = file.force {
            s.force.rms = f.rms.unwrap_or(s.force.rms);
            s.force.band_hz = f.band_hz.or(s.force.band_hz);
            s.force.low_hz = f.low_hz.unwrap_or(s.force.low_hz);
            s.force.between_samples = f.between_samples.unwrap_or(s.force.between_samples);
            s.force.windows = f
                .windows
                .unwrap_or_default()
                .into_iter()
                .map(|w| ForceWindow {
                    start: w.start,
                    end: w.end,
                    gain: w.gain,
                    ramp: w.ramp.unwrap_or(DEFAULT_WINDOW_RAMP),
                })
                .collect();
        }
        if let Some(n) = file.noise {
            match (n.fraction, n.sd) {
                (Some(_), Some(_)) => {
                    return Err(at
                        .field("noise")
                        .error("give either `fraction` or `sd`, not both".into()))
                }
                (Some(x), None) => s.noise.level = NoiseLevel::Fraction(x.values()),
                (None, Some(x)) => s.noise.level = NoiseLevel::Sd(x.values()),
                (None, None) => {}
            }
            s.noise.force_fraction = n.force_fraction.unwrap_or(s.noise.force_fraction);
        }
        let effects = at.field("effects");
        for (i, e) in file.effects.unwrap_or_default().iter().enumerate() {
            s.effects
                .push(parse_effect(&effects.index(i), e, s.storeys())?);
        }
        s.effects_from = file.effects_from.unwrap_or(0.0);
        if !(s.effects_from.is_finite() && s.effects_from >= 0.0) {
            return Err(at
                .field("effects_from")
                .error("the effects' start must be a time ≥ 0 s".into()));
        }
        let changes = at.field("changes");
        for (i, c) in file.changes.unwrap_or_default().into_iter().enumerate() {
            let at = changes.index(i);
            let parameter = ParamName::parse(&c.parameter).ok_or_else(|| {
                at.field("parameter").error(format!(
                    "unknown parameter {:?}; expected m1..m{n}, c1..c{n} or k1..k{n}",
                    c.parameter,
                    n = s.storeys()
                ))
            })?;
            let how = match (c.factor, c.value) {
                (Some(x), None) => ChangeHow::Factor(x),
                (None, Some(x)) => ChangeHow::Value(x),
                _ => return Err(at.error("give exactly one of `factor` and `value`".into())),
            };
            s.changes.push(Change {
                at: c.at,
                parameter,
                how,
            });
        }
        Ok(s)
    }

    /// The scenario as JSON, every default filled in: [`Scenario::from_json`] reads it back equal.
    pub fn to_json(&self) -> Value {
        let levels: Vec<f64> = (0..self.response_channels().len())
            .map(|i| self.noise.level.at(i))
            .collect();
        let noise = match &self.noise.level {
            NoiseLevel::Fraction(_) => {
                json!({"fraction": levels, "force_fraction": self.noise.force_fraction})
            }
            NoiseLevel::Sd(_) => {
                json!({"sd": levels, "force_fraction": self.noise.force_fraction})
            }
        };
        let mut v = json!({
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
        });
        // The building, its excitation and sensors when they are not the paper rig's (whose
        // scenarios read as they always have).
        if self.storeys() != PAPER_STOREYS {
            v["storeys"] = json!(self.storeys());
        }
        // Effects that start later (written only then: earlier scenarios read as they did).
        if self.effects_from > 0.0 {
            v["effects_from"] = json!(self.effects_from);
        }
        if self.excitation != Excitation::default() {
            v["excitation"] = json!(self.excitation.name());
        }
        if self.excitation == Excitation::Base {
            v["ground_motion"] = json!(self.ground);
        }
        if let Some(channels) = &self.channels {
            v["channels"] = json!(channels
                .iter()
                .map(|(c, u)| header_field(*c, *u))
                .collect::<Vec<_>>());
        }
        v
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

    /// Check the ranges; `origin` names the source (a file, or "scenario") in the errors.
    pub fn validate(&self, origin: &str) -> Result<()> {
        let at = Loc {
            origin,
            path: String::new(),
        };
        let n = self.check_sampling(&at)?;
        let n_storeys = self.check_structure(&at)?;
        let channels = self.check_channels(&at, n_storeys)?;
        self.check_force(&at, n)?;
        self.check_noise(&at, channels)?;
        self.check_effects(&at, n_storeys)?;
        self.check_changes(&at, n, n_storeys)
    }

    /// The sampling: a positive rate and duration, an oversampling in range, and a record of at
    /// least 2 samples that is not too long for the force's or the structure's fine grid.
    /// Returns the number of samples.
    fn check_sampling(&self, at: &Loc) -> Result<usize> {
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
        Ok(n)
    }

    /// The structure: 1 to [`MAX_STOREYS`] floors with a value of each parameter per storey in
    /// range, a forced floor the structure has, and under ground motion a valid spectrum and
    /// envelope. Returns the number of storeys.
    fn check_structure(&self, at: &Loc) -> Result<usize> {
        let p = at.field("parameters");
        let n_storeys = self.storeys();
        if !(1..=MAX_STOREYS).contains(&n_storeys) {
            return Err(p.field("m").error(format!(
                "{n_storeys} floors; a structure has 1 to {MAX_STOREYS}"
            )));
        }
        for (name, values) in [("c", &self.damping), ("k", &self.stiffness)] {
            if values.len() != n_storeys {
                return Err(p.field(name).error(format!(
                    "{} values for {n_storeys} storeys (m has {n_storeys})",
                    values.len()
                )));
            }
        }
        for i in 0..n_storeys {
            positive(p.field("m").index(i), self.mass[i], true)?;
            positive(p.field("c").index(i), self.damping[i], false)?;
            positive(p.field("k").index(i), self.stiffness[i], false)?;
        }
        if let Excitation::Force { floor } = self.excitation {
            if !(1..=n_storeys).contains(&floor) {
                return Err(at.field("excitation").error(format!(
                    "force:{floor}: the structure has floors 1 to {n_storeys}"
                )));
            }
        }
        if self.excitation == Excitation::Base {
            let g = at.field("ground_motion");
            positive(g.field("soil_hz"), self.ground.soil_hz, true)?;
            positive(g.field("soil_damping"), self.ground.soil_damping, true)?;
            positive(g.field("rise_end"), self.ground.rise_end, true)?;
            positive(g.field("decay"), self.ground.decay, false)?;
            if !(self.ground.strong_end.is_finite()
                && self.ground.strong_end >= self.ground.rise_end)
            {
                return Err(g.field("strong_end").error(format!(
                    "{} s must be a finite time ≥ rise_end {} s",
                    self.ground.strong_end, self.ground.rise_end
                )));
            }
        }
        Ok(n_storeys)
    }

    /// The response channels: at least one, each a response of a floor the structure has, in a
    /// unit of its quantity, none twice. Returns how many there are.
    fn check_channels(&self, at: &Loc, n_storeys: usize) -> Result<usize> {
        let channels = self.response_channels();
        if channels.is_empty() {
            return Err(at
                .field("channels")
                .error("is empty; give at least one response channel".into()));
        }
        for (i, (channel, unit)) in channels.iter().enumerate() {
            let at = at.field("channels").index(i);
            match channel {
                Channel::Response { floor, quantity } => {
                    if !(1..=n_storeys).contains(floor) {
                        return Err(at.error(format!(
                            "'{}': the structure has floors 1 to {n_storeys}",
                            channel.name()
                        )));
                    }
                    if unit.quantity() != *quantity {
                        return Err(at.error(format!(
                            "'{}' cannot be in {}",
                            channel.name(),
                            unit.symbol()
                        )));
                    }
                }
                _ => {
                    return Err(at.error(format!(
                        "'{}' is not a response (acc<i>, vel<i> or disp<i>); the excitation is always written",
                        channel.name()
                    )))
                }
            }
            if channels[..i].iter().any(|(c, _)| c == channel) {
                return Err(at.error(format!("'{}' is given twice", channel.name())));
            }
        }
        Ok(channels.len())
    }

    /// The force: its level, a band below the Nyquist frequency that holds at least one of the
    /// `n`-sample record's frequencies, and its windows.
    fn check_force(&self, at: &Loc, n: usize) -> Result<()> {
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
            check_window(f.field("windows").index(i), w)?;
        }
        Ok(())
    }

    /// The noise: one level or one per response channel (`channels` of them), each in range,
    /// and the force's fraction.
    fn check_noise(&self, at: &Loc, channels: usize) -> Result<()> {
        let noise = at.field("noise");
        let (name, levels) = match &self.noise.level {
            NoiseLevel::Fraction(x) => ("fraction", x),
            NoiseLevel::Sd(x) => ("sd", x),
        };
        if levels.len() != 1 && levels.len() != channels {
            return Err(noise.field(name).error(format!(
                "{} values for {} response channels; give one value or one per channel",
                levels.len(),
                channels
            )));
        }
        for (i, &x) in levels.iter().enumerate() {
            positive(noise.field(name).index(i), x, false)?;
        }
        positive(
            noise.field("force_fraction"),
            self.noise.force_fraction,
            false,
        )
    }

    /// The effects: each at a site of the structure, its parameters in range, and at most one of
    /// a kind per location.
    fn check_effects(&self, at: &Loc, n_storeys: usize) -> Result<()> {
        for (i, e) in self.effects.iter().enumerate() {
            let at = at.field("effects").index(i);
            check_effect(&at, e, n_storeys)?;
            check_library_parameters(&at, e)?;
            if let Some(j) = self.effects[..i].iter().position(|o| o.same_place(e)) {
                return Err(at.error(format!(
                    "{} {} is already given as effects[{j}]; one effect of a kind per location",
                    e.kind(),
                    e.describe_location()
                )));
            }
        }
        Ok(())
    }

    /// The changes: each of a parameter the structure has, inside the `n`-sample record, by a
    /// factor or to a value in range.
    fn check_changes(&self, at: &Loc, n: usize, n_storeys: usize) -> Result<()> {
        let last = (n - 1) as f64 / self.sample_rate;
        for (i, c) in self.changes.iter().enumerate() {
            let at = at.field("changes").index(i);
            if c.parameter.index >= n_storeys {
                return Err(at.field("parameter").error(format!(
                    "{} is not a parameter of the {n_storeys}-storey structure",
                    c.parameter.name()
                )));
            }
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

/// `x` is finite and > 0 (`strictly`) or ≥ 0; refused at `loc` otherwise.
fn positive(loc: Loc, x: f64, strictly: bool) -> Result<()> {
    let ok = x.is_finite() && if strictly { x > 0.0 } else { x >= 0.0 };
    if ok {
        Ok(())
    } else {
        Err(loc.error(format!(
            "{x} must be a finite number {} 0",
            if strictly { ">" } else { "≥" }
        )))
    }
}

/// A force window (at `at`): finite numbers, an end after its start, a gain and a ramp in
/// range, the ramp no longer than the window.
fn check_window(at: Loc, w: &ForceWindow) -> Result<()> {
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
    Ok(())
}

/// An effect (at `at`) where the `n_storeys`-storey structure has a site for its kind, with a
/// valid side (contact) or parameters (hysteresis, quadratic damping).
fn check_effect(at: &Loc, e: &EffectSpec, n_storeys: usize) -> Result<()> {
    match *e {
        EffectSpec::Contact { lower, side, .. } => {
            if lower >= n_storeys {
                return Err(at.field("location").error(format!(
                    "[{lower}, {}] is not a storey of the {n_storeys}-storey structure",
                    lower + 1
                )));
            }
            if Side::from_code(side).is_none() {
                return Err(at.field("side").error(format!("{side} is not -1, 0 or 1")));
            }
        }
        EffectSpec::Cubic { storey, .. } => {
            if !(1..=n_storeys).contains(&storey) {
                return Err(at
                    .field("location")
                    .error(format!("storey {storey} is not one of 1..{n_storeys}")));
            }
        }
        EffectSpec::Friction { floor, .. } => {
            if !(1..=n_storeys).contains(&floor) {
                return Err(at
                    .field("location")
                    .error(format!("floor {floor} is not one of 1..{n_storeys}")));
            }
        }
        EffectSpec::Hysteresis { .. } => check_hysteresis(at, e, n_storeys)?,
        EffectSpec::QuadraticDamping { site, coefficient } => {
            match site {
                DampingSite::Storey(s) if !(1..=n_storeys).contains(&s) => {
                    return Err(at
                        .field("location")
                        .error(format!("storey {s} is not one of 1..{n_storeys}")))
                }
                DampingSite::Floor(f) if !(1..=n_storeys).contains(&f) => {
                    return Err(at
                        .field("floor")
                        .error(format!("floor {f} is not one of 1..{n_storeys}")))
                }
                _ => {}
            }
            positive(at.field("coefficient"), coefficient, true)?;
        }
    }
    Ok(())
}

/// A hysteresis effect (at `at`): a storey of the `n_storeys`, positive stiffness and yield
/// drift, finite β and γ with β + γ > 0, an exponent ≥ 1.
fn check_hysteresis(at: &Loc, e: &EffectSpec, n_storeys: usize) -> Result<()> {
    let EffectSpec::Hysteresis {
        storey,
        stiffness,
        yield_drift,
        beta,
        gamma,
        exponent,
    } = *e
    else {
        return Ok(());
    };
    if !(1..=n_storeys).contains(&storey) {
        return Err(at
            .field("location")
            .error(format!("storey {storey} is not one of 1..{n_storeys}")));
    }
    positive(at.field("stiffness"), stiffness, true)?;
    positive(at.field("yield"), yield_drift, true)?;
    for (name, x) in [("beta", beta), ("gamma", gamma)] {
        if !x.is_finite() {
            return Err(at.field(name).error(format!("{x} is not a finite number")));
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
    Ok(())
}

/// A library effect's parameters (at `at`): the ranges the FMU accepts.
fn check_library_parameters(at: &Loc, e: &EffectSpec) -> Result<()> {
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
    Ok(())
}

/// One effect of the scenario's `effects` list (also what `--effect` becomes). The library's
/// kinds take their parameter names, defaults and side from its description.
pub(super) fn parse_effect(at: &Loc, value: &Value, storeys: usize) -> Result<EffectSpec> {
    let head: EffectHead = read(at, value)?;
    let loc = at.field("location");
    let small = |x: u64| usize::try_from(x).unwrap_or(usize::MAX);
    // The file's list of floor numbers as the text form's location.
    let place = |location: &[u64]| {
        Location::from_numbers(&location.iter().map(|&x| small(x)).collect::<Vec<_>>())
    };
    let storey_or_adjacent = |location: &[u64]| {
        place(location)
            .and_then(|l| l.storey(storeys))
            .ok_or_else(|| {
                loc.error(format!(
            "{location:?} is not a storey; expected [1]..[{storeys}] (storey 1 = ground–floor 1) or two adjacent floors"
        ))
            })
    };
    if head.kind == "quadratic_damping" {
        let q: QuadraticDampingFile = read(at, value)?;
        let site = match (head.location, q.floor) {
            (Some(location), None) => DampingSite::Storey(storey_or_adjacent(&location.floors())?),
            (None, Some(f)) if (1..=storeys as u64).contains(&f) => DampingSite::Floor(small(f)),
            (None, Some(f)) => {
                return Err(at
                    .field("floor")
                    .error(format!("floor {f} is not one of 1..{storeys}")))
            }
            (Some(_), Some(_)) => {
                return Err(at.error(
                    "give either `location` (a storey) or `floor` (to the ground), not both"
                        .into(),
                ))
            }
            (None, None) => return Err(loc.error(
                format!("is missing; give `location` (a storey: [1]..[{storeys}] or two adjacent floors) or `floor` (1..{storeys}, damped to the ground)"),
            )),
        };
        return Ok(EffectSpec::QuadraticDamping {
            site,
            coefficient: q.coefficient.unwrap_or(DEFAULT_QUADRATIC_DAMPING),
        });
    }
    let location = match head.location {
        Some(location) => location.floors(),
        None => return Err(loc.error("is missing".into())),
    };
    if head.kind == "hysteresis" {
        let h: HysteresisFile = read(at, value)?;
        return Ok(EffectSpec::Hysteresis {
            storey: storey_or_adjacent(&location)?,
            stiffness: h.stiffness.unwrap_or(DEFAULT_HYSTERESIS_STIFFNESS),
            yield_drift: h.yield_drift.unwrap_or(DEFAULT_HYSTERESIS_YIELD),
            beta: h.beta.unwrap_or(DEFAULT_HYSTERESIS_BETA),
            gamma: h.gamma.unwrap_or(DEFAULT_HYSTERESIS_GAMMA),
            exponent: h.exponent.unwrap_or(DEFAULT_HYSTERESIS_EXPONENT),
        });
    }
    let Some(kind) = Kind::parse(&head.kind) else {
        return Err(at.field("kind").error(format!(
            "unknown effect kind {:?}; expected \"contact\", \"cubic\", \"friction\", \"hysteresis\" or \"quadratic_damping\"",
            head.kind
        )));
    };
    // The rest of the object: the kind's parameters (and contact's side), nothing else.
    let fields: Map<String, Value> = read(at, value)?;
    let mut known = vec!["kind", "location"];
    known.extend(kind.real_params().iter().map(|p| p.suffix));
    if kind.has_side() {
        known.push("side");
    }
    if let Some(key) = fields.keys().find(|k| !known.contains(&k.as_str())) {
        return Err(at.field(key).error(format!(
            "unknown field; expected one of {}",
            known.join(", ")
        )));
    }
    // 0-based, as the library counts; where each kind may sit is the catalogue's.
    let location = match place(&location) {
        Some(at) => kind
            .site(at, storeys)
            .map_err(|e| loc.error(format!("{location:?}: {e}")))?,
        None => {
            return Err(loc.error(format!(
                "{location:?} is neither a storey or floor [N] nor two floors [lower, upper]"
            )))
        }
    };
    let side = match fields.get("side") {
        None => Side::Both,
        Some(v) => match read::<SideFile>(&at.field("side"), v)? {
            SideFile::Name(side) => side,
            SideFile::Code(code) => Side::from_code(code)
                .ok_or_else(|| at.field("side").error(format!("{code} is not -1, 0 or 1")))?,
        },
    };
    let reals = kind
        .real_params()
        .iter()
        .map(|p| match fields.get(p.suffix) {
            Some(v) => read::<f64>(&at.field(p.suffix), v),
            None => Ok(p.start),
        })
        .collect::<Result<Vec<f64>>>()?;
    let law = Law::new(kind, &reals, side)
        .ok_or_else(|| at.error(format!("too few parameters for {}", kind.name())))?;
    Ok(EffectSpec::from_library(location, law))
}

// ---------------------------------------------------------------------------------------------
// The scenario file as written: every field optional, unknown fields refused
// ---------------------------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct ScenarioFile {
    seed: Option<u64>,
    duration: Option<f64>,
    sample_rate: Option<f64>,
    oversample: Option<u32>,
    storeys: Option<usize>,
    excitation: Option<String>,
    parameters: Option<ParametersFile>,
    ground_motion: Option<GroundMotionFile>,
    /// Response channels as a record's header writes them: `acc1`, `acc3 (g)`, `vel2 (mm/s)`.
    channels: Option<Vec<String>>,
    force: Option<ForceFile>,
    noise: Option<NoiseFile>,
    /// Read one by one by [`parse_effect`], whose fields depend on the kind.
    effects: Option<Vec<Value>>,
    effects_from: Option<f64>,
    changes: Option<Vec<ChangeFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct ParametersFile {
    m: Option<Vec<f64>>,
    c: Option<Vec<f64>>,
    k: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct GroundMotionFile {
    soil_hz: Option<f64>,
    soil_damping: Option<f64>,
    rise_end: Option<f64>,
    strong_end: Option<f64>,
    decay: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct ForceFile {
    rms: Option<f64>,
    band_hz: Option<f64>,
    low_hz: Option<f64>,
    between_samples: Option<BetweenSamples>,
    windows: Option<Vec<WindowFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct WindowFile {
    start: f64,
    end: f64,
    gain: f64,
    ramp: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct NoiseFile {
    fraction: Option<OneOrMany>,
    sd: Option<OneOrMany>,
    force_fraction: Option<f64>,
}

/// A number for every response channel, or one per channel.
#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "expected a number or a list of numbers (one per response channel)"
)]
enum OneOrMany {
    One(f64),
    Many(Vec<f64>),
}

impl OneOrMany {
    fn values(self) -> Vec<f64> {
        match self {
            OneOrMany::One(x) => vec![x],
            OneOrMany::Many(x) => x,
        }
    }
}

/// A channel as a record's header writes it: `acc1` in SI, `acc1 (g)` otherwise.
pub fn header_field(channel: Channel, unit: Unit) -> String {
    if unit == channel.quantity().si() {
        channel.name()
    } else {
        format!("{} ({})", channel.name(), unit.symbol())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct ChangeFile {
    at: f64,
    parameter: String,
    factor: Option<f64>,
    value: Option<f64>,
}

/// What every effect has; the rest depends on the kind.
#[derive(Deserialize)]
#[serde(expecting = "an object")]
struct EffectHead {
    kind: String,
    /// Absent only for a quadratic damper on a floor (its `floor`).
    location: Option<LocationFile>,
}

/// Floor numbers, or a single number.
#[derive(Deserialize)]
#[serde(untagged, expecting = "expected a list of floor numbers")]
enum LocationFile {
    One(u64),
    Many(Vec<u64>),
}

impl LocationFile {
    fn floors(self) -> Vec<u64> {
        match self {
            LocationFile::One(x) => vec![x],
            LocationFile::Many(x) => x,
        }
    }
}

/// A contact's side by name or by the FMU's integer.
#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "expected \"both\", \"positive\" or \"negative\" (or 0, 1, -1)"
)]
enum SideFile {
    Name(Side),
    Code(i32),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct HysteresisFile {
    #[allow(dead_code)]
    kind: String,
    #[allow(dead_code)]
    location: Value,
    stiffness: Option<f64>,
    #[serde(rename = "yield")]
    yield_drift: Option<f64>,
    beta: Option<f64>,
    gamma: Option<f64>,
    exponent: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
struct QuadraticDampingFile {
    #[allow(dead_code)]
    kind: String,
    #[allow(dead_code)]
    location: Option<Value>,
    floor: Option<u64>,
    coefficient: Option<f64>,
}

/// Deserialize `value` at `at`; a bad field's error names the file and the field's JSON path.
fn read<T: DeserializeOwned>(at: &Loc, value: &Value) -> Result<T> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let mut loc = at.clone();
        for segment in e.path().iter() {
            loc = match segment {
                Segment::Seq { index } => loc.index(*index),
                Segment::Map { key } => loc.field(key),
                Segment::Enum { .. } | Segment::Unknown => loc,
            };
        }
        let message = e.into_inner().to_string();
        // serde names a missing or unknown field in its message: put it in the path instead.
        if let Some(name) = message
            .strip_prefix("missing field `")
            .and_then(|rest| rest.strip_suffix('`'))
        {
            return loc.field(name).error("is missing".into());
        }
        if let Some((name, expected)) = message
            .strip_prefix("unknown field `")
            .and_then(|rest| rest.split_once('`'))
        {
            if !loc.path.ends_with(name) {
                loc = loc.field(name);
            }
            return loc.error(format!(
                "unknown field; {}",
                expected.trim_start_matches(", ")
            ));
        }
        loc.error(message)
    })
}

/// Where a value sits: the file and the field path, for error messages.
#[derive(Clone)]
pub(super) struct Loc<'a> {
    pub(super) origin: &'a str,
    pub(super) path: String,
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
    fn error(&self, message: String) -> SynthError {
        SynthError::Scenario(if self.path.is_empty() {
            format!("{}: {message}", self.origin)
        } else {
            format!("{}: field `{}`: {message}", self.origin, self.path)
        })
    }
}
