//! The command-line forms of an effect (`--effect contact@2-3:gap=5e-4`) and a parameter
//! change (`--change k2@8:0.85`), read into the scenario's types.

use super::{Result, SynthError};
use ::structure::effects::{Kind, Label, Location};
use ::structure::paper::STOREYS as PAPER_STOREYS;
use serde_json::{Map, Value};

use super::scenario::{parse_effect, Change, ChangeHow, EffectSpec, Loc, ParamName};

/// The effect's text form ([`Label`]): `contact@2-3:gap=5e-4,stiffness=9000,side=both`,
/// `cubic@2`, `friction@1:force=0.2`, `hysteresis@2:stiffness=1500,yield=3e-4`,
/// `quadratic-damping@2:coefficient=40` (storey 2, or `@1-2`) and
/// `quadratic-damping@floor1:coefficient=40` (floor 1 to the ground; the kind may also be
/// written `quadratic_damping`, as in the JSON). Read into the scenario file's form and checked
/// as the file's effects are.
pub fn parse_effect_flag(text: &str) -> Result<EffectSpec> {
    parse_effect_flag_for(text, PAPER_STOREYS)
}

/// [`parse_effect_flag`] in a building of `storeys` storeys (the site checked against it).
pub fn parse_effect_flag_for(text: &str, storeys: usize) -> Result<EffectSpec> {
    let bad = |why: String| SynthError::Scenario(format!("--effect {text:?}: {why}"));
    let label = Label::parse(text).map_err(|e| bad(e.to_string()))?;
    let kind = match label.kind.as_str() {
        "quadratic-damping" => "quadratic_damping",
        other => other,
    };
    let mut o = Map::new();
    o.insert("kind".into(), Value::from(kind));
    // A library kind's site as the catalogue reads it, written in the file's form.
    let location = match Kind::parse(kind) {
        Some(kind) => kind.location(
            kind.site(label.location, storeys)
                .map_err(|e| bad(e.to_string()))?,
        ),
        None => label.location,
    };
    match location {
        // A quadratic damper on a floor, to the ground: `@floor1`.
        Location::Floor(floor) => o.insert("floor".into(), Value::from(floor)),
        Location::Number(n) | Location::Storey(n) => {
            o.insert("location".into(), Value::from(vec![n]))
        }
        Location::Between(lower, upper) => {
            o.insert("location".into(), Value::from(vec![lower, upper]))
        }
    };
    for (key, value) in &label.params {
        let v = match value.parse::<f64>() {
            Ok(x) if x.is_finite() => Value::from(x),
            _ if key == "side" => Value::from(value.as_str()),
            _ => return Err(bad(format!("{key}={value:?}: not a finite number"))),
        };
        o.insert(key.clone(), v);
    }
    let origin = format!("--effect {text:?}");
    parse_effect(
        &Loc {
            origin: &origin,
            path: String::new(),
        },
        &Value::Object(o),
        storeys,
    )
}

/// `k2@8:0.85` (factor) or `k2@8=3500` (value).
pub fn parse_change_flag(text: &str) -> Result<Change> {
    let bad = |why: String| SynthError::Scenario(format!("--change {text:?}: {why}"));
    let (name, rest) = text
        .split_once('@')
        .ok_or_else(|| bad("expected PARAM@TIME:FACTOR or PARAM@TIME=VALUE".into()))?;
    let parameter = ParamName::parse(name.trim()).ok_or_else(|| {
        bad(format!(
            "unknown parameter {name:?}; expected m, c or k and a floor or storey number (m1, k2, ...)"
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
