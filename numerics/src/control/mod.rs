//! Control design on nalgebra matrices: the continuous-time algebraic Riccati equation of the
//! LQR ([`solve_care`]), written here (see [`riccati`] for the method and its checks).

pub mod riccati;

pub use nalgebra::{Complex, DMatrix, DVector};
pub use riccati::{
    solve_care, Care, RiccatiError, AXIS_TOLERANCE_PER_DIMENSION, MAX_STATES, RESIDUAL_TOLERANCE,
    STABILISABILITY_TOLERANCE,
};

/// A complex number in double precision (the closed-loop poles, Hamiltonian eigenvalues).
pub type Complex64 = Complex<f64>;
