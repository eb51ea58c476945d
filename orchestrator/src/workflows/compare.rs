//! `twin compare`'s options and work: the twin on a record's excitation (open loop, or in a
//! closed loop with a `twin control` report's controller), compared with every measured
//! channel.

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
            )?
        }
    })
}

/// `twin compare --plot PATH [--frf]`: measured, predicted, ±3σ band, residual and failing
/// windows per measured channel (and the frequency-response view); with a corrector, the
/// latent-variance view of the channels it corrects beside it (`PATH-latent.svg`) against
/// `options.latent_threshold` (default: each channel's calibrated noise variance, else 1e-3 ×
/// its measured variance on this record).
pub fn plot(
    twin: &Twin,
    data: &Measurement,
    compared: &Compared,
    options: &CompareOptions,
    path: &std::path::Path,
    frf: bool,
) -> Result<(), crate::report::ReportError> {
    let title = format!("{} on {}", twin.describe(), data.path.display());
    let comparison = &compared.comparison;
    crate::report::plot_comparison(comparison, &data.excitation, &title, path, frf)?;
    let latent: Vec<(usize, &[f64], f64)> = comparison
        .channels
        .iter()
        .enumerate()
        .filter_map(|(c, channel)| {
            let values = compared.prediction.get(*channel)?.latent_var.as_deref()?;
            let threshold = match (options.latent_threshold, twin.noise_variance_of(*channel)) {
                (Some(t), _) => t,
                (None, Some(v)) => v,
                (None, None) => {
                    crate::workflows::learn::PAPER_THRESHOLD
                        * crate::evaluation::stats::variance(
                            &comparison.measured[c][comparison.first..],
                        )
                }
            };
            Some((c, values, threshold))
        })
        .collect();
    if !latent.is_empty() {
        crate::report::plot_latent_variance(comparison, &latent, &title, path)?;
    }
    Ok(())
}
