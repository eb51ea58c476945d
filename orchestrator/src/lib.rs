//! The twin's orchestrator: FMU packaging and import, the master algorithm, the twin archive,
//! comparisons and reports, and the `twin` CLI's commands.

pub mod calibrate;
pub mod commands;
pub mod compare;
pub mod cosim;
pub mod data;
pub mod diagnose;
pub mod fmu_archive;
pub mod fsutil;
pub mod import;
pub mod learn;
pub mod master;
pub mod report;
pub mod run;
pub mod stats;
pub mod synth;
pub mod train;
pub mod twin;
