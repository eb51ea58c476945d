//! The scenario's JSON form: read (every field checked for its type and named in the error) and
//! written back, the effects' entries, and where in the file a value sits.

use super::{
    BetweenSamples, Change, ChangeHow, DampingSite, EffectSpec, ForceWindow, GroundMotion,
    NoiseLevel, ParamName, Scenario,
};
use crate::synth::{Result, SynthError};
use crate::synth::{
    DEFAULT_HYSTERESIS_BETA, DEFAULT_HYSTERESIS_EXPONENT, DEFAULT_HYSTERESIS_GAMMA,
    DEFAULT_HYSTERESIS_STIFFNESS, DEFAULT_HYSTERESIS_YIELD, DEFAULT_QUADRATIC_DAMPING,
    DEFAULT_WINDOW_RAMP,
};
use ::structure::channel::{parse_header_field, Channel, Unit};
use ::structure::effects::{Kind, Law, Location, Side};
use ::structure::paper::STOREYS as PAPER_STOREYS;
use ::structure::{Excitation, MAX_STOREYS};
use serde::de::DeserializeOwned;
use serde::Deserialize;
use serde_json::{json, Map, Value};
use serde_path_to_error::Segment;

impl Scenario {
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
        s.structure_from(
            &at,
            file.storeys,
            file.parameters,
            file.excitation.as_deref(),
        )?;
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
            s.force_from(f);
        }
        if let Some(n) = file.noise {
            s.noise_from(&at, n)?;
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
        s.changes_from(&at, file.changes.unwrap_or_default())?;
        Ok(s)
    }

    /// The file's storey count (`storeys`, else the masses' length, else the default 3: damping
    /// and stiffness lists must then match it), its parameters and its excitation.
    fn structure_from(
        &mut self,
        at: &Loc,
        storeys: Option<usize>,
        parameters: Option<ParametersFile>,
        excitation: Option<&str>,
    ) -> Result<()> {
        let given = parameters.as_ref().and_then(|p| p.m.as_ref()).map(Vec::len);
        if let Some(n) = storeys.or(given) {
            if !(1..=MAX_STOREYS).contains(&n) {
                return Err(at
                    .field("storeys")
                    .error(format!("{n} storeys; a structure has 1 to {MAX_STOREYS}")));
            }
            self.set_storeys(n);
        }
        if let Some(p) = parameters {
            if let Some(m) = p.m {
                self.mass = m;
            }
            if let Some(c) = p.c {
                self.damping = c;
            }
            if let Some(k) = p.k {
                self.stiffness = k;
            }
        }
        if let Some(text) = excitation {
            self.excitation = Excitation::parse(text).map_err(|e| {
                at.field("excitation")
                    .error(format!("{e}; expected \"force:K\" or \"base\""))
            })?;
        }
        Ok(())
    }

    /// The file's force over the defaults: level, band, interpolation and windows.
    fn force_from(&mut self, f: ForceFile) {
        self.force.rms = f.rms.unwrap_or(self.force.rms);
        self.force.band_hz = f.band_hz.or(self.force.band_hz);
        self.force.low_hz = f.low_hz.unwrap_or(self.force.low_hz);
        self.force.between_samples = f.between_samples.unwrap_or(self.force.between_samples);
        self.force.windows = f
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

    /// The file's noise: a fraction or an sd (not both), and the force's fraction.
    fn noise_from(&mut self, at: &Loc, n: NoiseFile) -> Result<()> {
        match (n.fraction, n.sd) {
            (Some(_), Some(_)) => {
                return Err(at
                    .field("noise")
                    .error("give either `fraction` or `sd`, not both".into()))
            }
            (Some(x), None) => self.noise.level = NoiseLevel::Fraction(x.values()),
            (None, Some(x)) => self.noise.level = NoiseLevel::Sd(x.values()),
            (None, None) => {}
        }
        self.noise.force_fraction = n.force_fraction.unwrap_or(self.noise.force_fraction);
        Ok(())
    }

    /// The file's parameter changes, each naming a parameter of this structure and exactly one
    /// of a factor and a value.
    fn changes_from(&mut self, at: &Loc, changes: Vec<ChangeFile>) -> Result<()> {
        let list = at.field("changes");
        for (i, c) in changes.into_iter().enumerate() {
            let at = list.index(i);
            let parameter = ParamName::parse(&c.parameter).ok_or_else(|| {
                at.field("parameter").error(format!(
                    "unknown parameter {:?}; expected m1..m{n}, c1..c{n} or k1..k{n}",
                    c.parameter,
                    n = self.storeys()
                ))
            })?;
            let how = match (c.factor, c.value) {
                (Some(x), None) => ChangeHow::Factor(x),
                (None, Some(x)) => ChangeHow::Value(x),
                _ => return Err(at.error("give exactly one of `factor` and `value`".into())),
            };
            self.changes.push(Change {
                at: c.at,
                parameter,
                how,
            });
        }
        Ok(())
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
}

/// One effect of the scenario's `effects` list (also what `--effect` becomes). The library's
/// kinds take their parameter names, defaults and side from its description.
pub(in crate::synth) fn parse_effect(
    at: &Loc,
    value: &Value,
    storeys: usize,
) -> Result<EffectSpec> {
    let head: EffectHead = read(at, value)?;
    if head.kind == "quadratic_damping" {
        return quadratic_damping(at, value, head.location, storeys);
    }
    let location = match head.location {
        Some(location) => location.floors(),
        None => return Err(at.field("location").error("is missing".into())),
    };
    if head.kind == "hysteresis" {
        let h: HysteresisFile = read(at, value)?;
        return Ok(EffectSpec::Hysteresis {
            storey: storey_or_adjacent(at, &location, storeys)?,
            stiffness: h.stiffness.unwrap_or(DEFAULT_HYSTERESIS_STIFFNESS),
            yield_drift: h.yield_drift.unwrap_or(DEFAULT_HYSTERESIS_YIELD),
            beta: h.beta.unwrap_or(DEFAULT_HYSTERESIS_BETA),
            gamma: h.gamma.unwrap_or(DEFAULT_HYSTERESIS_GAMMA),
            exponent: h.exponent.unwrap_or(DEFAULT_HYSTERESIS_EXPONENT),
        });
    }
    library_effect(at, value, &head.kind, &location, storeys)
}

/// A floor number of the file as an index (too large: one no structure has).
fn small(x: u64) -> usize {
    usize::try_from(x).unwrap_or(usize::MAX)
}

/// The file's list of floor numbers as the text form's location.
fn place(location: &[u64]) -> Option<Location> {
    Location::from_numbers(&location.iter().map(|&x| small(x)).collect::<Vec<_>>())
}

/// The storey (1-based) the file's `location` names: one storey, or two adjacent floors.
fn storey_or_adjacent(at: &Loc, location: &[u64], storeys: usize) -> Result<usize> {
    place(location)
        .and_then(|l| l.storey(storeys))
        .ok_or_else(|| {
            at.field("location").error(format!(
        "{location:?} is not a storey; expected [1]..[{storeys}] (storey 1 = ground–floor 1) or two adjacent floors"
    ))
        })
}

/// A quadratic damper: on a storey (`location`) or from a floor to the ground (`floor`).
fn quadratic_damping(
    at: &Loc,
    value: &Value,
    location: Option<LocationFile>,
    storeys: usize,
) -> Result<EffectSpec> {
    let q: QuadraticDampingFile = read(at, value)?;
    let site = match (location, q.floor) {
        (Some(location), None) => {
            DampingSite::Storey(storey_or_adjacent(at, &location.floors(), storeys)?)
        }
        (None, Some(f)) if (1..=storeys as u64).contains(&f) => DampingSite::Floor(small(f)),
        (None, Some(f)) => {
            return Err(at
                .field("floor")
                .error(format!("floor {f} is not one of 1..{storeys}")))
        }
        (Some(_), Some(_)) => {
            return Err(at.error(
                "give either `location` (a storey) or `floor` (to the ground), not both".into(),
            ))
        }
        (None, None) => return Err(at.field("location").error(
            format!("is missing; give `location` (a storey: [1]..[{storeys}] or two adjacent floors) or `floor` (1..{storeys}, damped to the ground)"),
        )),
    };
    Ok(EffectSpec::QuadraticDamping {
        site,
        coefficient: q.coefficient.unwrap_or(DEFAULT_QUADRATIC_DAMPING),
    })
}

/// An effect of the library's catalogue (`kind`): its parameters (and contact's side) and
/// nothing else, at a site the catalogue allows.
fn library_effect(
    at: &Loc,
    value: &Value,
    kind_name: &str,
    location: &[u64],
    storeys: usize,
) -> Result<EffectSpec> {
    let loc = at.field("location");
    let Some(kind) = Kind::parse(kind_name) else {
        return Err(at.field("kind").error(format!(
            "unknown effect kind {:?}; expected \"contact\", \"cubic\", \"friction\", \"hysteresis\" or \"quadratic_damping\"",
            kind_name
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
    let location = match place(location) {
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
pub(super) struct ScenarioFile {
    pub(super) seed: Option<u64>,
    pub(super) duration: Option<f64>,
    pub(super) sample_rate: Option<f64>,
    pub(super) oversample: Option<u32>,
    pub(super) storeys: Option<usize>,
    pub(super) excitation: Option<String>,
    pub(super) parameters: Option<ParametersFile>,
    pub(super) ground_motion: Option<GroundMotionFile>,
    /// Response channels as a record's header writes them: `acc1`, `acc3 (g)`, `vel2 (mm/s)`.
    pub(super) channels: Option<Vec<String>>,
    pub(super) force: Option<ForceFile>,
    pub(super) noise: Option<NoiseFile>,
    /// Read one by one by [`parse_effect`], whose fields depend on the kind.
    pub(super) effects: Option<Vec<Value>>,
    pub(super) effects_from: Option<f64>,
    pub(super) changes: Option<Vec<ChangeFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct ParametersFile {
    pub(super) m: Option<Vec<f64>>,
    pub(super) c: Option<Vec<f64>>,
    pub(super) k: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct GroundMotionFile {
    pub(super) soil_hz: Option<f64>,
    pub(super) soil_damping: Option<f64>,
    pub(super) rise_end: Option<f64>,
    pub(super) strong_end: Option<f64>,
    pub(super) decay: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct ForceFile {
    pub(super) rms: Option<f64>,
    pub(super) band_hz: Option<f64>,
    pub(super) low_hz: Option<f64>,
    pub(super) between_samples: Option<BetweenSamples>,
    pub(super) windows: Option<Vec<WindowFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct WindowFile {
    pub(super) start: f64,
    pub(super) end: f64,
    pub(super) gain: f64,
    pub(super) ramp: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct NoiseFile {
    pub(super) fraction: Option<OneOrMany>,
    pub(super) sd: Option<OneOrMany>,
    pub(super) force_fraction: Option<f64>,
}

/// A number for every response channel, or one per channel.
#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "expected a number or a list of numbers (one per response channel)"
)]
pub(super) enum OneOrMany {
    One(f64),
    Many(Vec<f64>),
}

impl OneOrMany {
    pub(super) fn values(self) -> Vec<f64> {
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
pub(super) struct ChangeFile {
    pub(super) at: f64,
    pub(super) parameter: String,
    pub(super) factor: Option<f64>,
    pub(super) value: Option<f64>,
}

/// What every effect has; the rest depends on the kind.
#[derive(Deserialize)]
#[serde(expecting = "an object")]
pub(super) struct EffectHead {
    pub(super) kind: String,
    /// Absent only for a quadratic damper on a floor (its `floor`).
    pub(super) location: Option<LocationFile>,
}

/// Floor numbers, or a single number.
#[derive(Deserialize)]
#[serde(untagged, expecting = "expected a list of floor numbers")]
pub(super) enum LocationFile {
    One(u64),
    Many(Vec<u64>),
}

impl LocationFile {
    pub(super) fn floors(self) -> Vec<u64> {
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
pub(super) enum SideFile {
    Name(Side),
    Code(i32),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct HysteresisFile {
    #[allow(dead_code)]
    pub(super) kind: String,
    #[allow(dead_code)]
    pub(super) location: Value,
    pub(super) stiffness: Option<f64>,
    #[serde(rename = "yield")]
    pub(super) yield_drift: Option<f64>,
    pub(super) beta: Option<f64>,
    pub(super) gamma: Option<f64>,
    pub(super) exponent: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, expecting = "an object")]
pub(super) struct QuadraticDampingFile {
    #[allow(dead_code)]
    pub(super) kind: String,
    #[allow(dead_code)]
    pub(super) location: Option<Value>,
    pub(super) floor: Option<u64>,
    pub(super) coefficient: Option<f64>,
}

/// Deserialize `value` at `at`; a bad field's error names the file and the field's JSON path.
pub(super) fn read<T: DeserializeOwned>(at: &Loc, value: &Value) -> Result<T> {
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
pub(in crate::synth) struct Loc<'a> {
    pub(in crate::synth) origin: &'a str,
    pub(in crate::synth) path: String,
}

impl<'a> Loc<'a> {
    pub(super) fn field(&self, name: &str) -> Loc<'a> {
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
    pub(super) fn index(&self, i: usize) -> Loc<'a> {
        Loc {
            origin: self.origin,
            path: format!("{}[{i}]", self.path),
        }
    }
    pub(super) fn error(&self, message: String) -> SynthError {
        SynthError::Scenario(if self.path.is_empty() {
            format!("{}: {message}", self.origin)
        } else {
            format!("{}: field `{}`: {message}", self.origin, self.path)
        })
    }
}
