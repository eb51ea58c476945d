//! The candidates of the shear FMU's effect library: what each one is called, which FMU
//! parameters switch it on and which are estimated, and the priors they are estimated under.

use std::collections::BTreeMap;

use serde::Serialize;

use structure::effects::discovered::{variable_name, Slot};
pub use structure::effects::{Kind, Side};
use structure::effects::{Label, Placement, Term};

use crate::twin::ParameterValue;
use crate::workflows::calibrate::Prior;

/// One effect at one place: contact across storey `at` (between floors `at − 1` and `at`, 0 the
/// ground) on one side; cubic stiffness of storey `at`; friction on floor `at`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub kind: Kind,
    /// Storey (contact, cubic) or floor (friction), from 1.
    pub at: usize,
    /// Contact only.
    pub side: Side,
}

/// What the candidates' priors are scaled by: the calibrated twin's storey stiffness, and the
/// RMS of its storey drifts, floor velocities and of the force on the record.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Scales {
    /// Per storey, storey 1 first.
    pub stiffness: Vec<f64>,
    pub drift_rms: Vec<f64>,
    /// Per floor, floor 1 first.
    pub velocity_rms: Vec<f64>,
    pub force_rms: f64,
}

impl Candidate {
    /// Every candidate of the library in a building of `storeys` storeys: contact at each
    /// storey and side, cubic per storey, friction per floor (15 for three storeys).
    pub fn library(storeys: usize) -> Vec<Candidate> {
        let mut all = Vec::new();
        for kind in Kind::ALL {
            let sides: &[Side] = if kind.has_side() {
                &Side::ALL
            } else {
                &[Side::Both]
            };
            for at in 1..=kind.sites(storeys) {
                for &side in sides {
                    all.push(Candidate { kind, at, side });
                }
            }
        }
        all
    }

    /// `contact@2-3:positive`, `cubic@2`, `friction@1`: the effect's text form
    /// ([`Label`]), as `--effect` takes it.
    pub fn label(&self) -> String {
        let mut label = Label::new(self.kind.name(), self.kind.location(self.at - 1));
        if self.kind.has_side() {
            label.params.push(("side".into(), self.side.name().into()));
        }
        label.to_string()
    }

    /// Read a candidate of a building of `storeys` storeys from its text form ([`Label`]):
    /// `contact@2-3[:both|positive|negative]` (adjacent floors, 0 the ground; side both by
    /// default; also `:side=…`), `cubic@2` (storey) and `friction@1` (floor). A candidate's
    /// other parameters are estimated, so none is given.
    pub fn parse(text: &str, storeys: usize) -> Result<Candidate, String> {
        let error = |why: String| format!("effect '{text}': {why}");
        let label = Label::parse(text).map_err(|e| error(e.to_string()))?;
        let kind = Kind::parse(&label.kind).ok_or_else(|| {
            error(format!(
                "unknown kind '{}'; expected contact@L-U[:both|positive|negative] (adjacent \
                 floors, 0 the ground), cubic@S (storey 1..{storeys}) or friction@F (floor \
                 1..{storeys})",
                label.kind
            ))
        })?;
        let mut side = Side::Both;
        for (key, value) in &label.params {
            if key != "side" {
                return Err(error(format!(
                    "'{key}' is estimated, not given; a candidate takes only contact's side"
                )));
            }
            if !kind.has_side() {
                return Err(error("only contact has a side".into()));
            }
            side = Side::parse(value).ok_or_else(|| {
                error(format!("side '{value}' is not both, positive or negative"))
            })?;
        }
        let at = kind
            .site(label.location, storeys)
            .map_err(|e| error(e.to_string()))?
            + 1;
        Ok(Candidate { kind, at, side })
    }

    /// The report's location: contact `[lower, upper]`, cubic `[storey]`, friction `[floor]`.
    pub fn location(&self) -> Vec<usize> {
        match self.kind {
            Kind::Contact => vec![self.at - 1, self.at],
            Kind::Cubic | Kind::Friction => vec![self.at],
        }
    }

    /// Where the effect sits and what its force is a function of (the library's description).
    pub fn placement(&self) -> Placement {
        self.kind.placement()
    }

    /// The FMU's name prefix of this effect's parameters.
    pub fn prefix(&self) -> String {
        self.kind.prefix(self.at - 1)
    }

    /// The parameters that switch the effect on (and pick the contact's side).
    pub fn switches(&self) -> BTreeMap<String, ParameterValue> {
        let p = self.prefix();
        let mut out = BTreeMap::new();
        out.insert(format!("{p}_enabled"), ParameterValue::Boolean(true));
        if self.kind.has_side() {
            out.insert(
                format!("{p}_side"),
                ParameterValue::Integer(self.side.code()),
            );
        }
        out
    }

    /// The estimated parameters' FMU names and short names (a report's keys), in the
    /// library's order.
    pub fn parameter_names(&self) -> Vec<(String, &'static str)> {
        let p = self.prefix();
        self.kind
            .real_params()
            .iter()
            .map(|param| (format!("{p}_{}", param.suffix), param.suffix))
            .collect()
    }

    /// The estimated parameters (FMU names, short names) and their priors.
    ///
    /// - contact: gap, log-normal around 0.7 × the storey's drift RMS (contact needs a gap the
    ///   drift reaches), a factor e per sd; stiffness, log-normal around the storey's stiffness,
    ///   a factor e² per sd.
    /// - cubic: k₃ (N/m³), normal, mean 0, sd `k / drift_rms²` (at the drift RMS the cubic force
    ///   would equal the linear one: a wide prior), either sign.
    /// - friction: force, log-normal around 5 % of the force RMS, a factor e² per sd; velocity
    ///   scale, log-normal around 10 % of the floor's velocity RMS, a factor e per sd.
    pub fn parameters(&self, scales: &Scales) -> Vec<(String, &'static str, Prior)> {
        let i = self.at - 1;
        let positive = |x: f64| if x > 0.0 && x.is_finite() { x } else { 1.0 };
        // In the order of the library's parameter list.
        let priors = match self.kind {
            Kind::Contact => vec![
                Prior::log((0.7 * positive(scales.drift_rms[i])).ln(), 1.0),
                Prior::log(positive(scales.stiffness[i]).ln(), 4.0),
            ],
            Kind::Cubic => {
                let sd = positive(scales.stiffness[i]) / positive(scales.drift_rms[i]).powi(2);
                vec![Prior::linear(0.0, sd * sd)]
            }
            Kind::Friction => vec![
                Prior::log((0.05 * positive(scales.force_rms)).ln(), 4.0),
                Prior::log((0.1 * positive(scales.velocity_rms[i])).ln(), 1.0),
            ],
        };
        self.parameter_names()
            .into_iter()
            .zip(priors)
            .map(|((name, short), prior)| (name, short, prior))
            .collect()
    }
}

impl Candidate {
    /// Starts of a fit besides its priors' means, by value. A contact's fit has optima where
    /// the contact engages rarely; a start at the prior (0.7 × the drift RMS, about the median
    /// |drift|) and random draws from a prior three times as wide can all miss them, so its
    /// starts also put the gap where |drift| exceeds it 20 % and 5 % of the time (1.3 and 2.0 ×
    /// the RMS for a Gaussian drift).
    pub fn starts_at(&self, scales: &Scales) -> Vec<BTreeMap<String, f64>> {
        let rms = scales.drift_rms[self.at - 1];
        if self.kind != Kind::Contact || !(rms > 0.0 && rms.is_finite()) {
            return Vec::new();
        }
        let gap = format!("{}_{}", self.prefix(), self.kind.real_params()[0].suffix);
        [1.3, 2.0]
            .iter()
            .map(|factor| BTreeMap::from([(gap.clone(), factor * rms)]))
            .collect()
    }
}

/// The kind of the discovered terms in the text form: `discovered@storey2`.
pub const DISCOVERED: &str = "discovered";

/// What `add-physics` switches on: an effect of the library, or terms found by discovery
/// (the shear FMU's generic `discovered` effect, all at one site).
#[derive(Clone, Debug, PartialEq)]
pub enum Addition {
    Library(Candidate),
    Discovered(Vec<Term>),
}

impl Addition {
    /// The library's label, or `discovered@storey2` / `discovered@floor1`.
    pub fn label(&self) -> String {
        match self {
            Addition::Library(c) => c.label(),
            Addition::Discovered(terms) => match terms.first() {
                Some(t) => Label::new(DISCOVERED, t.site.location()).to_string(),
                None => format!("{DISCOVERED}@none"),
            },
        }
    }

    /// The parameters that switch it on (and fix what is not estimated: a contact's side, a
    /// term's function, site and scale).
    pub fn switches(&self) -> BTreeMap<String, ParameterValue> {
        match self {
            Addition::Library(c) => c.switches(),
            Addition::Discovered(terms) => {
                let mut out = BTreeMap::new();
                for (i, t) in terms.iter().enumerate() {
                    let index = i + 1;
                    out.insert(
                        variable_name(index, Slot::Enabled),
                        ParameterValue::Boolean(true),
                    );
                    for (name, value) in t.integer_parameters(index) {
                        out.insert(name, ParameterValue::Integer(value));
                    }
                    out.insert(
                        variable_name(index, Slot::Scale),
                        ParameterValue::Real(t.scale),
                    );
                }
                out
            }
        }
    }

    /// The estimated parameters: FMU name, short name, prior. A discovered term's coefficient
    /// (short name `term1`, …) has a normal prior centred on 0 (no effect) with an sd of 10 ×
    /// the coefficient found by the regression: weak, and shrinking towards no effect.
    pub fn parameters(&self, scales: &Scales) -> Vec<(String, String, Prior)> {
        match self {
            Addition::Library(c) => c
                .parameters(scales)
                .into_iter()
                .map(|(name, short, prior)| (name, short.to_string(), prior))
                .collect(),
            Addition::Discovered(terms) => terms
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let sd = 10.0 * t.coefficient.abs();
                    (
                        variable_name(i + 1, Slot::Coefficient),
                        format!("term{}", i + 1),
                        Prior::linear(0.0, if sd > 0.0 { sd * sd } else { 1.0 }),
                    )
                })
                .collect(),
        }
    }

    /// The FMU name prefixes it occupies (one per library effect; every term's for discovery).
    pub fn prefixes(&self) -> Vec<String> {
        match self {
            Addition::Library(c) => vec![c.prefix()],
            Addition::Discovered(terms) => (1..=terms.len())
                .map(|i| format!("discovered{i}"))
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use structure::paper::STOREYS as PAPER_STOREYS;

    #[test]
    fn labels_parse_back() {
        for c in Candidate::library(PAPER_STOREYS) {
            assert_eq!(
                Candidate::parse(&c.label(), PAPER_STOREYS),
                Ok(c),
                "{}",
                c.label()
            );
        }
        assert_eq!(Candidate::library(PAPER_STOREYS).len(), 15);
        let c = Candidate::parse("contact@0-1", PAPER_STOREYS).unwrap();
        assert_eq!((c.at, c.side, c.location()), (1, Side::Both, vec![0, 1]));
        assert_eq!(c.prefix(), "contact01");
    }

    #[test]
    fn bad_effects_are_refused_with_the_reason() {
        for (text, says) in [
            ("contact@1-3", "adjacent"),
            ("contact@2-3:up", "side 'up'"),
            ("cubic@4", "1, 2 or 3"),
            ("friction@1:both", "only contact"),
            ("hysteresis@2", "unknown kind"),
            ("cubic", "expected"),
            ("friction@x", "'x' is not a floor number"),
        ] {
            let e = Candidate::parse(text, PAPER_STOREYS).unwrap_err();
            assert!(e.contains(says) && e.contains(text), "{text}: {e}");
        }
    }
}
