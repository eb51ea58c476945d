//! `twin calibrate` as a whole, for the CLI and the Python package: the options checked, the
//! calibration, the calibrated twin and its NMSE on the validation records (the worst of which
//! sets its default tolerance).

use super::{calibrate, calibrated_twin, CalibrateError, Calibration, CalibrationSetup};
use crate::twin::data::Measurement;
use crate::twin::run::{nmse_on, RunError};
use crate::twin::Twin;
use crate::workflows::options::{check_threads, check_transient_leaves, InvalidOption};

#[derive(Debug, thiserror::Error)]
pub enum CalibrateRunError {
    #[error(transparent)]
    Options(#[from] InvalidOption),
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Plot(#[from] crate::report::ReportError),
}

impl CalibrationSetup {
    /// The options against the record they calibrate on.
    pub fn validate(&self, data: &Measurement) -> Result<(), InvalidOption> {
        check_threads(self.threads)?;
        check_transient_leaves(self.transient, data)
    }
}

/// What `twin calibrate` computes.
pub struct Validated {
    pub twin: Twin,
    pub calibration: Calibration,
    /// Each validation record's name and the calibrated twin's NMSE % per floor on it.
    pub validated: Vec<(String, [f64; 3])>,
}

/// Calibrate `twin` on `data`, and report the calibrated twin's NMSE on `validation`.
pub fn calibrate_validated(
    twin: &Twin,
    data: &Measurement,
    validation: &[&Measurement],
    setup: &CalibrationSetup,
) -> Result<Validated, CalibrateRunError> {
    setup.validate(data)?;
    let calibration = calibrate(twin, data, setup)?;
    let mut new_twin = calibrated_twin(twin, &calibration)?;
    let mut validated = Vec::new();
    for v in validation {
        validated.push((
            v.path.display().to_string(),
            nmse_on(&new_twin, v, setup.transient)?,
        ));
    }
    // The worst validation NMSE sets the default tolerance of compare and diagnose.
    new_twin.validation_nmse = crate::report::json::validation_nmse(&validated);
    Ok(Validated {
        twin: new_twin,
        calibration,
        validated,
    })
}

/// `twin calibrate --plot PATH`: the calibrated twin on the calibration record.
pub fn plot(
    calibrated: &Twin,
    data: &Measurement,
    transient: f64,
    path: &std::path::Path,
) -> Result<(), CalibrateRunError> {
    let comparison =
        crate::twin::run::run_and_compare(calibrated, data, transient, |_, _| {})?.comparison;
    let title = format!("calibrated on {}", data.path.display());
    crate::report::plot_comparison(&comparison, &data.excitation, &title, path, false)?;
    Ok(())
}
