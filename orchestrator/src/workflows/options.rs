//! What the commands' options share: the error of an option out of range, and the checks of
//! the options several commands take. Each command's options live in its workflow's module
//! (`CompareOptions`, `CalibrationSetup`, `DiagnoseOptions`, `ControlOptions`, `WatchOptions`,
//! `TrainOptions`, `LearnOptions`, `RunOptions`, …), with their defaults and a `validate()`:
//! the `twin` CLI and the Python package only map their arguments onto them, so a default or a
//! message is written once.

use crate::twin::data::Measurement;

/// An option out of its range; the message names the CLI's flag (`--tolerance …`), which the
/// Python package's keyword argument of the same name mirrors.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct InvalidOption(pub String);

impl InvalidOption {
    pub fn new(message: impl Into<String>) -> Self {
        InvalidOption(message.into())
    }
}

/// `--tolerance`: a non-negative NMSE in % (None: the twin's default).
pub fn check_tolerance(tolerance: Option<f64>) -> Result<(), InvalidOption> {
    match tolerance {
        Some(t) if !(t >= 0.0 && t.is_finite()) => Err(InvalidOption(format!(
            "--tolerance must be a non-negative NMSE in %, was {t}"
        ))),
        _ => Ok(()),
    }
}

/// `--transient`: a non-negative number of seconds (the CLI's parser says the same).
pub fn check_transient(transient: f64) -> Result<(), InvalidOption> {
    if transient >= 0.0 && transient.is_finite() {
        Ok(())
    } else {
        Err(InvalidOption(format!(
            "--transient {transient}: must be a non-negative number of seconds"
        )))
    }
}

/// `--transient` against a record: something of it must be left.
pub fn check_transient_leaves(transient: f64, data: &Measurement) -> Result<(), InvalidOption> {
    check_transient(transient)?;
    if transient >= data.duration() {
        return Err(InvalidOption(format!(
            "--transient {} s leaves nothing of {} ({} s long)",
            transient,
            data.path.display(),
            data.duration()
        )));
    }
    Ok(())
}

/// `--threads`: at least 1.
pub fn check_threads(threads: usize) -> Result<(), InvalidOption> {
    if threads == 0 {
        return Err(InvalidOption("--threads must be at least 1".into()));
    }
    Ok(())
}

/// A `.svg` plot path (`--plot`).
pub fn check_svg(path: &std::path::Path) -> Result<(), InvalidOption> {
    if path.extension().and_then(|e| e.to_str()) != Some("svg") {
        return Err(InvalidOption(format!(
            "{}: only .svg plots are supported",
            path.display()
        )));
    }
    Ok(())
}
