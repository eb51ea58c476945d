//! The discovered terms as the FMU carries them (the functions, sites and terms are the
//! catalogue's, `structure::effects::discovered`): [`MAX_TERMS`] slots, each a term with its
//! `enabled` switch, the function, the site and the numbers as FMU parameters.
//!
//! Why its own storage and not a [`super::Library`]: a library has an effect at each of a fixed
//! set of locations, the location given by the value reference, and each effect one law. A
//! discovered term chooses its law (an Integer) and its site (two Integers) through parameters,
//! so it has three integer parameters where a library slot has two, and its locations are
//! terms 1..=6, not storeys or floors. [`Discovered`] keeps the six terms with their own
//! value-reference layout ([`DISCOVERED_BASE_VR`] + 10·(term − 1) + slot).

use fmi2::{ModelError, Variable};
use serde::{Deserialize, Serialize};
use structure::effects::InvalidParameter;

pub use structure::effects::discovered::{
    check_coefficient, check_scale, invalid, variable_name, Function, Site, Slot, Term,
    DEFAULT_SCALE, PLACEMENT_FLOOR, PLACEMENT_STOREY,
};

/// How many discovered terms the FMU carries.
pub const MAX_TERMS: usize = 6;

/// First value reference of the discovered terms: term `i` (1-based) owns
/// `DISCOVERED_BASE_VR + 10·(i − 1) + slot`, slots as in [`Slot`].
pub const DISCOVERED_BASE_VR: u32 = 400;
const SLOTS_PER_TERM: u32 = 10;

/// The value reference of a term's parameter, `term` 1-based.
pub fn value_reference(term: usize, slot: Slot) -> u32 {
    DISCOVERED_BASE_VR + SLOTS_PER_TERM * (term as u32 - 1) + slot as u32
}

/// A catalogue error as the FMU reports it.
fn refused(e: InvalidParameter) -> ModelError {
    ModelError::InvalidValue {
        name: e.name,
        reason: e.reason,
    }
}

/// The FMU's discovered terms: six slots, each with its `enabled` switch.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Discovered {
    enabled: [bool; MAX_TERMS],
    terms: [Term; MAX_TERMS],
}

/// A slot's term at the start values: `0·x` at storey 1, scale [`DEFAULT_SCALE`].
const START_TERM: Term = Term {
    function: Function::X,
    site: Site::Storey(1),
    coefficient: 0.0,
    scale: DEFAULT_SCALE,
};

impl Default for Discovered {
    fn default() -> Self {
        Discovered {
            enabled: [false; MAX_TERMS],
            terms: [START_TERM; MAX_TERMS],
        }
    }
}

impl Discovered {
    /// The variables of the six terms, for the variable table of a building of `storeys`
    /// storeys.
    pub fn variables(storeys: usize) -> Vec<Variable> {
        let codes = Function::ALL
            .iter()
            .map(|f| format!("{} {}", f.code(), f.name()))
            .collect::<Vec<_>>()
            .join("; ");
        let mut vars = Vec::new();
        for i in 1..=MAX_TERMS {
            let what = format!("discovered term {i}");
            vars.push(
                Variable::boolean_parameter(
                    &variable_name(i, Slot::Enabled),
                    value_reference(i, Slot::Enabled),
                    false,
                )
                .describe(&format!(
                    "{what}: switched on; the term adds coefficient·f(x, v) to g"
                )),
            );
            vars.push(
                Variable::integer_parameter(
                    &variable_name(i, Slot::Function),
                    value_reference(i, Slot::Function),
                    START_TERM.function.code(),
                )
                .min(1.0)
                .max(f64::from(Function::LAST_CODE))
                .describe(&format!(
                    "{what}: the function f of the site's x and v (s = the scale): {codes}"
                )),
            );
            vars.push(
                Variable::integer_parameter(
                    &variable_name(i, Slot::Placement),
                    value_reference(i, Slot::Placement),
                    START_TERM.site.placement_code(),
                )
                .min(0.0)
                .max(1.0)
                .describe(&format!(
                    "{what}: 0 a storey (x its drift, v its drift rate; the force resists a positive drift), 1 a floor (x its displacement, v its velocity; the force acts on the floor against them)"
                )),
            );
            vars.push(
                Variable::integer_parameter(
                    &variable_name(i, Slot::At),
                    value_reference(i, Slot::At),
                    START_TERM.site.at() as i32,
                )
                .min(1.0)
                .max(storeys as f64)
                .describe(&format!("{what}: the storey or floor, 1..{storeys}")),
            );
            let mut coefficient = Variable::real_parameter(
                &variable_name(i, Slot::Coefficient),
                value_reference(i, Slot::Coefficient),
                "",
                START_TERM.coefficient,
            )
            .describe(&format!(
                "{what}: coefficient, in N per unit of the function (positive resists)"
            ));
            coefficient.unit = None;
            vars.push(coefficient);
            let mut scale = Variable::real_parameter(
                &variable_name(i, Slot::Scale),
                value_reference(i, Slot::Scale),
                "",
                START_TERM.scale,
            )
            .min(0.0)
            .describe(&format!(
                "{what}: scale s > 0 of tanh(v/s) (m/s) and of the ramps (m); unused by the other functions"
            ));
            scale.unit = None;
            vars.push(scale);
        }
        vars
    }

    /// (term index 1-based, slot) of a value reference of the discovered terms, if it is one.
    fn locate(vr: u32) -> Option<(usize, Slot)> {
        let offset = vr.checked_sub(DISCOVERED_BASE_VR)?;
        let index = (offset / SLOTS_PER_TERM) as usize;
        if index >= MAX_TERMS {
            return None;
        }
        Some((index + 1, Slot::from_index(offset % SLOTS_PER_TERM)?))
    }

    pub fn owns(vr: u32) -> bool {
        Self::locate(vr).is_some()
    }

    pub fn get_real(&self, vr: u32) -> Option<f64> {
        let (i, slot) = Self::locate(vr)?;
        let term = &self.terms[i - 1];
        match slot {
            Slot::Coefficient => Some(term.coefficient),
            Slot::Scale => Some(term.scale),
            _ => None,
        }
    }

    pub fn set_real(&mut self, vr: u32, value: f64) -> Option<Result<(), ModelError>> {
        let (i, slot) = Self::locate(vr)?;
        let term = &mut self.terms[i - 1];
        Some(match slot {
            Slot::Coefficient => check_coefficient(i, value)
                .map(|()| term.coefficient = value)
                .map_err(refused),
            Slot::Scale => check_scale(i, value)
                .map(|()| term.scale = value)
                .map_err(refused),
            _ => return None,
        })
    }

    pub fn get_integer(&self, vr: u32) -> Option<i32> {
        let (i, slot) = Self::locate(vr)?;
        let term = &self.terms[i - 1];
        match slot {
            Slot::Function => Some(term.function.code()),
            Slot::Placement => Some(term.site.placement_code()),
            Slot::At => Some(term.site.at() as i32),
            _ => None,
        }
    }

    /// Set an integer of a term, the site checked against a building of `storeys` storeys.
    pub fn set_integer(
        &mut self,
        vr: u32,
        value: i32,
        storeys: usize,
    ) -> Option<Result<(), ModelError>> {
        let (i, slot) = Self::locate(vr)?;
        let term = &mut self.terms[i - 1];
        let result = match slot {
            Slot::Function => match Function::from_code(value) {
                Some(function) => {
                    term.function = function;
                    Ok(())
                }
                None => Err(refused(invalid(
                    i,
                    slot,
                    format!(
                        "{value} is not a function code (1..={})",
                        Function::LAST_CODE
                    ),
                ))),
            },
            Slot::Placement => match Site::from_codes(value, term.site.at() as i32, storeys) {
                Some(site) => {
                    term.site = site;
                    Ok(())
                }
                None => Err(refused(invalid(
                    i,
                    slot,
                    format!("{value} is neither 0 (storey) nor 1 (floor)"),
                ))),
            },
            Slot::At => match Site::from_codes(term.site.placement_code(), value, storeys) {
                Some(site) => {
                    term.site = site;
                    Ok(())
                }
                None => Err(refused(invalid(
                    i,
                    slot,
                    format!("{value} is outside [1, {storeys}]"),
                ))),
            },
            _ => return None,
        };
        Some(result)
    }

    pub fn get_boolean(&self, vr: u32) -> Option<bool> {
        match Self::locate(vr)? {
            (i, Slot::Enabled) => Some(self.enabled[i - 1]),
            _ => None,
        }
    }

    pub fn set_boolean(&mut self, vr: u32, value: bool) -> Option<()> {
        match Self::locate(vr)? {
            (i, Slot::Enabled) => {
                self.enabled[i - 1] = value;
                Some(())
            }
            _ => None,
        }
    }

    pub fn any_enabled(&self) -> bool {
        self.enabled.iter().any(|&e| e)
    }

    /// The enabled terms.
    pub fn enabled_terms(&self) -> impl Iterator<Item = &Term> {
        self.terms
            .iter()
            .zip(self.enabled)
            .filter_map(|(term, on)| on.then_some(term))
    }

    /// Replace every term: `terms` (at most [`MAX_TERMS`], each valid) in slots 1.., switched
    /// on; the other slots off and at their start values. Nothing changes on an error.
    pub fn set_terms(&mut self, terms: &[Term], storeys: usize) -> Result<(), ModelError> {
        if terms.len() > MAX_TERMS {
            return Err(ModelError::InvalidValue {
                name: "discovered terms".into(),
                reason: format!("{} terms, at most {MAX_TERMS}", terms.len()),
            });
        }
        for (i, term) in terms.iter().enumerate() {
            term.validate(i + 1, storeys).map_err(refused)?;
        }
        *self = Discovered::default();
        for (i, term) in terms.iter().enumerate() {
            self.terms[i] = *term;
            self.enabled[i] = true;
        }
        Ok(())
    }

    #[inline]
    pub fn add_forces(&self, y: &[f64], v: &[f64], g: &mut [f64]) {
        for term in self.enabled_terms() {
            term.add_force(y, v, g);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expect_refused(result: Option<Result<(), ModelError>>, name: &str) {
        match result {
            Some(Err(error)) => {
                let message = error.to_string();
                assert!(message.contains(name), "{message} should name {name}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }

    #[test]
    fn bad_values_are_refused_with_the_variable_name_and_change_nothing() {
        let mut d = Discovered::default();
        let vr = |term, slot| value_reference(term, slot);
        for code in [0, -1, 14] {
            expect_refused(
                d.set_integer(vr(2, Slot::Function), code, 3),
                "discovered2_function",
            );
        }
        for at in [0, 4, -1] {
            expect_refused(d.set_integer(vr(3, Slot::At), at, 3), "discovered3_at");
        }
        expect_refused(
            d.set_integer(vr(1, Slot::Placement), 2, 3),
            "discovered1_placement",
        );
        for scale in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
            expect_refused(d.set_real(vr(6, Slot::Scale), scale), "discovered6_scale");
        }
        for c in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            expect_refused(
                d.set_real(vr(4, Slot::Coefficient), c),
                "discovered4_coefficient",
            );
        }
        assert_eq!(d, Discovered::default());
        let bad = Term::new(Function::X, Site::Floor(4), 1.0);
        let err = d.set_terms(&[Term::new(Function::X, Site::Floor(1), 1.0), bad], 3);
        assert!(err
            .expect_err("refused")
            .to_string()
            .contains("discovered2_at"));
        let err = d.set_terms(
            &[Term {
                scale: 0.0,
                ..Term::new(Function::TanhV, Site::Floor(1), 1.0)
            }],
            3,
        );
        assert!(err
            .expect_err("refused")
            .to_string()
            .contains("discovered1_scale"));
        let err = d.set_terms(&[Term::new(Function::X, Site::Floor(1), 1.0); 7], 3);
        assert!(err.is_err());
        assert_eq!(d, Discovered::default());
    }

    #[test]
    fn values_set_by_reference_read_back_and_make_the_term() {
        let mut d = Discovered::default();
        let vr = |slot| value_reference(5, slot);
        assert_eq!(d.set_boolean(vr(Slot::Enabled), true), Some(()));
        assert!(matches!(
            d.set_integer(vr(Slot::Function), 7, 3),
            Some(Ok(()))
        ));
        assert!(matches!(d.set_integer(vr(Slot::At), 2, 3), Some(Ok(()))));
        assert!(matches!(
            d.set_integer(vr(Slot::Placement), 1, 3),
            Some(Ok(()))
        ));
        assert!(matches!(
            d.set_real(vr(Slot::Coefficient), -3.5),
            Some(Ok(()))
        ));
        assert!(matches!(d.set_real(vr(Slot::Scale), 2e-3), Some(Ok(()))));
        assert_eq!(d.get_boolean(vr(Slot::Enabled)), Some(true));
        assert_eq!(d.get_integer(vr(Slot::Function)), Some(7));
        assert_eq!(d.get_integer(vr(Slot::Placement)), Some(1));
        assert_eq!(d.get_integer(vr(Slot::At)), Some(2));
        assert_eq!(d.get_real(vr(Slot::Coefficient)), Some(-3.5));
        assert_eq!(d.get_real(vr(Slot::Scale)), Some(2e-3));
        let terms: Vec<Term> = d.enabled_terms().copied().collect();
        assert_eq!(
            terms,
            [Term {
                function: Function::VAbsV,
                site: Site::Floor(2),
                coefficient: -3.5,
                scale: 2e-3
            }]
        );
        // Wrong type for a slot, or outside the block: not ours.
        assert_eq!(d.get_real(vr(Slot::Function)), None);
        assert_eq!(d.get_integer(vr(Slot::Coefficient)), None);
        assert_eq!(d.get_boolean(vr(Slot::Scale)), None);
        assert_eq!(d.get_real(DISCOVERED_BASE_VR + 6), None);
        assert!(!Discovered::owns(DISCOVERED_BASE_VR + 60));
        assert!(!Discovered::owns(DISCOVERED_BASE_VR - 1));
        // The parameter lists name the variables the table has.
        let names: Vec<String> = Discovered::variables(3)
            .into_iter()
            .map(|v| v.name)
            .collect();
        for (name, _) in terms[0].integer_parameters(5) {
            assert!(names.contains(&name), "{name}");
        }
        for (name, _) in terms[0].real_parameters(5) {
            assert!(names.contains(&name), "{name}");
        }
        assert_eq!(names.len(), 6 * MAX_TERMS);
    }
}
