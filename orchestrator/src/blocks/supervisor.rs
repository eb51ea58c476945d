//! The active-learning supervisor (the paper's Algorithm 1, lines 7–12) as a zero-time block
//! of the master: it reads the corrector's latent variances and says whether the streamed point
//! is worth learning.

use crate::cosim::master::{Block, MasterError};

/// The forgetting factors `--modes all` runs (Table 2).
pub const FORGETTING_FACTORS: [f64; 4] = [1.0, 0.999, 0.99, 0.9];

/// How queries are decided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    Uniform,
    Fixed,
    /// Adaptive threshold with forgetting factor f_f ∈ (0, 1].
    Adaptive(f64),
}

impl Mode {
    pub fn name(&self) -> String {
        match self {
            Mode::Uniform => "uniform".into(),
            Mode::Fixed => "fixed".into(),
            Mode::Adaptive(f) => format!("adaptive f_f={f}"),
        }
    }

    /// The six modes of the paper's Table 2.
    pub fn all() -> Vec<Mode> {
        let mut modes = vec![Mode::Uniform, Mode::Fixed];
        modes.extend(FORGETTING_FACTORS.iter().map(|&f| Mode::Adaptive(f)));
        modes
    }

    /// A file-name-safe tag.
    pub fn tag(&self) -> String {
        match self {
            Mode::Uniform => "uniform".into(),
            Mode::Fixed => "fixed".into(),
            Mode::Adaptive(f) => format!("adaptive-{f}"),
        }
    }
}

/// The active-learning supervisor as a zero-time block. Inputs: the latent variance of each of
/// the corrector's channels (`latent_var1..3` on the paper's rig); outputs: the learn flag (1 or
/// 0) and each channel's threshold. Per evaluation (one streamed
/// point): adaptive mode first applies the forgetting factor (Algorithm 1, line 7), then flags
/// the point if any floor's latent variance exceeds its threshold (line 8); uniform mode flags
/// every `uniform_every`-th evaluation since [`Supervisor::start_record`].
#[derive(Clone, Debug)]
pub struct Supervisor {
    mode: Mode,
    threshold: Vec<f64>,
    uniform_every: usize,
    seen: usize,
}

impl Supervisor {
    /// The paper rig's inputs (three floors) and outputs; another layout has one input per
    /// channel and one output more.
    pub const INPUTS: usize = 3;
    pub const OUTPUTS: usize = 4;

    /// One threshold per channel.
    pub fn new(mode: Mode, threshold: impl Into<Vec<f64>>, uniform_every: usize) -> Self {
        Supervisor {
            mode,
            threshold: threshold.into(),
            uniform_every: uniform_every.max(1),
            seen: 0,
        }
    }

    pub fn threshold(&self) -> Vec<f64> {
        self.threshold.clone()
    }

    /// After a query, adaptive modes take the largest latent variance seen (line 12).
    pub fn update_threshold(&mut self, threshold: impl Into<Vec<f64>>) {
        if matches!(self.mode, Mode::Adaptive(_)) {
            self.threshold = threshold.into();
        }
    }

    /// A new record starts: the uniform count starts again.
    pub fn start_record(&mut self) {
        self.seen = 0;
    }
}

impl Block for Supervisor {
    fn evaluate(
        &mut self,
        _time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError> {
        let m = self.threshold.len();
        if inputs.len() != m || outputs.len() != m + 1 {
            return Err(MasterError::Block {
                block: "supervisor".into(),
                message: format!(
                    "{} inputs and {} outputs, expected {m} (a latent variance per channel) and {} (learn, a threshold per channel)",
                    inputs.len(),
                    outputs.len(),
                    m + 1
                ),
            });
        }
        self.seen += 1;
        let learn = match self.mode {
            Mode::Uniform => self.seen.is_multiple_of(self.uniform_every),
            Mode::Fixed => inputs.iter().zip(&self.threshold).any(|(v, t)| v > t),
            Mode::Adaptive(f) => {
                for t in &mut self.threshold {
                    *t *= f;
                }
                inputs.iter().zip(&self.threshold).any(|(v, t)| v > t)
            }
        };
        outputs[0] = if learn { 1.0 } else { 0.0 };
        outputs[1..].copy_from_slice(&self.threshold);
        Ok(())
    }
}
