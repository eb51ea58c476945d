//! The shear building as data, for every crate above it.
//!
//! A building of N storeys: storey i joins floor i − 1 and floor i (floor 0 is the ground), floor
//! i carries the mass `m_i`, storey i the damping `c_i` and the stiffness `k_i`. It is excited by
//! a force at one floor or by ground acceleration at the base ([`Excitation`]). Its equation of
//! motion, in displacements `y` relative to the ground,
//!
//! ```text
//! M ÿ + C ẏ + K y + g(y, ẏ) = L u
//! ```
//!
//! with `L = e_K` for a force at floor K and `L = −M 1` for ground acceleration `u = a_g`; an
//! accelerometer reads the absolute acceleration `ÿ + a_g` (`ÿ` under a force).
//!
//! [`channel`] says what a record measures and in which units; [`effects`] is the catalogue of
//! the forces `g(y, ẏ)` (kinds, sites, parameters, force laws).

pub mod building;
pub mod channel;
pub mod effects;
pub mod paper;

pub use building::{Excitation, StateSpace, Structure, StructureError, MAX_STOREYS};
pub use channel::{Channel, ChannelError, Quantity, Unit};
