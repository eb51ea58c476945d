//! Priors of calibrated parameters: Gaussian on the value or on its logarithm.

use std::collections::BTreeMap;
use std::path::Path;

use ::structure::Structure;
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
    use ::structure::paper;
    // A floor or storey the rig has: m1..m3, c1..c3, k1..k3.
    let storey = |prefix: char| {
        family(name) == Some(prefix)
            && name[1..]
                .parse::<usize>()
                .is_ok_and(|i| i <= paper::STOREYS)
    };
    if storey('m') {
        Prior::linear(paper::MASS, 0.5)
    } else if storey('c') {
        Prior::log(paper::LOG_DAMPING, 1.0)
    } else if storey('k') {
        Prior::linear(paper::STIFFNESS, 10_000.0)
    } else if current > 0.0 {
        // A factor of e (≈ 2.7) either way is one standard deviation.
        Prior::log(current.ln(), 1.0)
    } else {
        Prior::linear(current, (current.abs().max(1.0)).powi(2))
    }
}

/// Default prior widths of a structure given by its nominal (`twin init --nominal`), each
/// parameter's prior centred on its nominal value: a floor's mass is known from the drawings to
/// about 10 % (Gaussian, sd 10 % of the nominal); a storey's stiffness to about 25 % (log-normal,
/// sd 0.25 of the log); a storey's damping hardly at all (log-normal, sd 1 of the log: a factor
/// e either way, as Table 1). The paper's rig keeps Table 1 ([`default_prior`]).
pub const NOMINAL_MASS_RELATIVE_SD: f64 = 0.10;
pub const NOMINAL_DAMPING_LOG_SD: f64 = 1.0;
pub const NOMINAL_STIFFNESS_LOG_SD: f64 = 0.25;

/// The default prior of a structure's parameter `m<i>`, `c<i>` or `k<i>` (None for any other
/// name or a floor it lacks): Table 1 on the paper's rig, otherwise centred on the nominal with
/// the widths above.
pub fn structure_prior(structure: &Structure, name: &str) -> Option<Prior> {
    let nominal = structure.get(name)?;
    if ::structure::paper::is_paper_rig(structure) {
        return Some(default_prior(name, nominal));
    }
    Some(match family(name)? {
        'm' => Prior::linear(nominal, (NOMINAL_MASS_RELATIVE_SD * nominal).powi(2)),
        'c' => Prior::log(
            nominal.max(f64::MIN_POSITIVE).ln(),
            NOMINAL_DAMPING_LOG_SD.powi(2),
        ),
        _ => Prior::log(nominal.ln(), NOMINAL_STIFFNESS_LOG_SD.powi(2)),
    })
}

/// `m`, `c` or `k` for `m<i>`, `c<i>`, `k<i>` (i ≥ 1, no leading zero).
fn family(name: &str) -> Option<char> {
    let mut chars = name.chars();
    let f = chars.next().filter(|c| matches!(c, 'm' | 'c' | 'k'))?;
    let digits = chars.as_str();
    (!digits.is_empty() && !digits.starts_with('0') && digits.bytes().all(|b| b.is_ascii_digit()))
        .then_some(f)
}

/// One entry of a priors file (see [`PriorSpec`]).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorEntry {
    /// `linear` or `log`; by default the parameter's default prior's.
    pub space: Option<Space>,
    /// The centre in the parameter's own unit (by default its nominal).
    pub value: Option<f64>,
    /// The centre in the prior's coordinate: the value, or its natural log for `log`.
    pub mean: Option<f64>,
    /// The width in the prior's coordinate; exactly one of `sd`, `variance`, `relative_sd`.
    pub sd: Option<f64>,
    pub variance: Option<f64>,
    /// The width as a fraction of the centre (`linear`: sd = relative_sd · centre; `log`: the sd
    /// of the log, which is the relative sd for small widths).
    pub relative_sd: Option<f64>,
}

/// A priors file, `--priors P.json` of `twin init` and `twin calibrate`: an object whose keys are
/// a family (`m`, `c`, `k`: every floor's mass, every storey's damping or stiffness) or one
/// parameter (`k3`, or any real parameter of the physics FMU such as `contact23_gap`), each with
/// [`PriorEntry`]'s fields: `{"m": {"relative_sd": 0.05}, "k": {"space": "log", "sd": 0.4},
/// "k3": {"value": 3900, "relative_sd": 0.1}}`. A parameter's own key overrides its family's;
/// a family takes no centre (each parameter is centred on its own nominal). The older form,
/// `{"k1": {"space": "linear", "mean": 4021, "variance": 10000}}`, is this format too.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PriorSpec {
    /// The file (or text) it came from, for messages.
    pub origin: String,
    pub entries: BTreeMap<String, PriorEntry>,
}

/// Priors from a JSON file ([`PriorSpec`]'s format), checked whole.
pub fn read_priors(path: &Path) -> Result<PriorSpec, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    priors_from_json(&text, &path.display().to_string())
}

/// Priors from JSON text ([`read_priors`]' format); `origin` names it in errors, each error
/// naming its key.
pub fn priors_from_json(text: &str, origin: &str) -> Result<PriorSpec, String> {
    let raw = priors_object(text, origin)?;
    let mut entries = BTreeMap::new();
    for (key, value) in raw {
        let entry = prior_entry(&key, value)
            .map_err(|message| format!("{origin}: key '{key}': {message}"))?;
        entries.insert(key, entry);
    }
    Ok(PriorSpec {
        origin: origin.to_owned(),
        entries,
    })
}

/// The priors file's object: each key with its entry, still as JSON.
fn priors_object(text: &str, origin: &str) -> Result<BTreeMap<String, serde_json::Value>, String> {
    serde_json::from_str(text).map_err(|e| {
        format!(
            "{origin}: {e}; expected an object of priors by family (m, c, k) or parameter, \
             e.g. {{\"k\": {{\"relative_sd\": 0.25}}}}"
        )
    })
}

/// The entry of `key`, checked: its width, its centre, and no centre for a family (the error
/// without the key).
fn prior_entry(key: &str, value: serde_json::Value) -> Result<PriorEntry, String> {
    let entry: PriorEntry = serde_json::from_value(value)
        .map_err(|e| format!("{e} (fields: space, value, mean, sd, variance, relative_sd)"))?;
    check_width(&entry)?;
    check_centre(&entry)?;
    let is_family = matches!(key, "m" | "c" | "k");
    if is_family && (entry.value.is_some() || entry.mean.is_some()) {
        return Err(
            "a family's priors are centred on each parameter's nominal; give a centre per \
             parameter (e.g. 'k2')"
                .into(),
        );
    }
    Ok(entry)
}

/// Exactly one width, finite and positive.
fn check_width(entry: &PriorEntry) -> Result<(), String> {
    let widths = [entry.sd, entry.variance, entry.relative_sd];
    match widths.iter().flatten().count() {
        1 => {}
        0 => return Err("no width: give one of sd, variance, relative_sd".into()),
        _ => return Err("more than one width: give one of sd, variance, relative_sd".into()),
    }
    if let Some(w) = widths.iter().flatten().next() {
        if !(w.is_finite() && *w > 0.0) {
            return Err(format!("the width {w} is not finite and positive"));
        }
    }
    Ok(())
}

/// At most one centre, finite; a value positive for a log-space prior.
fn check_centre(entry: &PriorEntry) -> Result<(), String> {
    if entry.value.is_some() && entry.mean.is_some() {
        return Err("both value and mean: give the centre once".into());
    }
    if let Some(m) = entry.value.or(entry.mean) {
        if !m.is_finite() {
            return Err(format!("the centre {m} is not finite"));
        }
    }
    if let Some(v) = entry.value {
        if entry.space == Some(Space::Log) && v <= 0.0 {
            return Err(format!(
                "value {v}: a log-space prior needs a positive value"
            ));
        }
    }
    Ok(())
}

impl PriorSpec {
    /// Whether every key names a family or a parameter of `structure` (`k7` of a five-storey
    /// building is refused); other names are left to the FMU when `strict` is false.
    pub fn check(&self, structure: &Structure, strict: bool) -> Result<(), String> {
        for key in self.entries.keys() {
            let structural = matches!(key.as_str(), "m" | "c" | "k") || family(key).is_some();
            if family(key).is_some() && structure.get(key).is_none() {
                return Err(format!(
                    "{}: key '{key}': the structure has floors and storeys 1 to {}",
                    self.origin,
                    structure.storeys()
                ));
            }
            if strict && !structural {
                return Err(format!(
                    "{}: key '{key}' is neither a family (m, c, k) nor a parameter m1..m{n}, \
                     c1..c{n}, k1..k{n}",
                    self.origin,
                    n = structure.storeys()
                ));
            }
        }
        Ok(())
    }

    /// The prior this file gives `name` (None when it says nothing of it): its own key, else its
    /// family's, completed from `default` (the structure's default prior, or the one around the
    /// current value) for what the entry leaves out.
    pub fn prior_for(&self, name: &str, default: Prior) -> Option<Result<Prior, String>> {
        let (key, entry) = self.entries.get_key_value(name).or_else(|| {
            family(name).and_then(|f| self.entries.get_key_value(f.to_string().as_str()))
        })?;
        let space = entry.space.unwrap_or(default.space);
        let centre_value = default.value(default.mean);
        let mean = match (entry.mean, entry.value) {
            (Some(m), _) => m,
            (None, Some(v)) => Prior {
                space,
                mean: 0.0,
                variance: 1.0,
            }
            .coordinate(v),
            (None, None) => Prior {
                space,
                mean: 0.0,
                variance: 1.0,
            }
            .coordinate(centre_value),
        };
        if !mean.is_finite() {
            return Some(Err(format!(
                "{}: key '{key}': the centre of {name}'s {space:?} prior is not finite (the \
                 nominal {centre_value})",
                self.origin
            )));
        }
        let centre = Prior {
            space,
            mean,
            variance: 1.0,
        }
        .value(mean);
        let variance = match (entry.sd, entry.variance, entry.relative_sd) {
            (Some(sd), _, _) => sd * sd,
            (_, Some(v), _) => v,
            (_, _, Some(r)) => match space {
                Space::Linear => (r * centre).powi(2),
                Space::Log => r * r,
            },
            _ => unreachable!("checked on reading: one width"),
        };
        if !(variance.is_finite() && variance > 0.0) {
            return Some(Err(format!(
                "{}: key '{key}': {name}'s prior has no positive width (centre {centre})",
                self.origin
            )));
        }
        Some(Ok(Prior {
            space,
            mean,
            variance,
        }))
    }
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

    #[test]
    fn a_priors_file_by_family_and_by_parameter_around_the_nominal() {
        let s = Structure::uniform(5, 6.0, 2.0, 5000.0, ::structure::Excitation::Base);
        let spec = priors_from_json(
            r#"{"k": {"relative_sd": 0.3}, "k2": {"value": 4000, "sd": 0.1},
                "m": {"space": "linear", "relative_sd": 0.05},
                "c1": {"space": "log", "mean": -1.0, "variance": 4.0}}"#,
            "P.json",
        )
        .unwrap();
        spec.check(&s, true).unwrap();
        let prior = |name: &str| {
            spec.prior_for(name, structure_prior(&s, name).unwrap())
                .unwrap()
                .unwrap()
        };
        // The family around each nominal, in the default space (log for k).
        assert_eq!(prior("k4"), Prior::log(5000f64.ln(), 0.09));
        assert_eq!(prior("k2"), Prior::log(4000f64.ln(), 0.010000000000000002));
        let m3 = prior("m3");
        assert_eq!(m3.space, Space::Linear);
        assert!((m3.mean - 6.0).abs() < 1e-12 && (m3.sd() - 0.3).abs() < 1e-12);
        assert_eq!(prior("c1"), Prior::log(-1.0, 4.0));
        assert!(spec
            .prior_for("c2", structure_prior(&s, "c2").unwrap())
            .is_none());
        // Without a file: centred on the nominal with the documented widths.
        assert_eq!(
            structure_prior(&s, "k1").unwrap(),
            Prior::log(5000f64.ln(), NOMINAL_STIFFNESS_LOG_SD.powi(2))
        );
        // The paper's rig keeps Table 1.
        let paper = Structure::default();
        assert_eq!(
            structure_prior(&paper, "k2").unwrap(),
            Prior::linear(4021.0, 10_000.0)
        );
        let seven = priors_from_json(r#"{"k7": {"sd": 1}}"#, "P.json").unwrap();
        let e = seven.check(&s, false).unwrap_err();
        assert!(
            e.contains("P.json: key 'k7'") && e.contains("1 to 5"),
            "{e}"
        );
    }
}
