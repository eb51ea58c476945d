//! `twin run`: any FMI 2.0 co-simulation FMU, or an SSP system of them, run by the master.
//!
//! The configuration (experiment, start values, the input file's columns) is checked against
//! the modelDescriptions before any FMU's code is loaded. The run then follows fmpy's
//! `simulate_fmu` conventions, so the same FMU with the same inputs gives the same rows:
//! - the communication points are `start + k·h` up to the stop time; an FMU that handles
//!   variable communication steps also stops at the input file's events (repeated time rows,
//!   changes of a discrete input), and gets a last short step to the stop time;
//! - continuous Real inputs are interpolated linearly between the file's rows at each point,
//!   the others (Integer, Boolean, Enumeration, discrete Reals) are held from the last row; an
//!   FMU that declares `canInterpolateInputs` also gets the slope up to the next point (unless
//!   `hold_inputs`: fmpy's default never sends one);
//! - a system's connections are resolved by Gauss–Seidel at each point (default), or by Jacobi
//!   (`algorithm`): every component then reads the others' outputs as the last step left them,
//!   as fmpy's `simulate_ssp` does (which also delivers the system inputs a step late);
//! - the outputs at a point are recorded as the step left them, before that point's inputs are
//!   applied (point 0: after the start values and the first inputs, in initialisation mode);
//! - an FMU that ends the simulation itself (`fmi2Discard` + `fmi2Terminated`) ends the run at
//!   its last successful time, recorded as the last row.
//!
//! The stages, one submodule each: `model` (the FMUs or the system, the start values), `inputs`
//! (the input file), `plan` (the communication points, checked before any code is loaded),
//! `execute` (instantiated, wired, stepped and recorded).

mod execute;
mod inputs;
mod model;
mod plan;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::cosim::import::{ImportError, ScalarType};
use crate::cosim::master::{Algorithm, MasterError};

use execute::execute;
use model::Model;
use plan::plan;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error("{path}: {message}")]
    Model { path: PathBuf, message: String },
    #[error("{0}")]
    Config(String),
    #[error("{path}: line {line}: {message}")]
    Input {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

/// What to run and how; None takes the model's `DefaultExperiment` (then fmpy's defaults).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub start: Option<f64>,
    pub stop: Option<f64>,
    pub step: Option<f64>,
    /// CSV: `time` first, then columns named like inputs (or tunable parameters).
    pub input: Option<PathBuf>,
    /// `NAME=VALUE` start values (`component.variable` in a system).
    pub sets: Vec<String>,
    /// Record the local variables too, not only the outputs.
    pub output_all: bool,
    /// Hold every input over each step, even for FMUs that can interpolate inputs (fmpy's
    /// `simulate_fmu` default).
    pub hold_inputs: bool,
    /// How a system's connections are resolved at a communication point: Gauss–Seidel (each
    /// component, in the SSD's order, sees what the ones before it produced at this point,
    /// repeated until nothing changes) or Jacobi (every component sees the outputs as the last
    /// step left them: fmpy's `simulate_ssp` for connections between components).
    pub algorithm: Algorithm,
}

/// A recorded column.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    pub name: String,
    pub scalar_type: ScalarType,
}

/// The recorded rows: `values[c][k]` (NaN for a String column, whose values are in `texts`).
#[derive(Debug, Clone)]
pub struct RunResult {
    pub columns: Vec<Column>,
    pub time: Vec<f64>,
    pub values: Vec<Vec<f64>>,
    pub texts: BTreeMap<usize, Vec<String>>,
    pub start: f64,
    pub stop: f64,
    pub step: f64,
    /// Set when an FMU ended the run itself: (its component, the time).
    pub terminated: Option<(String, f64)>,
}

impl RunResult {
    /// `time,<columns…>`; Reals in shortest round-trip form, Booleans as 0/1.
    pub fn write_csv(&self, writer: impl std::io::Write) -> Result<(), csv::Error> {
        let mut w = csv::Writer::from_writer(writer);
        let mut header = vec!["time".to_owned()];
        header.extend(self.columns.iter().map(|c| c.name.clone()));
        w.write_record(&header)?;
        let mut row = Vec::with_capacity(header.len());
        for (k, t) in self.time.iter().enumerate() {
            row.clear();
            row.push(real_text(*t));
            for (c, column) in self.columns.iter().enumerate() {
                row.push(match column.scalar_type {
                    ScalarType::String => self.texts[&c][k].clone(),
                    ScalarType::Real => real_text(self.values[c][k]),
                    _ => format!("{}", self.values[c][k] as i64),
                });
            }
            w.write_record(&row)?;
        }
        w.flush()?;
        Ok(())
    }

    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .position(|c| c.name == name)
            .map(|i| self.values[i].as_slice())
    }
}

/// The shortest text that reads back to the same `f64`: plain for magnitudes from 1e-4 to
/// 1e15, scientific beyond (Rust's `{:e}` is shortest round-trip too).
fn real_text(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-4..1e15).contains(&a) || !a.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

// ---------------------------------------------------------------------------------------------
// The model: one FMU, or the components of an SSP system

/// Run `path` (an `.fmu` or `.ssp`). `progress(done, total)` is called after each step.
pub fn run(
    path: &Path,
    options: &RunOptions,
    progress: impl FnMut(u64, u64),
) -> Result<RunResult, RunError> {
    let model = Model::open(path)?;
    let plan = plan(&model, options)?;
    execute(
        model,
        plan,
        options.hold_inputs,
        options.algorithm,
        progress,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reals_are_written_to_read_back_exactly() {
        for x in [
            0.0,
            -0.0,
            1.0 / 3.0,
            6.766057429708043e-10,
            -2.5e300,
            123456.789,
            1e15,
            1e-4,
        ] {
            let text = real_text(x);
            assert_eq!(
                text.parse::<f64>().expect("a number").to_bits(),
                x.to_bits(),
                "{text}"
            );
        }
        assert_eq!(real_text(6.766057429708043e-10), "6.766057429708043e-10");
        assert_eq!(real_text(0.25), "0.25");
    }
}
