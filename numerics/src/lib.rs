//! Numerics for the twin, with no FFI and no I/O.

pub mod actuator;
pub mod control;
pub mod excitation;
pub mod gp;
pub mod lqr;
pub mod modal;
pub mod ode;
pub mod substructure;
