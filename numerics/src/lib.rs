//! Numerics for the twin, with no FFI and no I/O.

pub mod gp;
pub mod lqr;
pub mod ode;
