//! A second change inside the looks at a first: the structure changed again after the samples
//! a look answered on, so the next look's samples would mix two structures — the case a
//! window taken regardless of the change answered `update_data_model` for.
//!
//! The answer the last look gave (its recalibrated physics, or its effects switched on) is run
//! on the next look's samples from the first change's state, as the diagnosis fits it; its
//! residuals, normalised by their own mean square over the samples that look answered on,
//! are searched for a variance step ([`locate_change`]). A step found after those samples, at
//! which the residual's sd at least doubles on some channel, is a second change: the look
//! answers on the samples before it, and the change is looked at on its own once the first
//! answer is adopted.

use serde_json::Value;

use super::online::{locate_change, ChangePoint};
use crate::twin::data::Measurement;
use crate::twin::{ParameterValue, Twin};
use crate::workflows::diagnose::change::residuals_after;

/// The variance ratio a second change must reach on some channel: the residual's sd doubled.
const SECOND_CHANGE_RATIO: f64 = 4.0;

/// The second change in `data` after the one at `change`, for the last look's `answer` given
/// on the samples up to `answered_until` (None: none found, or the twin cannot start from a
/// state).
pub fn second_change(
    twin: &Twin,
    answer: &[(String, ParameterValue)],
    data: &Measurement,
    change: f64,
    answered_until: f64,
) -> Option<ChangePoint> {
    let (time, residuals) = residuals_after(twin, answer, data, change).ok()??;
    let m = residuals.len();
    let fitted = time.iter().filter(|&&t| t <= answered_until + 1e-9).count();
    if m == 0 || fitted < 2 || fitted >= time.len() {
        return None;
    }
    let scale: Vec<f64> = residuals
        .iter()
        .map(|r| r[..fitted].iter().map(|x| x * x).sum::<f64>() / fitted as f64)
        .collect();
    if scale.iter().any(|&s| s.is_nan() || s <= 0.0) {
        return None;
    }
    let mut u2 = Vec::with_capacity(time.len() * m);
    for k in 0..time.len() {
        u2.extend(residuals.iter().zip(&scale).map(|(r, s)| r[k] * r[k] / s));
    }
    locate_change(&time, &u2, m).filter(|c| {
        c.low > answered_until && c.variance_ratio.iter().any(|&r| r >= SECOND_CHANGE_RATIO)
    })
}

/// An answer's parameters as JSON (kept in the checkpoint).
pub fn to_json(answer: &[(String, ParameterValue)]) -> Vec<(String, Value)> {
    answer
        .iter()
        .map(|(name, value)| {
            let v = match value {
                ParameterValue::Real(x) => serde_json::json!(x),
                ParameterValue::Integer(i) => serde_json::json!(i),
                ParameterValue::Boolean(b) => serde_json::json!(b),
            };
            (name.clone(), v)
        })
        .collect()
}

/// [`to_json`] read back.
pub fn from_json(answer: &[(String, Value)]) -> Vec<(String, ParameterValue)> {
    answer
        .iter()
        .filter_map(|(name, v)| {
            let value = match v {
                Value::Bool(b) => ParameterValue::Boolean(*b),
                Value::Number(n) if n.is_i64() => ParameterValue::Integer(n.as_i64()? as i32),
                Value::Number(n) => ParameterValue::Real(n.as_f64()?),
                _ => return None,
            };
            Some((name.clone(), value))
        })
        .collect()
}
