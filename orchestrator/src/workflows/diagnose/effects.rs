//! What a fit says of an effect: the fitted values and posterior sds by parameter name
//! ([`Estimates`]) and the effect's report from them — read by the verdict, the forward
//! selection, discovery and `add_physics`.

use std::collections::BTreeMap;

use super::{Addition, EffectName, EffectReport, Scales, TermReport};
use crate::workflows::calibrate::Calibration;

/// Fitted values and posterior sds by FMU parameter name.
pub(crate) type Estimates = BTreeMap<String, (f64, f64)>;

pub(super) fn estimates(calibration: &Calibration) -> Estimates {
    calibration
        .parameters
        .iter()
        .map(|p| (p.name.clone(), (p.value, p.sd)))
        .collect()
}

pub(super) fn effect_report(a: &Addition, fitted: &Estimates, scales: &Scales) -> EffectReport {
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
