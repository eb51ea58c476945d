//! The optional-effect library `g(y, ẏ)` as the FMU carries it: its variables, value
//! references and storage. The kinds themselves (their parameters, force laws and site names)
//! are the catalogue in `structure::effects`; adding a kind is a file there, one field in
//! [`Effects`] and its line in `Effects::all_variables` / the dispatch below.
//! The exception is [`discovered`]: up to six generic terms `coefficient · f(x, v)` whose
//! function and site are parameters too, for the forces a diagnosis finds by regression.
//!
//! Sign convention: an effect adds to `g`, the left-hand side of `M ÿ + C ẏ + K y + g = φ u`, so
//! a restoring force is positive along the displacement that causes it.

pub mod discovered;

use fmi2::{ModelError, Variable};
use serde::{Deserialize, Serialize};
use structure::building::PAPER_STOREYS;

pub use discovered::{Discovered, MAX_TERMS};
pub use structure::effects::{
    add_storey_force, contact, cubic, drift, friction, kind, Contact, Cubic, Effect, Friction,
    Function, Kind, Law, Placement, RealParam, Side, Site, Term,
};

/// The storeys of the FMU's building (its floors 1..N, ground excluded).
pub const STOREYS: usize = PAPER_STOREYS;

/// Displacements and velocities of floors 1..N (ground excluded).
pub type Floors = [f64; STOREYS];

/// Value-reference layout of a library: base + 10·location + slot, where slot 0 is the `enabled`
/// Boolean, 1..=7 the reals and 8..=9 the integers.
const SLOTS_PER_LOCATION: u32 = 10;
const FIRST_REAL_SLOT: u32 = 1;
const FIRST_INTEGER_SLOT: u32 = 8;

/// One effect kind at each of its locations, each with its own `enabled` switch.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Library<E> {
    base_vr: u32,
    enabled: Vec<bool>,
    effects: Vec<E>,
}

impl<E: Effect> Library<E> {
    pub fn new(base_vr: u32) -> Self {
        Library {
            base_vr,
            enabled: vec![false; E::sites(STOREYS)],
            effects: (0..E::sites(STOREYS)).map(E::at_start).collect(),
        }
    }

    pub fn variables(base_vr: u32) -> Vec<Variable> {
        let mut vars = Vec::new();
        for location in 0..E::sites(STOREYS) {
            let prefix = E::prefix(location);
            let vr0 = base_vr + SLOTS_PER_LOCATION * location as u32;
            vars.push(
                Variable::boolean_parameter(&format!("{prefix}_enabled"), vr0, false)
                    .describe(&format!("{} {}: switched on", E::KIND, E::where_(location))),
            );
            for (i, p) in E::real_params().iter().enumerate() {
                let mut var = Variable::real_parameter(
                    &format!("{prefix}_{}", p.suffix),
                    vr0 + FIRST_REAL_SLOT + i as u32,
                    p.unit,
                    p.start,
                )
                .describe(&format!(
                    "{} {}: {}",
                    E::KIND,
                    E::where_(location),
                    p.description
                ));
                if p.min > f64::MIN {
                    var = var.min(p.min);
                }
                vars.push(var);
            }
            for (i, (suffix, start, min, max, description)) in
                E::integer_params().iter().enumerate()
            {
                vars.push(
                    Variable::integer_parameter(
                        &format!("{prefix}_{suffix}"),
                        vr0 + FIRST_INTEGER_SLOT + i as u32,
                        *start,
                    )
                    .min(f64::from(*min))
                    .max(f64::from(*max))
                    .describe(&format!(
                        "{} {}: {}",
                        E::KIND,
                        E::where_(location),
                        description
                    )),
                );
            }
        }
        vars
    }

    /// (location, slot) of a value reference of this library, if it is one.
    fn locate(&self, vr: u32) -> Option<(usize, u32)> {
        let offset = vr.checked_sub(self.base_vr)?;
        let location = (offset / SLOTS_PER_LOCATION) as usize;
        (location < E::sites(STOREYS)).then_some((location, offset % SLOTS_PER_LOCATION))
    }

    pub fn owns(&self, vr: u32) -> bool {
        self.locate(vr).is_some()
    }

    pub fn get_real(&self, vr: u32) -> Option<f64> {
        let (location, slot) = self.locate(vr)?;
        let index = slot.checked_sub(FIRST_REAL_SLOT)? as usize;
        (index < E::real_params().len()).then(|| self.effects[location].real(index))
    }

    pub fn set_real(&mut self, vr: u32, value: f64) -> Option<Result<(), ModelError>> {
        let (location, slot) = self.locate(vr)?;
        let index = slot.checked_sub(FIRST_REAL_SLOT)? as usize;
        let p = E::real_params().get(index)?;
        let ok = if p.strictly {
            value > p.min
        } else {
            value >= p.min
        };
        if !ok {
            return Some(Err(ModelError::InvalidValue {
                name: format!("{}_{}", E::prefix(location), p.suffix),
                reason: format!(
                    "{value} must be {} {}",
                    if p.strictly { ">" } else { "≥" },
                    p.min
                ),
            }));
        }
        self.effects[location].set_real(index, value);
        Some(Ok(()))
    }

    pub fn get_integer(&self, vr: u32) -> Option<i32> {
        let (location, slot) = self.locate(vr)?;
        let index = slot.checked_sub(FIRST_INTEGER_SLOT)? as usize;
        (index < E::integer_params().len()).then(|| self.effects[location].integer(index))
    }

    pub fn set_integer(&mut self, vr: u32, value: i32) -> Option<Result<(), ModelError>> {
        let (location, slot) = self.locate(vr)?;
        let index = slot.checked_sub(FIRST_INTEGER_SLOT)? as usize;
        let (suffix, _, min, max, _) = E::integer_params().get(index)?;
        if value < *min || value > *max {
            return Some(Err(ModelError::InvalidValue {
                name: format!("{}_{suffix}", E::prefix(location)),
                reason: format!("{value} is outside [{min}, {max}]"),
            }));
        }
        self.effects[location].set_integer(index, value);
        Some(Ok(()))
    }

    pub fn get_boolean(&self, vr: u32) -> Option<bool> {
        let (location, slot) = self.locate(vr)?;
        (slot == 0).then(|| self.enabled[location])
    }

    pub fn set_boolean(&mut self, vr: u32, value: bool) -> Option<()> {
        let (location, slot) = self.locate(vr)?;
        (slot == 0).then(|| self.enabled[location] = value)
    }

    pub fn any_enabled(&self) -> bool {
        self.enabled.iter().any(|&e| e)
    }

    #[inline]
    pub fn add_forces(&self, y: &Floors, v: &Floors, g: &mut Floors) {
        for (location, effect) in self.effects.iter().enumerate() {
            if self.enabled[location] {
                effect.add_force(location, y, v, g);
            }
        }
    }

    /// Direct access, for tests and the synthetic structure.
    pub fn effect_mut(&mut self, location: usize) -> &mut E {
        &mut self.effects[location]
    }
    pub fn enable(&mut self, location: usize, on: bool) {
        self.enabled[location] = on;
    }
    pub fn is_enabled(&self, location: usize) -> bool {
        self.enabled[location]
    }
    pub fn effect(&self, location: usize) -> &E {
        &self.effects[location]
    }
}

/// Up to two switch values per contact location and one per discovered ramp term.
pub const MAX_SWITCHES: usize = 2 * STOREYS + MAX_TERMS;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Switches {
    pub values: [f64; MAX_SWITCHES],
    pub len: usize,
}

/// Every effect kind of the library.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Effects {
    pub contact: Library<Contact>,
    pub cubic: Library<Cubic>,
    pub friction: Library<Friction>,
    /// The generic terms of a diagnosis (`discovered{1..6}_*`); its own layout, see
    /// [`discovered`].
    pub discovered: Discovered,
}

pub const CONTACT_BASE_VR: u32 = 100;
pub const CUBIC_BASE_VR: u32 = 200;
pub const FRICTION_BASE_VR: u32 = 300;
pub use discovered::DISCOVERED_BASE_VR;

impl Default for Effects {
    fn default() -> Self {
        Effects {
            contact: Library::new(CONTACT_BASE_VR),
            cubic: Library::new(CUBIC_BASE_VR),
            friction: Library::new(FRICTION_BASE_VR),
            discovered: Discovered::default(),
        }
    }
}

impl Effects {
    pub fn all_variables() -> Vec<Variable> {
        let mut vars = Library::<Contact>::variables(CONTACT_BASE_VR);
        vars.extend(Library::<Cubic>::variables(CUBIC_BASE_VR));
        vars.extend(Library::<Friction>::variables(FRICTION_BASE_VR));
        vars.extend(Discovered::variables());
        vars
    }

    /// Switch on the effect `law` at `location` (0-based storey or floor).
    pub fn switch_on(&mut self, location: usize, law: Law) {
        match law {
            Law::Contact(e) => {
                *self.contact.effect_mut(location) = e;
                self.contact.enable(location, true);
            }
            Law::Cubic(e) => {
                *self.cubic.effect_mut(location) = e;
                self.cubic.enable(location, true);
            }
            Law::Friction(e) => {
                *self.friction.effect_mut(location) = e;
                self.friction.enable(location, true);
            }
        }
    }

    /// Replace the discovered terms by `terms` (at most [`MAX_TERMS`], switched on in slots
    /// 1..; the other slots off). A term that is not valid is refused, naming its variable, and
    /// nothing changes.
    pub fn switch_on_terms(&mut self, terms: &[Term]) -> Result<(), ModelError> {
        self.discovered.set_terms(terms)
    }

    pub fn any_enabled(&self) -> bool {
        self.contact.any_enabled()
            || self.cubic.any_enabled()
            || self.friction.any_enabled()
            || self.discovered.any_enabled()
    }

    /// The switch functions of the enabled effects: values whose sign change marks a kink in
    /// `g` (a contact gap opening or closing, a discovered ramp's `x ∓ s` crossing zero).
    /// Smooth effects have none.
    #[inline]
    pub fn switches(&self, y: &Floors) -> Switches {
        let mut out = Switches {
            values: [0.0; MAX_SWITCHES],
            len: 0,
        };
        for (location, contact) in self.contact.effects.iter().enumerate() {
            if self.contact.enabled[location] {
                for value in contact.switches(drift(y, location)).into_iter().flatten() {
                    out.values[out.len] = value;
                    out.len += 1;
                }
            }
        }
        for value in self.discovered.enabled_terms().filter_map(|t| t.switch(y)) {
            out.values[out.len] = value;
            out.len += 1;
        }
        out
    }

    /// `g(y, ẏ)`: the sum of every enabled effect's force on each floor.
    #[inline]
    pub fn force(&self, y: &Floors, v: &Floors) -> Floors {
        let mut g = [0.0; STOREYS];
        self.contact.add_forces(y, v, &mut g);
        self.cubic.add_forces(y, v, &mut g);
        self.friction.add_forces(y, v, &mut g);
        self.discovered.add_forces(y, v, &mut g);
        g
    }

    pub fn get_real(&self, vr: u32) -> Option<f64> {
        self.contact
            .get_real(vr)
            .or_else(|| self.cubic.get_real(vr))
            .or_else(|| self.friction.get_real(vr))
            .or_else(|| self.discovered.get_real(vr))
    }
    pub fn set_real(&mut self, vr: u32, value: f64) -> Option<Result<(), ModelError>> {
        self.contact
            .set_real(vr, value)
            .or_else(|| self.cubic.set_real(vr, value))
            .or_else(|| self.friction.set_real(vr, value))
            .or_else(|| self.discovered.set_real(vr, value))
    }
    pub fn get_integer(&self, vr: u32) -> Option<i32> {
        self.contact
            .get_integer(vr)
            .or_else(|| self.cubic.get_integer(vr))
            .or_else(|| self.friction.get_integer(vr))
            .or_else(|| self.discovered.get_integer(vr))
    }
    pub fn set_integer(&mut self, vr: u32, value: i32) -> Option<Result<(), ModelError>> {
        self.contact
            .set_integer(vr, value)
            .or_else(|| self.cubic.set_integer(vr, value))
            .or_else(|| self.friction.set_integer(vr, value))
            .or_else(|| self.discovered.set_integer(vr, value))
    }
    pub fn get_boolean(&self, vr: u32) -> Option<bool> {
        self.contact
            .get_boolean(vr)
            .or_else(|| self.cubic.get_boolean(vr))
            .or_else(|| self.friction.get_boolean(vr))
            .or_else(|| self.discovered.get_boolean(vr))
    }
    pub fn set_boolean(&mut self, vr: u32, value: bool) -> Option<()> {
        self.contact
            .set_boolean(vr, value)
            .or_else(|| self.cubic.set_boolean(vr, value))
            .or_else(|| self.friction.set_boolean(vr, value))
            .or_else(|| self.discovered.set_boolean(vr, value))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The law of each kind is the force the model adds: at a location, along its drift or
    /// velocity.
    #[test]
    fn each_law_is_the_models_force() {
        let y = [1e-3, -2e-3, 4e-3];
        let v = [0.02, -0.01, 0.005];
        for kind in Kind::ALL {
            for location in 0..kind.sites(STOREYS) {
                let reals: Vec<f64> = kind.real_params().iter().map(|p| 2.0 * p.start).collect();
                let law = Law::new(kind, &reals, Side::Negative).expect("enough parameters");
                assert_eq!(law.reals(), reals);
                let mut effects = Effects::default();
                let mut g = [0.0; 3];
                let expected = match kind.placement() {
                    Placement::Storey => {
                        let f = law.force_at(drift(&y, location));
                        add_storey_force(location, f, &mut g);
                        g
                    }
                    Placement::Floor => {
                        g[location] = law.force_at(v[location]);
                        g
                    }
                };
                effects.switch_on(location, law);
                assert_eq!(effects.force(&y, &v), expected, "{kind:?} at {location}");
            }
        }
    }
}
