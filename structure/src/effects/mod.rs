//! The effect catalogue: the forces `g(y, ẏ)` that eq. (1) does not have, described once for
//! every crate (the shear FMU runs them, the diagnosis proposes them, the synthetic structure
//! hides them in its records). For each kind: where it sits (a storey or a floor, [`Placement`]),
//! how many sites a building of N storeys has ([`Kind::sites`]), its parameters with their
//! defaults and ranges ([`RealParam`]), its force law as a function ([`Law`]), and the site in
//! words and in the FMU's variable names ([`Kind::prefix`], [`Kind::where_`]). The
//! [`discovered`] terms are the generic `coefficient · f(x, v)` forces a diagnosis finds by
//! regression: their functions and sites.
//!
//! [`label`] is the one text form of an effect, `KIND@LOC[:k=v,...]`
//! (`contact@2-3:gap=5e-4,side=positive`, `cubic@2`, `friction@1`, `discovered@storey2`).
//!
//! Sign convention: an effect adds to `g`, the left-hand side of `M ÿ + C ẏ + K y + g = L u`, so
//! a restoring force is positive along the displacement that causes it. Displacements and
//! velocities are of floors 1..N (the ground excluded), in slices of length N.

pub mod contact;
pub mod cubic;
pub mod discovered;
pub mod friction;
pub mod kind;
pub mod label;

use serde::{Deserialize, Serialize};

pub use contact::Contact;
pub use cubic::Cubic;
pub use discovered::{Function, Site, Term};
pub use friction::Friction;
pub use kind::{Kind, Law, Placement, Side};
pub use label::{Label, LabelError, Location};

/// A real parameter of an effect kind: its name suffix (`contact23_gap`), unit, start value and
/// smallest allowed value.
pub struct RealParam {
    pub suffix: &'static str,
    pub unit: &'static str,
    pub start: f64,
    /// Smallest allowed value; `strictly` excludes it.
    pub min: f64,
    pub strictly: bool,
    pub description: &'static str,
}

/// A parameter value outside its range, named as the FMU's variable (`discovered2_scale`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid value for '{name}': {reason}")]
pub struct InvalidParameter {
    pub name: String,
    pub reason: String,
}

/// One kind of physical effect at one site (a storey or a floor, 0-based `location`).
pub trait Effect: Clone + std::fmt::Debug + Serialize + for<'de> Deserialize<'de> {
    /// Kind name as the diagnosis reports it: "contact", "cubic", "friction".
    const KIND: &'static str;
    /// How many sites this kind has in a building of `storeys` storeys (one per storey or one
    /// per floor: as many either way).
    fn sites(storeys: usize) -> usize {
        storeys
    }
    /// Variable-name prefix at `location` (0-based), e.g. "contact23".
    fn prefix(location: usize) -> String;
    /// Human description of the location, for the modelDescription.
    fn where_(location: usize) -> String;
    fn real_params() -> &'static [RealParam];
    /// Integer parameters: (suffix, start, min, max, description).
    fn integer_params() -> &'static [(&'static str, i32, i32, i32, &'static str)] {
        &[]
    }
    /// The effect with its parameters at their start values.
    fn at_start(location: usize) -> Self;
    fn real(&self, index: usize) -> f64;
    fn set_real(&mut self, index: usize, value: f64);
    fn integer(&self, _index: usize) -> i32 {
        0
    }
    fn set_integer(&mut self, _index: usize, _value: i32) {}
    /// Add this effect's force at `location` to `g`, for floor displacements `y` and velocities
    /// `v`.
    fn add_force(&self, location: usize, y: &[f64], v: &[f64], g: &mut [f64]);
}

/// Inter-storey drift of storey `s` (0-based: storey 0 is ground–floor 1): `y_s − y_{s−1}`.
#[inline]
pub fn drift(y: &[f64], storey: usize) -> f64 {
    if storey == 0 {
        y[0]
    } else {
        y[storey] - y[storey - 1]
    }
}

/// Apply a storey force `f` (positive when it resists a positive drift): on the upper floor of
/// the storey `+f`, on the lower floor (if not the ground) `−f`.
#[inline]
pub fn add_storey_force(storey: usize, f: f64, g: &mut [f64]) {
    g[storey] += f;
    if storey > 0 {
        g[storey - 1] -= f;
    }
}
