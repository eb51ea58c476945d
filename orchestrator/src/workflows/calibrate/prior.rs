//! Priors of calibrated parameters: Gaussian on the value or on its logarithm.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// The prior is on the value itself.
    Linear,
    /// The prior is on the natural logarithm of the value (keeps it positive).
    Log,
}

/// `N(mean, variance)` on the value (Linear) or its logarithm (Log).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    pub space: Space,
    pub mean: f64,
    pub variance: f64,
}

impl Prior {
    pub fn linear(mean: f64, variance: f64) -> Self {
        Prior {
            space: Space::Linear,
            mean,
            variance,
        }
    }
    pub fn log(mean: f64, variance: f64) -> Self {
        Prior {
            space: Space::Log,
            mean,
            variance,
        }
    }
    pub fn sd(&self) -> f64 {
        self.variance.sqrt()
    }
    /// The value from the prior's coordinate `u` (value or log value).
    pub fn value(&self, u: f64) -> f64 {
        match self.space {
            Space::Linear => u,
            Space::Log => u.exp(),
        }
    }
    /// The prior's coordinate of a value.
    pub fn coordinate(&self, value: f64) -> f64 {
        match self.space {
            Space::Linear => value,
            Space::Log => value.ln(),
        }
    }
}

/// The engineering priors of the reference paper's Table 1 for the shear model's parameters;
/// for any other positive parameter, a wide log-normal prior around its current value.
pub fn default_prior(name: &str, current: f64) -> Prior {
    let storey = |prefix: char| {
        name.len() == 2 && name.starts_with(prefix) && matches!(name.as_bytes()[1], b'1'..=b'3')
    };
    if storey('m') {
        Prior::linear(5.2, 0.5)
    } else if storey('c') {
        Prior::log(-4.605, 1.0)
    } else if storey('k') {
        Prior::linear(4021.0, 10_000.0)
    } else if current > 0.0 {
        // A factor of e (≈ 2.7) either way is one standard deviation.
        Prior::log(current.ln(), 1.0)
    } else {
        Prior::linear(current, (current.abs().max(1.0)).powi(2))
    }
}

/// Priors from a JSON file: `{"k1": {"space": "linear", "mean": 4021, "variance": 10000}, ...}`.
pub fn read_priors(path: &Path) -> Result<BTreeMap<String, Prior>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    priors_from_json(&text, &path.display().to_string())
}

/// Priors from JSON text (`read_priors`' format); `origin` names it in errors.
pub fn priors_from_json(text: &str, origin: &str) -> Result<BTreeMap<String, Prior>, String> {
    let priors: BTreeMap<String, Prior> =
        serde_json::from_str(text).map_err(|e| format!("{origin}: {e}"))?;
    for (name, p) in &priors {
        if !(p.mean.is_finite() && p.variance.is_finite() && p.variance > 0.0) {
            return Err(format!(
                "{origin}: prior of '{name}' needs a finite mean and a positive variance"
            ));
        }
    }
    Ok(priors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_one_priors_and_a_fallback() {
        assert_eq!(default_prior("m2", 5.2), Prior::linear(5.2, 0.5));
        assert_eq!(default_prior("c3", 0.01), Prior::log(-4.605, 1.0));
        assert_eq!(default_prior("k1", 4021.0), Prior::linear(4021.0, 10_000.0));
        let gap = default_prior("contact23_gap", 5e-4);
        assert_eq!(gap.space, Space::Log);
        assert!((gap.value(gap.mean) - 5e-4).abs() < 1e-15);
        assert_eq!(
            default_prior("k12", 1.0).space,
            Space::Log,
            "only k1..k3 take Table 1's stiffness prior"
        );
    }
}
