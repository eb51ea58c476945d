//! The co-simulation layer: SSP system structures and `twin run`, the general FMI 2.0 runner.
//! It knows nothing of the shear structure.

pub mod run;
pub mod ssp;
