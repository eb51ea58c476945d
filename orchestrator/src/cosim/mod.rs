//! The co-simulation layer: FMU import, the master algorithm, SSP system structures, FMU
//! packing, and `twin run`, the general FMI 2.0 runner. It knows nothing of the shear
//! structure.

pub mod import;
pub mod master;
pub mod pack;
pub mod run;
pub mod ssp;
