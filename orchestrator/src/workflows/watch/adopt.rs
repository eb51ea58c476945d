//! The rules of adoption: the parameters a firm verdict of a background diagnosis sets, the
//! twin they make of the live one, where it is written, and the diagnosis alert's answer fields.
//! The watcher ([`super::watcher`]) reports the diagnosis and adopts the twin.

use super::alerts::floats;
use super::WatchError;
use crate::twin::{ParameterValue, Twin, TwinError};
use crate::workflows::diagnose::Action;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A twin the watch adopted: live from `at` (s of the stream), written to `twin`, on the
/// verdict of the diagnosis `report`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Adopted {
    pub at: f64,
    pub twin: PathBuf,
    pub verdict: String,
    pub report: PathBuf,
}

/// A diagnosis alert's answer: the diagnosis's action, reason, effects and scores, where its
/// fits started, and its report's and samples' paths.
pub(super) fn answer_fields(
    m: &mut serde_json::Map<String, Value>,
    d: &crate::workflows::diagnose::Diagnosis,
    path: &Path,
) {
    m.insert("action".into(), json!(d.action));
    m.insert("reason".into(), json!(d.reason));
    m.insert("effects".into(), json!(d.effects));
    m.insert("channels".into(), json!(d.channels));
    m.insert("nmse_before".into(), floats(&d.nmse_before));
    m.insert("nmse_after".into(), floats(&d.nmse_after));
    if let Some(at) = d.changed_at {
        // Its fits started there, from the state the twin reached on the samples before;
        // those after are the ones it scored.
        m.insert("fitted_from".into(), json!(at));
    }
    m.insert("report".into(), json!(path.display().to_string()));
    m.insert(
        "samples".into(),
        json!(path.with_extension("csv").display().to_string()),
    );
}

/// The physics parameters a firm verdict sets: a recalibration's every parameter; the
/// library effects `add_physics` names, switched on with their jointly fitted values, and the
/// physics that moved with them. None for any other verdict, and for a discovered effect (its
/// twin comes from `twin add-physics`, which refits its terms).
pub(super) fn answer(
    d: &crate::workflows::diagnose::Diagnosis,
) -> Option<Vec<(String, ParameterValue)>> {
    use crate::workflows::diagnose::Candidate;
    let real = |(name, value): (String, f64)| (name, ParameterValue::Real(value));
    match d.action {
        Action::Recalibrate => Some(
            d.recalibration
                .as_ref()?
                .parameters
                .iter()
                .map(|p| real((p.name.clone(), p.after)))
                .collect(),
        ),
        Action::AddPhysics if !d.effects.is_empty() => {
            let mut set = Vec::new();
            for e in &d.effects {
                let c = Candidate::parse(&e.name.label, structure::MAX_STOREYS).ok()?;
                set.extend(c.switches());
                for (name, short) in c.parameter_names() {
                    set.push(real((name, *e.parameters.get(short)?)));
                }
            }
            set.extend(
                d.physics_moved
                    .iter()
                    .map(|p| real((p.name.clone(), p.after))),
            );
            Some(set)
        }
        _ => None,
    }
}

/// The twin a firm verdict names ([`answer`]): `live` with those physics parameters, its noise
/// variances and posterior kept (the stream's noise did not change).
pub(super) fn answered(
    live: &Twin,
    parameters: &[(String, ParameterValue)],
) -> Result<Twin, WatchError> {
    let mut twin = live.duplicate();
    let physics = twin.component_mut(crate::twin::PHYSICS).ok_or_else(|| {
        WatchError::Twin(TwinError::Message(format!(
            "{} has no physics component",
            live.describe()
        )))
    })?;
    for (name, value) in parameters {
        physics.parameters.insert(name.clone(), value.clone());
    }
    twin.source = None;
    Ok(twin)
}

/// Where the `k`-th adopted twin goes: beside the alerts, `ALERTS.twin-k.ssp`.
pub(super) fn adopted_path(alerts: &Path, k: usize) -> PathBuf {
    let stem = alerts
        .file_stem()
        .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
    alerts.with_file_name(format!("{stem}.twin-{k}.ssp"))
}
