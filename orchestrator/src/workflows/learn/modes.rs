//! The modes chosen (`--modes`), run in parallel threads, and the learned twin written.

use super::refit::initial_floors;
use super::results::ModeResult;
use super::run::run_mode;
use super::stream::Stream;
use super::threshold::fixed_threshold;
use super::{LearnOptions, Result};
use crate::blocks::supervisor::Mode;
use crate::twin::Twin;

impl LearnOptions {
    /// The options `prepare` and `run_modes` do not check themselves.
    pub fn validate(&self) -> Result<(), crate::workflows::options::InvalidOption> {
        use crate::workflows::options::InvalidOption;
        if !(self.refit_growth >= 0.0 && self.refit_growth.is_finite()) {
            return Err(InvalidOption(format!(
                "--refit-growth must be a non-negative fraction, was {}",
                self.refit_growth
            )));
        }
        if let Some(t) = self.threshold {
            if !(t > 0.0 && t.is_finite()) {
                return Err(InvalidOption(format!(
                    "--threshold must be a positive number, was {t}"
                )));
            }
        }
        crate::workflows::options::check_transient(self.transient)
    }
}

/// `--mode`'s default.
pub const MODE: &str = "adaptive";
/// `--forgetting`'s default: plain adaptive.
pub const FORGETTING: f64 = 1.0;

/// `--mode NAME` (uniform, fixed or adaptive, the latter with `--forgetting`) or, with `all`,
/// the six modes of the paper's Table 2.
pub fn chosen_modes(
    mode: &str,
    forgetting: f64,
    all: bool,
) -> Result<Vec<Mode>, crate::workflows::options::InvalidOption> {
    use crate::workflows::options::InvalidOption;
    if !(forgetting > 0.0 && forgetting <= 1.0) {
        return Err(InvalidOption(format!(
            "--forgetting must be in (0, 1], was {forgetting}"
        )));
    }
    if all {
        return Ok(Mode::all());
    }
    Ok(vec![match mode {
        "uniform" => Mode::Uniform,
        "fixed" => Mode::Fixed,
        "adaptive" => Mode::Adaptive(forgetting),
        other => {
            return Err(InvalidOption(format!(
                "--mode {other}: expected uniform, fixed or adaptive"
            )))
        }
    }])
}

/// Every mode over the records, the modes in parallel threads.
pub fn run_modes(
    streams: &[Stream],
    modes: &[Mode],
    options: &LearnOptions,
) -> Result<Vec<ModeResult>> {
    let clock = std::time::Instant::now();
    let initial = initial_floors(streams, options)?;
    let initial_fit_seconds = clock.elapsed().as_secs_f64();
    let fixed = if modes.contains(&Mode::Fixed) {
        Some(fixed_threshold(streams, options)?)
    } else {
        None
    };
    std::thread::scope(|scope| {
        let handles: Vec<_> = modes
            .iter()
            .map(|&mode| {
                let (initial, fixed) = (&initial, fixed.as_ref());
                scope.spawn(move || run_mode(streams, initial, mode, fixed, options))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| match h.join() {
                Ok(r) => r.map(|r| ModeResult {
                    initial_fit_seconds,
                    ..r
                }),
                Err(payload) => std::panic::resume_unwind(payload),
            })
            .collect()
    })
}

/// The twin with the corrector as `result` learned it (its final training set and
/// hyperparameters) behind `twin`'s physics.
pub fn learned_twin(
    twin: &Twin,
    result: &ModeResult,
    options: &LearnOptions,
) -> Result<Twin, crate::workflows::train::TrainError> {
    let trained = result.final_gps.to_training(options.target);
    crate::workflows::train::with_corrector(twin, &trained)
}
