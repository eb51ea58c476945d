//! The negative log marginal likelihood (eq. (12)) and its analytic gradient with respect to
//! all log-hyperparameters, and the jittered Cholesky factorisation they and the model share.
//!
//! With `K = K_f + σ_n² I` (plus jitter, see [`factorise`]), `α = K⁻¹y` and
//! `W = K⁻¹ − ααᵀ`, `∂NLML/∂θ = ½ tr(W ∂K/∂θ)` (Rasmussen & Williams eq. 5.9). `K⁻¹` comes
//! from the factor (faer's triangular inverse and product, `O(N³)` once per evaluation); the
//! traces then cost `O(N² d)` together, not `O(N³ d)`, and no `∂K/∂θ` is formed:
//!
//! - `σ_f²` and `σ_n²`: `½ Σ_ij W_ij K_f,ij` and `½ σ_n² tr W`, in one pass over the lower
//!   triangles;
//! - `log l_d`: with `∂K_ij/∂log l_d = D_ij (z_id − z_jd)²`, `D = 3 σ_f² e^{−√3 r}` (kernel.rs)
//!   and `A = W ∘ D` (zero diagonal: `∂K_ii/∂l = 0`),
//!   `½ Σ_ij A_ij (z_id − z_jd)² = Σ_i s_i z_id² − Σ_i z_id (A Z)_id`, `s = A 1`; the
//!   same pass builds `A` (over `K⁻¹`, in place) and `s`, and `A Z` is one `N × N` by `N × d`
//!   product (two triangular faer products), `O(N² d)` at matrix-product speed.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::{factor, inverse};
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::{Accum, Mat, Par};

use super::kernel::{clear_upper_vector_state, dot, fill_lower, scaled_centred};
use super::{check_training, GpError, Hyperparameters, Inputs};

/// The first jitter tried when a factorisation fails, relative to the mean of `K`'s diagonal.
pub(crate) const JITTER_FIRST: f64 = 1e-10;
/// The factor between successive jitters.
pub(crate) const JITTER_GROWTH: f64 = 10.0;
/// The largest jitter tried, relative to the mean diagonal, before giving up.
pub(crate) const JITTER_LIMIT: f64 = 1e-4;

/// A likelihood value with its gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct LikelihoodGradient {
    /// `−log p(y | X, φ)`, eq. (12).
    pub nlml: f64,
    /// `∂NLML/∂(log l_1..l_d, log σ_f², log σ_n²)`.
    pub gradient: Vec<f64>,
    /// The jitter added to `K`'s diagonal (0 when the plain factorisation succeeded).
    pub jitter: f64,
}

/// Eq. (12) at the given hyperparameters.
pub fn negative_log_marginal_likelihood(
    inputs: &Inputs,
    targets: &[f64],
    hyper: &Hyperparameters,
) -> Result<f64, GpError> {
    let mut work = Workspace::new(inputs.len());
    Ok(work.evaluate(inputs, targets, hyper, false)?.nlml)
}

/// Eq. (12) and its gradient with respect to all log-hyperparameters.
pub fn nlml_with_gradient(
    inputs: &Inputs,
    targets: &[f64],
    hyper: &Hyperparameters,
) -> Result<LikelihoodGradient, GpError> {
    let mut work = Workspace::new(inputs.len());
    work.evaluate(inputs, targets, hyper, true)
}

/// Floating-point operations of one evaluation of the NLML with its gradient at `n` points of
/// `dim` inputs ([`nlml_with_gradient`], one L-BFGS evaluation of a fit), counted from the code
/// below: every add, subtract, multiply, divide, max, square root and exponential is one
/// operation (an exponential costs far more than one multiply, so the elementwise passes weigh
/// more in time than in this count). `p = n(n−1)/2` pairs below the diagonal.
///
/// | step | operations |
/// | --- | --- |
/// | scaled, centred inputs `Z` | `4nd` |
/// | Gram matrix `Z Zᵀ`, lower triangle with diagonal (faer) | `n(n+1)d` |
/// | `K_f` and `3σ_f² e^{−√3r}` from it ([`fill_lower`]) | `13p` |
/// | `K_f + σ_n² I`, Cholesky (faer) | `2n + n³/3 + n²/2 + n/6` |
/// | pivot check, `α = K⁻¹y` (two triangular solves), `log det`, `yᵀα` | `2n + 2n² + n + 4n` |
/// | `K⁻¹ = L⁻ᵀ L⁻¹`: triangular inverse and product (faer) | `2n³/3` |
/// | `W = K⁻¹ − ααᵀ`, `A = W ∘ D`, `σ_f²`, `σ_n²` traces, `A 1` | `8p + 6n` |
/// | `A Z` (two triangular products, faer) | `4pd` |
/// | the `d` lengthscale traces | `5nd` |
///
/// In all `n³ + 3n²d + O(n²)`: at n = 1000, d = 40, 1.13e9, nine tenths of them in the
/// Cholesky factor and the inverse.
pub fn evaluation_flops(n: usize, dim: usize) -> f64 {
    let (n, d) = (n as f64, dim as f64);
    let p = n * (n - 1.0) / 2.0;
    4.0 * n * d
        + n * (n + 1.0) * d
        + 13.0 * p
        + 2.0 * n
        + n * n * n / 3.0
        + n * n / 2.0
        + n / 6.0
        + 2.0 * n * n
        + 7.0 * n
        + 2.0 * n * n * n / 3.0
        + 8.0 * p
        + 6.0 * n
        + 4.0 * p * d
        + 5.0 * n * d
}

/// Floating-point operations of building a model at given hyperparameters
/// ([`GaussianProcess::new`](super::GaussianProcess::new), which a fit does once at the end):
/// `Z`, the Gram matrix, `K_f` (11 operations a pair, no derivative factor), the Cholesky
/// factor and the whitened targets `L⁻¹y` (`n²`), counted as in [`evaluation_flops`].
pub fn model_flops(n: usize, dim: usize) -> f64 {
    let (n, d) = (n as f64, dim as f64);
    let p = n * (n - 1.0) / 2.0;
    4.0 * n * d
        + n * (n + 1.0) * d
        + 11.0 * p
        + 2.0 * n
        + n * n * n / 3.0
        + n * n / 2.0
        + n / 6.0
        + n * n
}

/// Buffers kept across the evaluations of one fit: four `N × N` matrices (`K_f`, the length-
/// scale derivative factor, the Cholesky factor, `K⁻¹`) and faer's scratch space, so that an
/// L-BFGS run allocates them once.
pub(crate) struct Workspace {
    kf: Mat<f64>,
    dk: Mat<f64>,
    factor: Mat<f64>,
    inverse: Mat<f64>,
    scratch: MemBuffer,
}

impl Workspace {
    pub(crate) fn new(n: usize) -> Self {
        let scratch = StackReq::any_of(&[
            factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()),
            inverse::inverse_scratch::<f64>(n, Par::Seq),
        ]);
        Self {
            kf: Mat::zeros(n, n),
            dk: Mat::zeros(0, 0),
            factor: Mat::zeros(n, n),
            inverse: Mat::zeros(0, 0),
            scratch: MemBuffer::new(scratch),
        }
    }

    /// The NLML and, with `with_gradient`, its gradient (otherwise an empty vector).
    pub(crate) fn evaluate(
        &mut self,
        inputs: &Inputs,
        targets: &[f64],
        hyper: &Hyperparameters,
        with_gradient: bool,
    ) -> Result<LikelihoodGradient, GpError> {
        check_training(inputs, targets)?;
        let dim = inputs.dim();
        hyper.validate(dim)?;
        let n = inputs.len();
        if self.kf.nrows() != n {
            *self = Self::new(n);
        }
        if with_gradient && self.dk.nrows() != n {
            self.dk = Mat::zeros(n, n);
            self.inverse = Mat::zeros(n, n);
        }

        let z = scaled_centred(inputs.as_row_major(), &hyper.inverse_lengthscales());
        let signal_variance = hyper.signal_variance();
        let noise_variance = hyper.noise_variance();
        fill_lower(
            &z,
            signal_variance,
            &mut self.kf,
            with_gradient.then_some(&mut self.dk),
        );
        let jitter = factorise(
            &self.kf,
            noise_variance,
            0.0,
            &mut self.factor,
            &mut self.scratch,
        )?;
        let alpha = solve_with_factor(&self.factor, targets);
        let half_log_det: f64 = (0..n).map(|j| self.factor[(j, j)].ln()).sum();
        let data_fit: f64 = targets.iter().zip(&alpha).map(|(y, a)| y * a).sum();
        let nlml =
            0.5 * data_fit + half_log_det + 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
        if !nlml.is_finite() {
            return Err(GpError::NotPositiveDefinite { jitter });
        }
        if !with_gradient {
            return Ok(LikelihoodGradient {
                nlml,
                gradient: Vec::new(),
                jitter,
            });
        }

        let gradient = self.gradient(&z, &alpha, noise_variance);
        Ok(LikelihoodGradient {
            nlml,
            gradient,
            jitter,
        })
    }

    /// The NLML's gradient in the log length-scales, then the log signal and noise variances,
    /// from the factor, `K_f` and its length-scale factor in the workspace (`α = K⁻¹y`).
    fn gradient(&mut self, z: &Mat<f64>, alpha: &[f64], noise_variance: f64) -> Vec<f64> {
        let n = alpha.len();
        // Lower triangle of K⁻¹ = L⁻ᵀ L⁻¹.
        inverse::inverse(
            self.inverse.as_mut(),
            self.factor.as_ref(),
            Par::Seq,
            MemStack::new(&mut self.scratch),
        );
        clear_upper_vector_state();
        let mut row_sums = vec![0.0; n];
        let mut signal_terms = vec![0.0; n];
        let mut g_signal = 0.0;
        let mut g_noise = 0.0;
        for j in 0..n {
            let a_col = &mut self.inverse.col_as_slice_mut(j)[j..];
            let kf_col = &self.kf.col_as_slice(j)[j..];
            let dk_col = &self.dk.col_as_slice(j)[j + 1..];
            let aj = alpha[j];
            let w_diag = a_col[0] - aj * aj;
            g_signal += w_diag * kf_col[0];
            g_noise += w_diag * noise_variance;
            // Off-diagonal pairs count twice (W and ∂K are symmetric). The elementwise part
            // first (it vectorises), then the two running sums in the order of the entries.
            let a_col = &mut a_col[1..];
            let terms = &mut signal_terms[j + 1..];
            for ((((a, t), k), d), (s, al)) in a_col
                .iter_mut()
                .zip(terms.iter_mut())
                .zip(&kf_col[1..])
                .zip(dk_col)
                .zip(row_sums[j + 1..].iter_mut().zip(&alpha[j + 1..]))
            {
                let w = *a - al * aj;
                *t = 2.0 * w * k;
                *a = w * d;
                *s += *a;
            }
            let mut sum_j = 0.0;
            for (t, a) in terms.iter().zip(a_col.iter()) {
                g_signal += t;
                sum_j += a;
            }
            row_sums[j] += sum_j;
        }
        let mut gradient = lengthscale_gradient(&self.inverse, z, &row_sums);
        gradient.push(0.5 * g_signal);
        gradient.push(0.5 * g_noise);
        gradient
    }
}

/// The length-scales' part of the gradient: `Σᵢ sᵢ zᵢₜ² − zᵢₜ (A Z)ᵢₜ` per input dimension `t`,
/// `A` symmetric with a zero diagonal held in the strict lower triangle of `a`, `s` its row sums.
fn lengthscale_gradient(a: &Mat<f64>, z: &Mat<f64>, row_sums: &[f64]) -> Vec<f64> {
    let (n, dim) = (z.nrows(), z.ncols());
    let mut az = Mat::zeros(n, dim);
    triangular::matmul(
        az.as_mut(),
        BlockStructure::Rectangular,
        Accum::Replace,
        a.as_ref(),
        BlockStructure::StrictTriangularLower,
        z.as_ref(),
        BlockStructure::Rectangular,
        1.0,
        Par::Seq,
    );
    triangular::matmul(
        az.as_mut(),
        BlockStructure::Rectangular,
        Accum::Add,
        a.as_ref().transpose(),
        BlockStructure::StrictTriangularUpper,
        z.as_ref(),
        BlockStructure::Rectangular,
        1.0,
        Par::Seq,
    );
    clear_upper_vector_state();
    (0..dim)
        .map(|t| {
            let zt = z.col_as_slice(t);
            let azt = az.col_as_slice(t);
            zt.iter()
                .zip(azt)
                .zip(row_sums)
                .map(|((z, az), s)| s * z * z - z * az)
                .sum()
        })
        .collect()
}

/// Cholesky factor of `K = K_f + (noise_variance + jitter) I` into the lower triangle of `out`
/// (`K_f` is read from the lower triangle of `kf`); returns the jitter used.
///
/// The first try uses `first_jitter` (0 for a fresh model; the stored jitter when a model is
/// reloaded, so that it gets the same factor). A try fails when faer meets a non-positive
/// pivot or when a pivot `L_ii²` falls below `n ε` times the mean diagonal: such a pivot is
/// rounding noise (duplicated inputs with almost no noise), and dividing by it would turn `α`
/// into noise too. On failure the jitter becomes `1e-10 ×` the mean diagonal, then grows ×10 up
/// to `1e-4 ×` it.
pub(crate) fn factorise(
    kf: &Mat<f64>,
    noise_variance: f64,
    first_jitter: f64,
    out: &mut Mat<f64>,
    scratch: &mut MemBuffer,
) -> Result<f64, GpError> {
    let n = kf.nrows();
    if out.nrows() != n || out.ncols() != n {
        *out = Mat::zeros(n, n);
    }
    let mean_diagonal = if n > 0 {
        (0..n).map(|j| kf[(j, j)]).sum::<f64>() / n as f64 + noise_variance
    } else {
        noise_variance
    };
    let limit = JITTER_LIMIT * mean_diagonal;
    let smallest_pivot = n as f64 * f64::EPSILON * mean_diagonal;
    if !(first_jitter >= 0.0 && first_jitter <= limit * (1.0 + 1e-9)) {
        return Err(GpError::InvalidJitter {
            jitter: first_jitter,
            limit,
        });
    }
    let mut jitter = first_jitter;
    loop {
        for j in 0..n {
            let src = &kf.col_as_slice(j)[j..];
            let dst = &mut out.col_as_slice_mut(j)[j..];
            dst.copy_from_slice(src);
            dst[0] += noise_variance + jitter;
        }
        let factored = factor::cholesky_in_place(
            out.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(scratch),
            Default::default(),
        );
        clear_upper_vector_state();
        let pivots_ok = factored.is_ok()
            && (0..n).all(|j| {
                let p = out[(j, j)];
                p.is_finite() && p * p > smallest_pivot
            });
        if pivots_ok {
            return Ok(jitter);
        }
        jitter = if jitter == 0.0 {
            JITTER_FIRST * mean_diagonal
        } else {
            jitter * JITTER_GROWTH
        };
        // A relative tolerance: the schedule's last step lands on the limit up to rounding.
        if jitter > limit * (1.0 + 1e-9) {
            return Err(GpError::NotPositiveDefinite {
                jitter: jitter / JITTER_GROWTH,
            });
        }
    }
}

/// `K⁻¹ y` from the lower Cholesky factor in `l` (column-major: both triangular solves walk
/// contiguous columns).
pub(crate) fn solve_with_factor(l: &Mat<f64>, y: &[f64]) -> Vec<f64> {
    let n = l.nrows();
    let mut x = y.to_vec();
    for j in 0..n {
        let col = l.col_as_slice(j);
        x[j] /= col[j];
        let xj = x[j];
        for (xi, lij) in x[j + 1..].iter_mut().zip(&col[j + 1..]) {
            *xi -= lij * xj;
        }
    }
    for j in (0..n).rev() {
        let col = l.col_as_slice(j);
        x[j] = (x[j] - dot(&x[j + 1..], &col[j + 1..])) / col[j];
    }
    x
}

/// A workspace-owned factorisation for the model: `K_f` of the training set and its jittered
/// factor. Returns (factor, jitter).
pub(crate) fn factor_training_set(
    inputs: &Inputs,
    hyper: &Hyperparameters,
    first_jitter: f64,
) -> Result<(Mat<f64>, f64), GpError> {
    let n = inputs.len();
    let z = scaled_centred(inputs.as_row_major(), &hyper.inverse_lengthscales());
    let mut kf = Mat::zeros(n, n);
    fill_lower(&z, hyper.signal_variance(), &mut kf, None);
    let mut out = Mat::zeros(n, n);
    let mut scratch = MemBuffer::new(factor::cholesky_in_place_scratch::<f64>(
        n,
        Par::Seq,
        Default::default(),
    ));
    let jitter = factorise(
        &kf,
        hyper.noise_variance(),
        first_jitter,
        &mut out,
        &mut scratch,
    )?;
    Ok((out, jitter))
}
