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

/// The active-learning supervisor as a zero-time block. Inputs: `latent_var1..3`; outputs:
/// the learn flag (1 or 0) and the thresholds of floors 1..3. Per evaluation (one streamed
/// point): adaptive mode first applies the forgetting factor (Algorithm 1, line 7), then flags
/// the point if any floor's latent variance exceeds its threshold (line 8); uniform mode flags
/// every `uniform_every`-th evaluation since [`Supervisor::start_record`].
#[derive(Clone, Debug)]
pub struct Supervisor {
    mode: Mode,
    threshold: [f64; 3],
    uniform_every: usize,
    seen: usize,
}

impl Supervisor {
    pub const INPUTS: usize = 3;
    pub const OUTPUTS: usize = 4;

    pub fn new(mode: Mode, threshold: [f64; 3], uniform_every: usize) -> Self {
        Supervisor {
            mode,
            threshold,
            uniform_every: uniform_every.max(1),
            seen: 0,
        }
    }

    pub fn threshold(&self) -> [f64; 3] {
        self.threshold
    }

    /// After a query, adaptive modes take the largest latent variance seen (line 12).
    pub fn update_threshold(&mut self, threshold: [f64; 3]) {
        if matches!(self.mode, Mode::Adaptive(_)) {
            self.threshold = threshold;
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
        if inputs.len() != Self::INPUTS || outputs.len() != Self::OUTPUTS {
            return Err(MasterError::Block {
                block: "supervisor".into(),
                message: format!(
                    "{} inputs and {} outputs, expected {} (latent_var1..3) and {} (learn, threshold1..3)",
                    inputs.len(),
                    outputs.len(),
                    Self::INPUTS,
                    Self::OUTPUTS
                ),
            });
        }
        self.seen += 1;
        let learn = match self.mode {
            Mode::Uniform => self.seen.is_multiple_of(self.uniform_every),
            Mode::Fixed => inputs.iter().zip(self.threshold).any(|(v, t)| *v > t),
            Mode::Adaptive(f) => {
                for t in &mut self.threshold {
                    *t *= f;
                }
                inputs.iter().zip(self.threshold).any(|(v, t)| *v > t)
            }
        };
        outputs[0] = if learn { 1.0 } else { 0.0 };
        outputs[1..].copy_from_slice(&self.threshold);
        Ok(())
    }
}
