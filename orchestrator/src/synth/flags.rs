//! The command-line forms of an effect (`--effect contact@2-3:gap=5e-4`) and a parameter
//! change (`--change k2@8:0.85`), read into the scenario's types.

use super::{Result, SynthError};
use serde_json::{Map, Value};

use super::scenario::{parse_effect, Change, ChangeHow, EffectSpec, Loc, ParamName};

/// `contact@2-3:gap=5e-4,stiffness=9000,side=both`, `cubic@2`, `friction@1:force=0.2`,
/// `hysteresis@2:stiffness=1500,yield=3e-4`, `quadratic-damping@2:coefficient=40` (storey 2,
/// or `@1-2`) and `quadratic-damping@floor1:coefficient=40` (floor 1 to the ground; the kind
/// may also be written `quadratic_damping`, as in the JSON).
pub fn parse_effect_flag(text: &str) -> Result<EffectSpec> {
    let bad = |why: String| SynthError::Scenario(format!("--effect {text:?}: {why}"));
    let (head, params) = match text.split_once(':') {
        Some((h, p)) => (h, Some(p)),
        None => (text, None),
    };
    let (kind, location) = head
        .split_once('@')
        .ok_or_else(|| bad("expected KIND@LOCATION, e.g. contact@2-3".into()))?;
    let kind = match kind.trim() {
        "quadratic-damping" => "quadratic_damping",
        other => other,
    };
    let mut o = Map::new();
    o.insert("kind".into(), Value::from(kind));
    // A quadratic damper on a floor, to the ground: `@floor1`.
    if let Some(floor) = location.trim().strip_prefix("floor") {
        let floor = floor
            .parse::<u64>()
            .map_err(|_| bad(format!("location {location:?} is not floorN")))?;
        o.insert("floor".into(), Value::from(floor));
    } else {
        let floors: Vec<Value> = location
            .split('-')
            .map(|p| {
                p.trim()
                    .parse::<u64>()
                    .map(Value::from)
                    .map_err(|_| bad(format!("location {location:?} is not N or N-M")))
            })
            .collect::<Result<_>>()?;
        o.insert("location".into(), Value::Array(floors));
    }
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
    let bad = |why: String| SynthError::Scenario(format!("--change {text:?}: {why}"));
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
