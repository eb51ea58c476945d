//! The twin's orchestrator, by job:
//!
//! - `cosim`: the co-simulation layer — FMU import, the master algorithm, SSP, FMU packing and
//!   `twin run`; it knows nothing of the shear structure;
//! - `record`: measurement records in and out (the one reader and writer of the CSV format);
//! - `twin`: the twin as an SSP archive around the shear FMU and running it on a record;
//! - `evaluation`: statistics and the comparison of a run with a record;
//! - `workflows`: calibrate, train, learn, diagnose (with forward selection and discovery),
//!   control, the hybrid test;
//! - `blocks`: zero-time blocks of the master (the LQR, the active-learning supervisor);
//! - `synth`: the synthetic structure that makes records with known truth;
//! - `report`: JSON and SVG plots;
//! - `choice`: the options with a closed set of values, by name;
//! - `fsutil`: the one atomic file write;
//! - `notice`: what the library has to say besides its results, handed to the caller's sink.
//!
//! The `twin` command line (clap, anyhow, progress bars, printing) is the binary's own
//! (`src/commands`, a module of `main.rs`; its crates are the feature `cli`'s): the library
//! computes and returns data.

pub mod blocks;
pub mod choice;
pub mod cosim;
pub mod evaluation;
pub mod fsutil;
pub mod notice;
pub mod parallel;
pub mod record;
pub mod report;
pub mod serve;
pub mod synth;
pub mod twin;
pub mod workflows;

// The paths the integration tests and examples were written against, from before the
// modules were grouped by job.
pub use cosim::{import, master};
pub use evaluation::{compare, stats};
pub use twin::{data, run};
pub use workflows::{calibrate, diagnose, learn, train};
