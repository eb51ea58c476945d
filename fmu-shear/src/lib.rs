//! `fmu_shear`: the three-storey shear frame as an FMI 2.0 co-simulation FMU.
//!
//! `M ÿ + C ẏ + K y + g(y, ẏ) = φ (force − control_force)`, φ = floor 1, integrated by RK4 with
//! `substeps` internal steps per communication step; `g` is the optional-effect library
//! (`effects/`), every effect off by default.

pub mod effects;
pub mod integrate;
pub mod model;
pub mod piecewise;
pub mod sensitivity;
pub mod variables;

pub use model::{Integrator, ShearModel, ShearParameters, DEFAULT_SUBSTEPS};

fmi2::export_fmu!(crate::model::ShearModel);
