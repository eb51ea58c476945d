//! `fmu_shear`: an N-storey shear frame as an FMI 2.0 co-simulation FMU.
//!
//! `M ÿ + C ẏ + K y + g(y, ẏ) = L u − e_cf control_force` in displacements relative to the
//! ground, `L = e_K` for a force at floor K (input `force`), `L = −M 1` for ground acceleration
//! (input `ground_acc`; the accelerometers read `ÿ + ground_acc`); integrated by RK4 with
//! `substeps` internal steps per communication step (for the linear model, its exact step map:
//! `linear`). The structure comes from `resources/structure.json` ([`model::StructureResource`])
//! at `fmi2Instantiate`, the paper's rig (3 storeys, a force at floor 1) without it; each
//! structure has its own variable table and GUID (`variables::table`). `g` is the optional-effect
//! library (`effects/`) at every site of the structure, every effect off by default; contacts
//! alone step exactly (`piecewise_any`, any structure).

pub mod batch;
pub mod effects;
pub(crate) mod hermite;
pub mod integrate;
pub mod kernels;
pub mod linear;
pub mod modal;
pub mod model;
pub mod piecewise_any;
pub mod sensitivity;
pub mod variables;

pub use model::{Integrator, ShearModel, ShearParameters, StructureResource, DEFAULT_SUBSTEPS};

fmi2::export_fmu!(crate::model::ShearModel);
