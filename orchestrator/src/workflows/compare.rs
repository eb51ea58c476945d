//! `twin compare`'s options and work: the twin on a record's force (open loop, or in a closed
//! loop with a `twin control` report's controller), compared with the measured accelerations.

use crate::evaluation::compare::DEFAULT_TRANSIENT;
use crate::twin::data::Measurement;
use crate::twin::run::{compare_with, run_and_compare_with, Compared, RunError};
use crate::twin::Twin;
use crate::workflows::control::{predict_controlled, ControlError, ControllerSpec};
use crate::workflows::options::{check_tolerance, check_transient_leaves, InvalidOption};

/// `twin compare`'s options (what it writes aside).
#[derive(Clone, Debug, PartialEq)]
pub struct CompareOptions {
    /// Seconds at the start left out of the error measures.
    pub transient: f64,
    /// Practical significance, NMSE % (None: the twin's default, see `Tolerance::resolve`).
    pub tolerance: Option<f64>,
    /// Threshold line of the latent-variance view, (m/s²)² (None: the twin's noise variances).
    pub latent_threshold: Option<f64>,
    /// Which design of a controller's report (None: the first stable one).
    pub controller_q: Option<f64>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            transient: DEFAULT_TRANSIENT,
            tolerance: None,
            latent_threshold: None,
            controller_q: None,
        }
    }
}

impl CompareOptions {
    /// The options alone (the record's length is checked by [`CompareOptions::validate_for`]).
    pub fn validate(&self) -> Result<(), InvalidOption> {
        if let Some(t) = self.latent_threshold {
            if !(t > 0.0 && t.is_finite()) {
                return Err(InvalidOption(format!(
                    "--latent-threshold must be a positive number, was {t}"
                )));
            }
        }
        check_tolerance(self.tolerance)
    }

    /// The options against the record: the transient must leave something of it.
    pub fn validate_for(&self, data: &Measurement) -> Result<(), InvalidOption> {
        check_transient_leaves(self.transient, data)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error(transparent)]
    Options(#[from] InvalidOption),
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Control(#[from] ControlError),
}

/// Run the twin on `data` (with `controller` in the loop when given) and compare.
pub fn compare(
    twin: &Twin,
    data: &Measurement,
    options: &CompareOptions,
    controller: Option<&ControllerSpec>,
    mut progress: impl FnMut(u64, u64),
) -> Result<Compared, CompareError> {
    options.validate()?;
    options.validate_for(data)?;
    Ok(match controller {
        None => run_and_compare_with(twin, data, options.transient, options.tolerance, progress)?,
        Some(spec) => {
            let prediction =
                predict_controlled(twin, data, spec, options.controller_q, &mut progress)?;
            compare_with(
                twin,
                data,
                options.transient,
                options.tolerance,
                prediction,
                None,
            )
        }
    })
}
