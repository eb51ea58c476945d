//! The twin's orchestrator: FMU packaging and import, the master algorithm, and what the `twin`
//! CLI does with them.

pub mod fmu_archive;
pub mod import;
pub mod data;
pub mod master;
