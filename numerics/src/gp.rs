//! Gaussian-process regression for the twin's data-based component (paper §4.1, eqs. (5)–(12)):
//! zero mean, Matérn 3/2 covariance with ARD lengthscales plus Gaussian noise, hyperparameters by
//! type-II maximum likelihood, predictions with the latent variance that drives active learning
//! (Algorithm 1), and O(n²) updates when a point joins or leaves the training set.
//!
//! One [`GaussianProcess`] models one output; the corrector's three floors are three values
//! fitted on the same [`Inputs`] (by the caller, in parallel threads if it wants, or by
//! [`GaussianProcess::fit_many`], which shares the (output, start) runs among threads; all else
//! here is single-threaded and `Send + Sync`). A model holds its training set, its hyperparameters and
//! the Cholesky factor with `α = K⁻¹y`; it serialises as the first two (plus the jitter in use)
//! and refactors on load.
//!
//! Call order: [`GaussianProcess::fit`] (or [`GaussianProcess::new`] with known
//! hyperparameters) → [`GaussianProcess::predict`] / [`GaussianProcess::predict_point`] →
//! [`GaussianProcess::append`] / [`GaussianProcess::remove`] as the training set changes →
//! [`GaussianProcess::refit`] (warm-started from the current hyperparameters) when the
//! hyperparameters should follow. [`TrackedPoints`] keeps latent variances and means at a fixed
//! set of points in step with a changing model (`O(n m)` per append or removal). Every entry
//! point validates its arguments before any linear algebra runs and answers bad input (NaN,
//! mismatched lengths, no points) with a [`GpError`].
//!
//! Dense linear algebra runs on faer: at N = 1000 its blocked Cholesky and Cholesky-based
//! inverse were several times faster than nalgebra's (benches/gp.rs measures both).

mod budget;
mod fit;
mod kernel;
mod lbfgs;
mod likelihood;
mod model;
mod synthetic;
mod tracked;

use serde::{Deserialize, Serialize};

pub use budget::BudgetedGp;
pub use fit::{Bounds, FitOptions, FitReport, StartOutcome};
pub use likelihood::{
    evaluation_flops, model_flops, negative_log_marginal_likelihood, nlml_with_gradient,
    LikelihoodGradient,
};
pub use model::{GaussianProcess, PendingAppend, PointPrediction, Predictions, BATCH_THRESHOLD};
pub use synthetic::{benchmark_problem, BENCHMARK_NOISE_SD};
pub use tracked::{TrackedPoints, Tracking};

/// Everything that can go wrong; nothing in this module panics on user data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpError {
    #[error("no training points")]
    NoPoints,
    #[error("inputs have dimension 0")]
    ZeroDimension,
    #[error("{len} input values do not make whole rows of {dim}")]
    RaggedInputs { len: usize, dim: usize },
    #[error("{what} has {found} entries, expected {expected}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    #[error("{what}[{index}] is not finite ({value})")]
    NotFinite {
        what: &'static str,
        index: usize,
        value: f64,
    },
    #[error("covariance matrix is not positive definite even with jitter {jitter:e}")]
    NotPositiveDefinite { jitter: f64 },
    #[error("jitter {jitter:e} is outside [0, {limit:e}]")]
    InvalidJitter { jitter: f64, limit: f64 },
    #[error("index {index} is out of range for {len} training points")]
    IndexOutOfRange { index: usize, len: usize },
    #[error("cannot remove the only training point")]
    LastPoint,
    #[error("invalid fit options: {0}")]
    InvalidOptions(String),
    #[error("no start of the hyperparameter fit succeeded: {0}")]
    FitFailed(String),
}

/// Points in the input space: `len()` rows of `dim()` features, stored row-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "InputsData")]
pub struct Inputs {
    dim: usize,
    values: Vec<f64>,
}

#[derive(Deserialize)]
struct InputsData {
    dim: usize,
    values: Vec<f64>,
}

impl TryFrom<InputsData> for Inputs {
    type Error = GpError;
    fn try_from(data: InputsData) -> Result<Self, GpError> {
        Inputs::from_row_major(data.dim, data.values)
    }
}

impl Inputs {
    /// Rows of `dim` values laid end to end. Zero rows is allowed (an empty test set); a
    /// training set is checked for that where it is used.
    pub fn from_row_major(dim: usize, values: Vec<f64>) -> Result<Self, GpError> {
        if dim == 0 {
            return Err(GpError::ZeroDimension);
        }
        if !values.len().is_multiple_of(dim) {
            return Err(GpError::RaggedInputs {
                len: values.len(),
                dim,
            });
        }
        check_finite("inputs", &values)?;
        Ok(Self { dim, values })
    }

    /// One slice per point; all must have the same length.
    pub fn from_rows<R: AsRef<[f64]>>(rows: &[R]) -> Result<Self, GpError> {
        let dim = rows.first().map_or(0, |r| r.as_ref().len());
        let mut values = Vec::with_capacity(dim * rows.len());
        for row in rows {
            let row = row.as_ref();
            if row.len() != dim {
                return Err(GpError::LengthMismatch {
                    what: "input row",
                    expected: dim,
                    found: row.len(),
                });
            }
            values.extend_from_slice(row);
        }
        Self::from_row_major(dim, values)
    }

    pub fn len(&self) -> usize {
        self.values.len() / self.dim
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The `i`-th point. Panics if `i >= len()`, like slice indexing.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.dim..(i + 1) * self.dim]
    }

    pub fn rows(&self) -> impl ExactSizeIterator<Item = &[f64]> + '_ {
        self.values.chunks_exact(self.dim)
    }

    pub fn as_row_major(&self) -> &[f64] {
        &self.values
    }

    /// Per-feature standard deviation (population); 1 for a constant feature, so that it can
    /// scale a lengthscale.
    pub fn feature_scales(&self) -> Vec<f64> {
        let n = self.len();
        (0..self.dim)
            .map(|t| {
                let column = self.values.iter().skip(t).step_by(self.dim);
                scale_or_one(spread(column, n).1.sqrt())
            })
            .collect()
    }

    fn push(&mut self, x: &[f64]) {
        self.values.extend_from_slice(x);
    }

    fn remove(&mut self, i: usize) {
        self.values.drain(i * self.dim..(i + 1) * self.dim);
    }
}

/// The largest magnitude a log-hyperparameter may have.
pub const LOG_LIMIT: f64 = 300.0;

/// Hyperparameters in the log space the optimiser works in: `log l_1..l_d`, `log σ_f²`,
/// `log σ_n²` (in this order in [`Hyperparameters::to_log_vector`] and in gradients).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    pub log_lengthscales: Vec<f64>,
    pub log_signal_variance: f64,
    pub log_noise_variance: f64,
}

impl Hyperparameters {
    /// From lengthscales and variances on their natural scale; all must be positive and finite.
    pub fn new(
        lengthscales: &[f64],
        signal_variance: f64,
        noise_variance: f64,
    ) -> Result<Self, GpError> {
        let positive = |what, index, value: f64| {
            if value > 0.0 && value.is_finite() {
                Ok(value.ln())
            } else {
                Err(GpError::NotFinite { what, index, value })
            }
        };
        Ok(Self {
            log_lengthscales: lengthscales
                .iter()
                .enumerate()
                .map(|(i, &l)| positive("lengthscales", i, l))
                .collect::<Result<_, _>>()?,
            log_signal_variance: positive("signal variance", 0, signal_variance)?,
            log_noise_variance: positive("noise variance", 0, noise_variance)?,
        })
    }

    /// The inverse of [`Hyperparameters::to_log_vector`]: `d + 2` log values.
    pub fn from_log_vector(dim: usize, theta: &[f64]) -> Result<Self, GpError> {
        if theta.len() != dim + 2 {
            return Err(GpError::LengthMismatch {
                what: "log-hyperparameter vector",
                expected: dim + 2,
                found: theta.len(),
            });
        }
        let hyper = Self {
            log_lengthscales: theta[..dim].to_vec(),
            log_signal_variance: theta[dim],
            log_noise_variance: theta[dim + 1],
        };
        hyper.validate(dim)?;
        Ok(hyper)
    }

    pub fn to_log_vector(&self) -> Vec<f64> {
        let mut theta = self.log_lengthscales.clone();
        theta.push(self.log_signal_variance);
        theta.push(self.log_noise_variance);
        theta
    }

    pub fn dim(&self) -> usize {
        self.log_lengthscales.len()
    }

    pub fn lengthscales(&self) -> Vec<f64> {
        self.log_lengthscales.iter().map(|l| l.exp()).collect()
    }

    pub fn signal_variance(&self) -> f64 {
        self.log_signal_variance.exp()
    }

    pub fn noise_variance(&self) -> f64 {
        self.log_noise_variance.exp()
    }

    /// The noise-free Matérn 3/2 ARD covariance `k(a, b)` (eq. (6) with `r` of eq. (7)).
    pub fn covariance(&self, a: &[f64], b: &[f64]) -> Result<f64, GpError> {
        self.validate(a.len())?;
        check_len("second point", a.len(), b.len())?;
        let inv = self.inverse_lengthscales();
        Ok(kernel::matern32(
            self.signal_variance(),
            kernel::scaled_sq_distance(a, b, &inv).sqrt(),
        ))
    }

    /// `dim` lengthscales, and log values within ±[`LOG_LIMIT`], so that every value stays
    /// positive and finite on the natural scale.
    pub fn validate(&self, dim: usize) -> Result<(), GpError> {
        check_len("log lengthscales", dim, self.log_lengthscales.len())?;
        let logs = self
            .log_lengthscales
            .iter()
            .enumerate()
            .map(|(i, l)| ("log lengthscales", i, *l))
            .chain([
                ("log signal variance", 0, self.log_signal_variance),
                ("log noise variance", 0, self.log_noise_variance),
            ]);
        for (what, index, value) in logs {
            // exp overflows past ~709.8; keep a margin so that sums and squares of scaled
            // inputs stay finite.
            if !value.is_finite() || value.abs() > LOG_LIMIT {
                return Err(GpError::NotFinite { what, index, value });
            }
        }
        Ok(())
    }

    fn inverse_lengthscales(&self) -> Vec<f64> {
        self.log_lengthscales.iter().map(|l| (-l).exp()).collect()
    }
}

fn check_finite(what: &'static str, values: &[f64]) -> Result<(), GpError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(GpError::NotFinite {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), GpError> {
    if expected == found {
        Ok(())
    } else {
        Err(GpError::LengthMismatch {
            what,
            expected,
            found,
        })
    }
}

/// A training set as the fit and the model need it: at least one point, finite, one target per
/// point, and hyperparameters (if any) of the right dimension.
fn check_training(inputs: &Inputs, targets: &[f64]) -> Result<(), GpError> {
    if inputs.is_empty() {
        return Err(GpError::NoPoints);
    }
    check_len("targets", inputs.len(), targets.len())?;
    check_finite("targets", targets)
}

/// (mean, population variance) of `n` values.
fn spread<'a>(values: impl Iterator<Item = &'a f64> + Clone, n: usize) -> (f64, f64) {
    let n = n.max(1) as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
    (mean, var)
}

/// A positive scale, or 1 when the data give none (constant or empty).
fn scale_or_one(s: f64) -> f64 {
    if s > 0.0 && s.is_finite() {
        s
    } else {
        1.0
    }
}

/// The targets' variance, the scale for σ_f², σ_n² and the noise floor: the variance when the
/// targets vary, their mean square when they are constant, 1 when they are all zero.
fn target_scale(targets: &[f64]) -> f64 {
    let (mean, var) = spread(targets.iter(), targets.len());
    if var > 0.0 && var.is_finite() {
        var
    } else {
        scale_or_one(mean * mean)
    }
}

#[cfg(test)]
mod tests;
