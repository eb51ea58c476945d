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
use smallvec::SmallVec;
use structure::building::MAX_STOREYS;
use structure::paper::STOREYS as PAPER_STOREYS;

pub use discovered::{Discovered, MAX_TERMS};
pub use structure::effects::{
    add_storey_force, contact, cubic, drift, friction, kind, Contact, Cubic, Effect, Friction,
    Function, Kind, Law, Placement, RealParam, Side, Site, Term,
};

/// Value-reference layout of a library: each site (0-based location) owns a block of
/// [`SLOTS_PER_LOCATION`] references, slot 0 the `enabled` Boolean, 1..=7 the reals and 8..=9
/// the integers. The block of site `l` starts at [`site_vr`]: `base + 10·l` for the paper's
/// three sites (contact 100, cubic 200, friction 300: the references the paper's twins and
/// `modelDescription/fmu_shear.xml` carry), and `EXTENDED_BASE_VR + 10·base + 10·l` for every
/// later site, so that no two kinds' blocks meet for any N ≤ [`MAX_STOREYS`] (the base blocks
/// hold 10 sites before the next kind's, the extended ones 100).
pub const SLOTS_PER_LOCATION: u32 = 10;
const FIRST_REAL_SLOT: u32 = 1;
const FIRST_INTEGER_SLOT: u32 = 8;
/// Where the sites past the paper's third start: above every other block (the sensitivities
/// end below `SENSITIVITY + 3·MAX_STOREYS²`).
pub const EXTENDED_BASE_VR: u32 = 100_000;

const _: () = assert!(SLOTS_PER_LOCATION * PAPER_STOREYS as u32 <= 100);
const _: () = assert!(SLOTS_PER_LOCATION * MAX_STOREYS as u32 <= 1000);
const _: () = assert!(
    crate::variables::SENSITIVITY + 3 * (MAX_STOREYS * MAX_STOREYS) as u32 <= EXTENDED_BASE_VR
);

/// The first value reference of site `location` (0-based) of the library whose paper block
/// starts at `base` (see [`SLOTS_PER_LOCATION`]).
pub fn site_vr(base: u32, location: usize) -> u32 {
    if location < PAPER_STOREYS {
        base + SLOTS_PER_LOCATION * location as u32
    } else {
        EXTENDED_BASE_VR + 10 * base + SLOTS_PER_LOCATION * location as u32
    }
}

/// The inverse of [`site_vr`]: (location, slot) of `vr` for a library at `base` with `sites`
/// sites.
fn site_of(base: u32, vr: u32, sites: usize) -> Option<(usize, u32)> {
    let paper = vr
        .checked_sub(base)
        .filter(|&offset| offset < SLOTS_PER_LOCATION * PAPER_STOREYS as u32);
    let (location, slot) = match paper {
        Some(offset) => (offset / SLOTS_PER_LOCATION, offset % SLOTS_PER_LOCATION),
        None => {
            let offset = vr.checked_sub(EXTENDED_BASE_VR + 10 * base)?;
            let location = offset / SLOTS_PER_LOCATION;
            if location < PAPER_STOREYS as u32 {
                return None;
            }
            (location, offset % SLOTS_PER_LOCATION)
        }
    };
    ((location as usize) < sites).then_some((location as usize, slot))
}

/// One effect kind at each of its locations, each with its own `enabled` switch.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Library<E> {
    base_vr: u32,
    enabled: Vec<bool>,
    effects: Vec<E>,
}

impl<E: Effect> Library<E> {
    /// Every site of a building of `storeys` storeys, each off at its start values.
    pub fn new(base_vr: u32, storeys: usize) -> Self {
        Library {
            base_vr,
            enabled: vec![false; E::sites(storeys)],
            effects: (0..E::sites(storeys)).map(E::at_start).collect(),
        }
    }

    /// The sites of a building of `storeys` storeys: the ones it has kept, new ones off.
    fn fit(&mut self, storeys: usize) {
        let sites = E::sites(storeys);
        self.enabled.resize(sites, false);
        let have = self.effects.len();
        self.effects.truncate(sites);
        self.effects.extend((have..sites).map(E::at_start));
    }

    pub fn variables(base_vr: u32, storeys: usize) -> Vec<Variable> {
        let mut vars = Vec::new();
        for location in 0..E::sites(storeys) {
            let prefix = E::prefix(location);
            let vr0 = site_vr(base_vr, location);
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
        site_of(self.base_vr, vr, self.effects.len())
    }

    pub fn owns(&self, vr: u32) -> bool {
        self.locate(vr).is_some()
    }

    /// The value reference of real parameter `index` at `location`.
    pub fn real_vr(&self, location: usize, index: usize) -> u32 {
        site_vr(self.base_vr, location) + FIRST_REAL_SLOT + index as u32
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

    /// Add the enabled effects' forces to `g` (floor displacements `y`, velocities `v`, all of
    /// the building's length).
    #[inline]
    pub fn add_forces(&self, y: &[f64], v: &[f64], g: &mut [f64]) {
        for (location, effect) in self.effects.iter().enumerate() {
            if self.enabled[location] {
                effect.add_force(location, y, v, g);
            }
        }
    }

    /// How many sites the library has.
    pub fn sites(&self) -> usize {
        self.effects.len()
    }

    /// The enabled sites (0-based).
    pub fn enabled_sites(&self) -> impl Iterator<Item = usize> + '_ {
        self.enabled
            .iter()
            .enumerate()
            .filter_map(|(location, &on)| on.then_some(location))
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

/// The switch values of the enabled effects (up to two per contact, one per discovered ramp
/// term), inline up to eight.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Switches {
    pub values: SmallVec<[f64; 8]>,
}

/// Every effect kind of the library, at every site of a building of N storeys.
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
    /// The library of the paper's rig (three storeys).
    fn default() -> Self {
        Effects::new(PAPER_STOREYS)
    }
}

impl Effects {
    /// Every site of a building of `storeys` storeys, every effect off.
    pub fn new(storeys: usize) -> Self {
        Effects {
            contact: Library::new(CONTACT_BASE_VR, storeys),
            cubic: Library::new(CUBIC_BASE_VR, storeys),
            friction: Library::new(FRICTION_BASE_VR, storeys),
            discovered: Discovered::default(),
        }
    }

    /// The storeys of the building the library is laid out for.
    pub fn storeys(&self) -> usize {
        self.cubic.sites()
    }

    /// Lay the library out for a building of `storeys` storeys: the sites it has keep their
    /// settings, new ones are off.
    pub fn fit(&mut self, storeys: usize) {
        self.contact.fit(storeys);
        self.cubic.fit(storeys);
        self.friction.fit(storeys);
    }

    /// The variables of every site of a building of `storeys` storeys.
    pub fn variables(storeys: usize) -> Vec<Variable> {
        let mut vars = Library::<Contact>::variables(CONTACT_BASE_VR, storeys);
        vars.extend(Library::<Cubic>::variables(CUBIC_BASE_VR, storeys));
        vars.extend(Library::<Friction>::variables(FRICTION_BASE_VR, storeys));
        vars.extend(Discovered::variables(storeys));
        vars
    }

    /// The variables of the paper's rig.
    pub fn all_variables() -> Vec<Variable> {
        Effects::variables(PAPER_STOREYS)
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
        let storeys = self.storeys();
        self.discovered.set_terms(terms, storeys)
    }

    pub fn any_enabled(&self) -> bool {
        self.contact.any_enabled()
            || self.cubic.any_enabled()
            || self.friction.any_enabled()
            || self.discovered.any_enabled()
    }

    /// Whether any enabled effect has a kink (a contact, or a discovered term with a switch
    /// function): without one, [`Effects::switches`] is always empty.
    pub fn any_switching(&self) -> bool {
        self.contact.any_enabled()
            || self
                .discovered
                .enabled_terms()
                .any(|t| t.function.switch(0.0, t.scale).is_some())
    }

    /// The switch functions of the enabled effects: values whose sign change marks a kink in
    /// `g` (a contact gap opening or closing, a discovered ramp's `x ∓ s` crossing zero).
    /// Smooth effects have none.
    #[inline]
    pub fn switches(&self, y: &[f64]) -> Switches {
        let mut out = Switches::default();
        for (location, contact) in self.contact.effects.iter().enumerate() {
            if self.contact.enabled[location] {
                out.values
                    .extend(contact.switches(drift(y, location)).into_iter().flatten());
            }
        }
        out.values
            .extend(self.discovered.enabled_terms().filter_map(|t| t.switch(y)));
        out
    }

    /// Add `g(y, ẏ)`, the sum of every enabled effect's force on each floor, to `g`.
    #[inline]
    pub fn add_forces(&self, y: &[f64], v: &[f64], g: &mut [f64]) {
        self.contact.add_forces(y, v, g);
        self.cubic.add_forces(y, v, g);
        self.friction.add_forces(y, v, g);
        self.discovered.add_forces(y, v, g);
    }

    /// `g(y, ẏ)`: the sum of every enabled effect's force on each floor.
    pub fn force(&self, y: &[f64], v: &[f64]) -> Vec<f64> {
        let mut g = vec![0.0; y.len()];
        self.add_forces(y, v, &mut g);
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
        let storeys = self.storeys();
        self.contact
            .set_integer(vr, value)
            .or_else(|| self.cubic.set_integer(vr, value))
            .or_else(|| self.friction.set_integer(vr, value))
            .or_else(|| self.discovered.set_integer(vr, value, storeys))
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

    /// The law of each kind is the force the model adds: at every location of a 3- and a
    /// 12-storey building, along its drift or velocity.
    #[test]
    fn each_law_is_the_models_force() {
        for storeys in [3, 12] {
            let y: Vec<f64> = (0..storeys)
                .map(|i| 1e-3 * (i as f64 * 1.7).sin())
                .collect();
            let v: Vec<f64> = (0..storeys)
                .map(|i| 0.02 * (i as f64 * 0.9).cos())
                .collect();
            for kind in Kind::ALL {
                for location in 0..kind.sites(storeys) {
                    let reals: Vec<f64> =
                        kind.real_params().iter().map(|p| 2.0 * p.start).collect();
                    let law = Law::new(kind, &reals, Side::Negative).expect("enough parameters");
                    assert_eq!(law.reals(), reals);
                    let mut effects = Effects::new(storeys);
                    let mut g = vec![0.0; storeys];
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

    /// Every site of every kind of a building of up to MAX_STOREYS storeys has its own block of
    /// references, found back from any of its slots, none shared with another site or kind; the
    /// paper's first three sites at base + 10·site.
    #[test]
    fn site_references_never_meet_and_read_back() {
        let mut seen = std::collections::HashMap::new();
        for (k, base) in [CONTACT_BASE_VR, CUBIC_BASE_VR, FRICTION_BASE_VR]
            .into_iter()
            .enumerate()
        {
            for location in 0..MAX_STOREYS {
                let vr = site_vr(base, location);
                if location < PAPER_STOREYS {
                    assert_eq!(vr, base + 10 * location as u32);
                }
                for slot in 0..SLOTS_PER_LOCATION {
                    assert_eq!(
                        site_of(base, vr + slot, MAX_STOREYS),
                        Some((location, slot))
                    );
                    assert_eq!(seen.insert(vr + slot, (k, location)), None, "{vr}");
                    assert!(!Discovered::owns(vr + slot));
                }
                // A site the building lacks is not found.
                assert_eq!(site_of(base, vr, location), None);
            }
        }
    }
}
