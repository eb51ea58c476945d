//! A trained GP: training set, hyperparameters, Cholesky factor and `α`; predictions (eqs. (10)
//! and (11)), appending and removing points, and serialisation.
//!
//! The factor is kept as packed rows of the lower triangle (row `i` holds `L_i0..L_ii`), so that
//! appending a point pushes one row without moving the others, the forward solve of a
//! prediction reads each row contiguously, and removing a point compacts the rows in one pass.

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Mat, Par};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::kernel::{dot, matern32, scaled_sq_distance};
use super::likelihood::factor_training_set;
use super::{check_finite, check_len, check_training, GpError, Hyperparameters, Inputs};

/// A zero-mean GP on one output with Matérn 3/2 ARD covariance and Gaussian noise.
#[derive(Clone, Debug)]
pub struct GaussianProcess {
    inputs: Inputs,
    targets: Vec<f64>,
    hyper: Hyperparameters,
    /// Added to `K`'s diagonal on top of `σ_n²` when the plain factorisation failed.
    jitter: f64,
    /// `L` with `LLᵀ = K_f + (σ_n² + jitter) I`, packed rows.
    factor: Vec<f64>,
    /// `L⁻¹ y`, kept so that appending a point extends it by one entry.
    whitened: Vec<f64>,
    /// `K⁻¹ y`.
    alpha: Vec<f64>,
}

/// Mean and variances at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointPrediction {
    /// `E(f*) = k*ᵀ K⁻¹ y`, eq. (10).
    pub mean: f64,
    /// `V(f*) = k** − k*ᵀ K⁻¹ k*`: eq. (11) without the noise, the quantity Algorithm 1
    /// compares with its threshold. Clamped at 0 against rounding.
    pub latent_variance: f64,
    /// `V(y*) = V(f*) + σ_n²`, eq. (11).
    pub predictive_variance: f64,
}

/// [`PointPrediction`]s at many points, one vector per quantity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Predictions {
    pub mean: Vec<f64>,
    pub latent_variance: Vec<f64>,
    pub predictive_variance: Vec<f64>,
}

/// From this many test points on, [`GaussianProcess::predict`] solves them as one block.
pub const BATCH_THRESHOLD: usize = 8;

/// Start of packed row `i`.
#[inline]
fn row_start(i: usize) -> usize {
    i * (i + 1) / 2
}

impl GaussianProcess {
    /// A model at given hyperparameters: checks the data, then factorises `K` (`O(n³)`).
    pub fn new(inputs: Inputs, targets: Vec<f64>, hyper: Hyperparameters) -> Result<Self, GpError> {
        Self::with_first_jitter(inputs, targets, hyper, 0.0)
    }

    fn with_first_jitter(
        inputs: Inputs,
        targets: Vec<f64>,
        hyper: Hyperparameters,
        first_jitter: f64,
    ) -> Result<Self, GpError> {
        check_training(&inputs, &targets)?;
        hyper.validate(inputs.dim())?;
        let (dense, jitter) = factor_training_set(&inputs, &hyper, first_jitter)?;
        let factor = pack_lower(&dense);
        let mut model = Self {
            inputs,
            targets,
            hyper,
            jitter,
            factor,
            whitened: Vec::new(),
            alpha: Vec::new(),
        };
        model.whitened = model.forward_solve(&model.targets);
        model.alpha = model.backward_solve(&model.whitened);
        Ok(model)
    }

    pub fn inputs(&self) -> &Inputs {
        &self.inputs
    }

    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    pub fn hyperparameters(&self) -> &Hyperparameters {
        &self.hyper
    }

    /// The jitter on `K`'s diagonal besides `σ_n²` (0 unless the factorisation needed it).
    pub fn jitter(&self) -> f64 {
        self.jitter
    }

    /// Number of training points.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// Always false: a model has at least one training point.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    pub fn dim(&self) -> usize {
        self.inputs.dim()
    }

    /// `K⁻¹ y` (`K` with noise and jitter).
    pub fn alpha(&self) -> &[f64] {
        &self.alpha
    }

    /// Eq. (12) at the model's hyperparameters, from the factor it holds (`O(n)`).
    pub fn negative_log_marginal_likelihood(&self) -> f64 {
        let n = self.len();
        let half_log_det: f64 = (0..n).map(|i| self.factor[row_start(i) + i].ln()).sum();
        let data_fit = dot(&self.whitened, &self.whitened);
        0.5 * data_fit + half_log_det + 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln()
    }

    /// Mean, latent and predictive variance at one point: `O(n d)` for `k*`, `O(n²)` for the
    /// forward solve.
    pub fn predict_point(&self, x: &[f64]) -> Result<PointPrediction, GpError> {
        check_len("test point", self.dim(), x.len())?;
        check_finite("test point", x)?;
        let k_star = self.cross_covariance(x);
        let mean = dot(&k_star, &self.alpha);
        let v = self.forward_solve(&k_star);
        let explained = dot(&v, &v);
        let latent_variance = (self.hyper.signal_variance() - explained).max(0.0);
        Ok(PointPrediction {
            mean,
            latent_variance,
            predictive_variance: latent_variance + self.hyper.noise_variance(),
        })
    }

    /// [`GaussianProcess::predict_point`] at every row of `points`. From
    /// [`BATCH_THRESHOLD`] points on, the `m` forward solves are one blocked triangular solve
    /// with `m` right-hand sides (faer; the factor is unpacked once, `O(n²)`), several times
    /// faster than `m` vector solves; results agree with `predict_point` to rounding.
    pub fn predict(&self, points: &Inputs) -> Result<Predictions, GpError> {
        check_len("test inputs' dimension", self.dim(), points.dim())?;
        let m = points.len();
        if m < BATCH_THRESHOLD {
            let mut out = Predictions {
                mean: Vec::with_capacity(m),
                latent_variance: Vec::with_capacity(m),
                predictive_variance: Vec::with_capacity(m),
            };
            for x in points.rows() {
                let p = self.predict_point(x)?;
                out.mean.push(p.mean);
                out.latent_variance.push(p.latent_variance);
                out.predictive_variance.push(p.predictive_variance);
            }
            return Ok(out);
        }
        let n = self.len();
        let mut factor = Mat::zeros(n, n);
        for i in 0..n {
            for (j, l) in self.factor[row_start(i)..row_start(i) + i + 1]
                .iter()
                .enumerate()
            {
                factor[(i, j)] = *l;
            }
        }
        // Column j: k(x_i, x*_j) for every training point i, then L⁻¹ of it.
        let mut v = Mat::zeros(n, m);
        let mut mean = Vec::with_capacity(m);
        for (j, x) in points.rows().enumerate() {
            let k_star = self.cross_covariance(x);
            mean.push(dot(&k_star, &self.alpha));
            v.col_as_slice_mut(j).copy_from_slice(&k_star);
        }
        solve_lower_triangular_in_place(factor.as_ref(), v.as_mut(), Par::Seq);
        let signal_variance = self.hyper.signal_variance();
        let noise_variance = self.hyper.noise_variance();
        let latent_variance: Vec<f64> = (0..m)
            .map(|j| {
                let col = v.col_as_slice(j);
                (signal_variance - dot(col, col)).max(0.0)
            })
            .collect();
        Ok(Predictions {
            mean,
            predictive_variance: latent_variance.iter().map(|v| v + noise_variance).collect(),
            latent_variance,
        })
    }

    /// Adds a training point in `O(n²)` at fixed hyperparameters: the factor grows by the row
    /// `[wᵀ, d]` with `L w = k`, `d = √(k** + σ_n² + jitter − wᵀw)`; `L⁻¹y` grows by
    /// `(y − wᵀ L⁻¹y) / d`; `α` is solved again with the new factor (one backward solve).
    ///
    /// When `d²` is rounding noise (the point duplicates one already held and the noise is tiny),
    /// the whole factor is recomputed with jitter instead (`O(n³)`, seen in
    /// [`GaussianProcess::jitter`]).
    pub fn append(&mut self, x: &[f64], y: f64) -> Result<(), GpError> {
        check_len("new point", self.dim(), x.len())?;
        check_finite("new point", x)?;
        check_finite("new target", &[y])?;
        let n = self.len();
        let k = self.cross_covariance(x);
        let w = self.forward_solve(&k);
        let diagonal = self.hyper.signal_variance() + self.hyper.noise_variance() + self.jitter;
        let schur = diagonal - dot(&w, &w);
        // The same test as `factorise` applies to a new pivot (mean diagonal = `diagonal`).
        let smallest_pivot = (n + 1) as f64 * f64::EPSILON * diagonal;
        if schur > smallest_pivot && schur.is_finite() {
            let d = schur.sqrt();
            let projected = dot(&w, &self.whitened);
            self.inputs.push(x);
            self.targets.push(y);
            self.factor.extend_from_slice(&w);
            self.factor.push(d);
            self.whitened.push((y - projected) / d);
            self.alpha = self.backward_solve(&self.whitened);
        } else {
            // Built aside, so that a failure leaves the model as it was.
            let mut inputs = self.inputs.clone();
            inputs.push(x);
            let mut targets = self.targets.clone();
            targets.push(y);
            *self = Self::with_first_jitter(inputs, targets, self.hyper.clone(), self.jitter)?;
        }
        Ok(())
    }

    /// Removes training point `index` (for forgetting) in `O(n²)` at fixed hyperparameters.
    ///
    /// Deleting row and column `k` of `K` leaves the rows of `L` above `k` as they are; the
    /// trailing block must satisfy `L₂₂' L₂₂'ᵀ = L₂₂ L₂₂ᵀ + l l ᵀ` with `l` the removed column
    /// below the diagonal, a rank-one *update* (never a downdate, so it cannot lose
    /// definiteness), done with Givens-like rotations in `O((n − k)²)`. `L⁻¹y` and `α` are then
    /// solved again (`O(n²)`).
    pub fn remove(&mut self, index: usize) -> Result<(), GpError> {
        let n = self.len();
        if index >= n {
            return Err(GpError::IndexOutOfRange { index, len: n });
        }
        if n == 1 {
            return Err(GpError::LastPoint);
        }
        // The removed column below the diagonal.
        let mut update: Vec<f64> = (index + 1..n)
            .map(|i| self.factor[row_start(i) + index])
            .collect();
        // Compact the packed rows: drop row `index` and entry `index` of every later row.
        let mut packed = Vec::with_capacity(row_start(n - 1));
        packed.extend_from_slice(&self.factor[..row_start(index)]);
        for i in index + 1..n {
            let row = &self.factor[row_start(i)..row_start(i) + i + 1];
            packed.extend_from_slice(&row[..index]);
            packed.extend_from_slice(&row[index + 1..]);
        }
        // Rank-one update of the trailing block, row by row: row `a` of the block applies the
        // rotations of the columns before it, then makes its own from its diagonal entry.
        // Each rotation is (c, s, 1/c), so that the chain through `xi` holds no division.
        let m = n - 1 - index;
        let mut rotations: Vec<(f64, f64, f64)> = Vec::with_capacity(m);
        for (a, x) in update.iter_mut().enumerate() {
            let i = index + a;
            let row = &mut packed[row_start(i)..row_start(i) + i + 1];
            let mut xi = *x;
            for (l, (c, s, inv_c)) in row[index..index + a].iter_mut().zip(&rotations) {
                let updated = (*l + s * xi) * inv_c;
                xi = c * xi - s * updated;
                *l = updated;
            }
            let diag = row[i];
            let r = diag.hypot(xi);
            rotations.push((r / diag, xi / diag, diag / r));
            row[i] = r;
        }
        self.factor = packed;
        self.inputs.remove(index);
        self.targets.remove(index);
        self.whitened = self.forward_solve(&self.targets);
        self.alpha = self.backward_solve(&self.whitened);
        Ok(())
    }

    /// `k(x, x_i)` for every training point.
    fn cross_covariance(&self, x: &[f64]) -> Vec<f64> {
        let inv_l = self.hyper.inverse_lengthscales();
        let signal_variance = self.hyper.signal_variance();
        self.inputs
            .rows()
            .map(|xi| matern32(signal_variance, scaled_sq_distance(xi, x, &inv_l).sqrt()))
            .collect()
    }

    /// `L⁻¹ b` (rows of the packed factor are contiguous).
    fn forward_solve(&self, b: &[f64]) -> Vec<f64> {
        let mut x = Vec::with_capacity(b.len());
        for (i, bi) in b.iter().enumerate() {
            let row = &self.factor[row_start(i)..row_start(i) + i + 1];
            x.push((bi - dot(&row[..i], &x)) / row[i]);
        }
        x
    }

    /// `L⁻ᵀ b`, column-oriented so that it too reads rows of the packed factor.
    fn backward_solve(&self, b: &[f64]) -> Vec<f64> {
        let mut x = b.to_vec();
        for i in (0..x.len()).rev() {
            let row = &self.factor[row_start(i)..row_start(i) + i + 1];
            x[i] /= row[i];
            let xi = x[i];
            for (xj, l) in x[..i].iter_mut().zip(&row[..i]) {
                *xj -= l * xi;
            }
        }
        x
    }
}

/// The lower triangle of a column-major faer matrix as packed rows.
fn pack_lower(dense: &Mat<f64>) -> Vec<f64> {
    let n = dense.nrows();
    let mut packed = vec![0.0; row_start(n)];
    for j in 0..n {
        let col = dense.col_as_slice(j);
        for (i, v) in col.iter().enumerate().skip(j) {
            packed[row_start(i) + j] = *v;
        }
    }
    packed
}

/// What a model serialises as: the training set, the hyperparameters and the jitter in use;
/// the factor is recomputed on load (`O(n³)`) rather than stored (`n²/2` numbers).
#[derive(Serialize)]
struct SnapshotRef<'a> {
    inputs: &'a Inputs,
    targets: &'a [f64],
    hyperparameters: &'a Hyperparameters,
    jitter: f64,
}

#[derive(Deserialize)]
struct Snapshot {
    inputs: Inputs,
    targets: Vec<f64>,
    hyperparameters: Hyperparameters,
    #[serde(default)]
    jitter: f64,
}

impl Serialize for GaussianProcess {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        SnapshotRef {
            inputs: &self.inputs,
            targets: &self.targets,
            hyperparameters: &self.hyper,
            jitter: self.jitter,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for GaussianProcess {
    /// Validates the snapshot and refactors, starting from the stored jitter: a model whose
    /// factor was computed whole comes back with the same factor, bit for bit.
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let s = Snapshot::deserialize(deserializer)?;
        Self::with_first_jitter(s.inputs, s.targets, s.hyperparameters, s.jitter)
            .map_err(serde::de::Error::custom)
    }
}
