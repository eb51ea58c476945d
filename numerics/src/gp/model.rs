//! A trained GP: training set, hyperparameters, Cholesky factor and `α`; predictions (eqs. (10)
//! and (11)), appending and removing points, and serialisation.
//!
//! The factor is kept as packed rows of the lower triangle (row `i` holds `L_i0..L_ii`), so that
//! appending a point pushes one row without moving the others, the forward solve of a
//! prediction reads each row contiguously, and removing a point compacts the rows in one pass.
//!
//! Every state of a model has a version, unique in the process (a clone shares it: same
//! state), and the model keeps a short log of its last incremental changes: the new factor row
//! of an append, the rotations of a removal. A [`super::TrackedPoints`] reads that log to follow
//! the model in `O(n m)` per change instead of solving again in `O(n² m)`.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Mat, Par};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::kernel::{clear_upper_vector_state, dot, matern32, scaled_sq_distance};
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
    /// `K⁻¹ y`, solved on first use after a change (a learning loop that reads means through
    /// [`super::TrackedPoints`] never needs it).
    alpha: OnceLock<Vec<f64>>,
    /// This state's version (see the module doc).
    version: u64,
    /// A second buffer for the factor, so that a removal writes the compacted, rotated rows in
    /// one pass (not copied with the model).
    spare: Spare,
    /// The last incremental changes, oldest first, each from the version before the next
    /// (the last one's from the version before the current).
    log: VecDeque<LoggedChange>,
}

/// Scratch space that a clone does not copy.
#[derive(Default)]
struct Spare(Vec<f64>);

impl Clone for Spare {
    fn clone(&self) -> Self {
        Spare(Vec::new())
    }
}

impl std::fmt::Debug for Spare {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Spare({})", self.0.capacity())
    }
}

/// Changes a model remembers: a learning step appends, and at the size limit also removes, so
/// a follower that syncs after every step needs two; eight leave room.
const CHANGE_LOG: usize = 8;

/// A fresh version number.
fn next_version() -> u64 {
    static VERSIONS: AtomicU64 = AtomicU64::new(1);
    VERSIONS.fetch_add(1, Ordering::Relaxed)
}

/// One incremental change of a model, as a follower needs it.
#[derive(Clone, Debug)]
pub(crate) enum Change {
    /// A point `x` appended: the new factor row is `[wᵀ, d]` and `whitened` the new entry of
    /// `L⁻¹ y`.
    Appended {
        x: Vec<f64>,
        w: Vec<f64>,
        d: f64,
        whitened: f64,
    },
    /// Point `index` removed: the rows of `L` below it were rotated with `rotations`
    /// (cos, sin), in order, against the removed column (see [`GaussianProcess::remove`]);
    /// `leftover` is what the rotations left of the removed entry of `L⁻¹y`.
    Removed {
        index: usize,
        rotations: Vec<(f64, f64)>,
        leftover: f64,
    },
}

#[derive(Clone, Debug)]
pub(crate) struct LoggedChange {
    pub(crate) from: u64,
    pub(crate) change: Change,
}

/// An append computed but not yet made: [`GaussianProcess::plan_append`] does the fallible
/// `O(n²)` work on a shared reference, [`GaussianProcess::commit`] applies it, so that several
/// models can be updated all or none.
#[derive(Clone, Debug)]
pub struct PendingAppend {
    /// The version the plan was made from.
    from: u64,
    x: Vec<f64>,
    y: f64,
    kind: PendingKind,
}

#[derive(Clone, Debug)]
enum PendingKind {
    /// The new factor row `[wᵀ, d]` and the new entry of `L⁻¹ y`.
    Row { w: Vec<f64>, d: f64, whitened: f64 },
    /// The whole model refactored with jitter (the new pivot was rounding noise).
    Rebuilt(Box<GaussianProcess>),
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
            alpha: OnceLock::new(),
            version: next_version(),
            spare: Spare::default(),
            log: VecDeque::new(),
        };
        model.whitened = model.forward_solve(&model.targets);
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
        self.alpha
            .get_or_init(|| self.backward_solve(&self.whitened))
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
        let mean = dot(&k_star, self.alpha());
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
        let factor = self.dense_factor();
        // Column j: k(x_i, x*_j) for every training point i, then L⁻¹ of it.
        let mut v = Mat::zeros(n, m);
        let mut mean = Vec::with_capacity(m);
        for (j, x) in points.rows().enumerate() {
            let k_star = self.cross_covariance(x);
            mean.push(dot(&k_star, self.alpha()));
            v.col_as_slice_mut(j).copy_from_slice(&k_star);
        }
        solve_lower_triangular_in_place(factor.as_ref(), v.as_mut(), Par::Seq);
        clear_upper_vector_state();
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
        let plan = self.plan_append(x, y)?;
        self.commit(plan)
    }

    /// The work of [`GaussianProcess::append`] without changing the model: checks the point and
    /// computes the new factor row (or, on the jitter path, the refactored model). Everything
    /// that can fail happens here.
    pub fn plan_append(&self, x: &[f64], y: f64) -> Result<PendingAppend, GpError> {
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
        let kind = if schur > smallest_pivot && schur.is_finite() {
            let d = schur.sqrt();
            let whitened = (y - dot(&w, &self.whitened)) / d;
            PendingKind::Row { w, d, whitened }
        } else {
            let mut inputs = self.inputs.clone();
            inputs.push(x);
            let mut targets = self.targets.clone();
            targets.push(y);
            PendingKind::Rebuilt(Box::new(Self::with_first_jitter(
                inputs,
                targets,
                self.hyper.clone(),
                self.jitter,
            )?))
        };
        Ok(PendingAppend {
            from: self.version,
            x: x.to_vec(),
            y,
            kind,
        })
    }

    /// Applies a plan of [`GaussianProcess::plan_append`]: `O(n²)` for the new `α`, and
    /// infallible when the model has not changed since the plan. A plan made from another state
    /// is not applied: the point is appended afresh (which can fail as `append` can).
    pub fn commit(&mut self, plan: PendingAppend) -> Result<(), GpError> {
        if plan.from != self.version {
            return self.append(&plan.x, plan.y);
        }
        match plan.kind {
            PendingKind::Row { w, d, whitened } => {
                self.inputs.push(&plan.x);
                self.targets.push(plan.y);
                self.factor.extend_from_slice(&w);
                self.factor.push(d);
                self.whitened.push(whitened);
                self.alpha = OnceLock::new();
                self.record(Change::Appended {
                    x: plan.x,
                    w,
                    d,
                    whitened,
                });
            }
            PendingKind::Rebuilt(model) => *self = *model,
        }
        Ok(())
    }

    /// A new version, reached from the current one by `change`.
    fn record(&mut self, change: Change) {
        let to = next_version();
        if self.log.len() == CHANGE_LOG {
            self.log.pop_front();
        }
        self.log.push_back(LoggedChange {
            from: self.version,
            change,
        });
        self.version = to;
    }

    /// This state's version (see the module doc).
    pub fn version(&self) -> u64 {
        self.version
    }

    /// The logged changes from `version` to the current one, if the log reaches back to it.
    pub(crate) fn changes_since(
        &self,
        version: u64,
    ) -> Option<impl Iterator<Item = &LoggedChange>> {
        let start = self.log.iter().position(|c| c.from == version)?;
        Some(self.log.iter().skip(start))
    }

    /// Removes training point `index` (for forgetting) in `O(n²)` at fixed hyperparameters.
    ///
    /// Deleting row and column `k` of `K` leaves the rows of `L` above `k` as they are; the
    /// trailing block must satisfy `L₂₂' L₂₂'ᵀ = L₂₂ L₂₂ᵀ + l l ᵀ` with `l` the removed column
    /// below the diagonal, a rank-one *update* (never a downdate, so it cannot lose
    /// definiteness), done with Givens rotations in `O((n − k)²)`: `[L₂₂ | l] Q = [L₂₂' | 0]`.
    /// The same rotations take `L⁻¹y` along (`O(n)`): its trailing part becomes the first
    /// entries of `Qᵀ [(L⁻¹y)₂; (L⁻¹y)_k]`. The rows are read once and written once, compacted
    /// and rotated, into a second buffer kept for the purpose (with room for the next append),
    /// and `α` is solved again when next needed.
    pub fn remove(&mut self, index: usize) -> Result<(), GpError> {
        let n = self.len();
        if index >= n {
            return Err(GpError::IndexOutOfRange { index, len: n });
        }
        if n == 1 {
            return Err(GpError::LastPoint);
        }
        let mut out = std::mem::take(&mut self.spare.0);
        let rotations = remove_and_rotate(&self.factor, n, index, &mut out);
        self.spare.0 = std::mem::replace(&mut self.factor, out);
        // L⁻¹y: rows above `index` keep their entries; the rest rotate against the removed one.
        let mut leftover = self.whitened.remove(index);
        for (v, (c, s)) in self.whitened[index..].iter_mut().zip(&rotations) {
            let (a, b) = (*v, leftover);
            *v = c * a + s * b;
            leftover = c * b - s * a;
        }
        self.inputs.remove(index);
        self.targets.remove(index);
        self.alpha = OnceLock::new();
        self.record(Change::Removed {
            index,
            rotations,
            leftover,
        });
        Ok(())
    }

    /// `L⁻¹ y`.
    pub(crate) fn whitened(&self) -> &[f64] {
        &self.whitened
    }

    /// The factor as a dense lower-triangular faer matrix (`O(n²)`).
    pub(crate) fn dense_factor(&self) -> Mat<f64> {
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
        factor
    }

    /// `k(x, x_i)` for every training point.
    pub(crate) fn cross_covariance(&self, x: &[f64]) -> Vec<f64> {
        let inv_l = self.hyper.inverse_lengthscales();
        let signal_variance = self.hyper.signal_variance();
        self.inputs
            .rows()
            .map(|xi| matern32(signal_variance, scaled_sq_distance(xi, x, &inv_l).sqrt()))
            .collect()
    }

    /// `L⁻¹ b` (rows of the packed factor are contiguous).
    pub(crate) fn forward_solve(&self, b: &[f64]) -> Vec<f64> {
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

/// Packed factor `src` (`n` rows) without row and column `index`, the rows below rotated
/// (the rank-one update of [`GaussianProcess::remove`]), written to `out`; returns the
/// rotations (cos, sin) in order. Rotation `a` combines column `a` of the trailing block with
/// what is left of the removed column, `(cos, sin) = (L_aa, x_a) / r`, `L_aa ← r`.
///
/// Each entry of a row goes through the rotations of the columns before it, a chain of
/// dependent operations; four rows go through the shared columns together, so that four
/// independent chains keep the floating-point units busy. One pass over the factor.
fn remove_and_rotate(src: &[f64], n: usize, index: usize, out: &mut Vec<f64>) -> Vec<(f64, f64)> {
    out.clear();
    out.reserve(row_start(n));
    out.extend_from_slice(&src[..row_start(index)]);
    out.resize(row_start(n - 1), 0.0);
    let m = n - 1 - index;
    let mut rotations: Vec<(f64, f64)> = Vec::with_capacity(m);
    // New row index + a is old row index + 1 + a.
    let old = |a: usize| row_start(index + 1 + a);
    let new = |a: usize| row_start(index + a);
    let mut a = 0;
    while a < m {
        let group = 4.min(m - a);
        let mut xi = [0.0f64; 4];
        for (g, x) in xi.iter_mut().enumerate().take(group) {
            let (o, w) = (old(a + g), new(a + g));
            out[w..w + index].copy_from_slice(&src[o..o + index]);
            *x = src[o + index];
        }
        // The columns before the group's first row, shared by the whole group.
        if group == 4 {
            let o = [0, 1, 2, 3].map(|g| old(a + g) + index + 1);
            let (s0, s1, s2, s3) = (
                &src[o[0]..o[0] + a],
                &src[o[1]..o[1] + a],
                &src[o[2]..o[2] + a],
                &src[o[3]..o[3] + a],
            );
            // The group's new rows are consecutive: split them off one after the other.
            let block = &mut out[new(a) + index..];
            let (d0, rest) = block.split_at_mut(a + index + 1);
            let (d1, rest) = rest.split_at_mut(a + index + 2);
            let (d2, rest) = rest.split_at_mut(a + index + 3);
            let (d0, d1, d2, d3) = (&mut d0[..a], &mut d1[..a], &mut d2[..a], &mut rest[..a]);
            let [mut x0, mut x1, mut x2, mut x3] = xi;
            for (col, (c, s)) in rotations.iter().enumerate() {
                let (l0, l1, l2, l3) = (s0[col], s1[col], s2[col], s3[col]);
                d0[col] = c * l0 + s * x0;
                d1[col] = c * l1 + s * x1;
                d2[col] = c * l2 + s * x2;
                d3[col] = c * l3 + s * x3;
                x0 = c * x0 - s * l0;
                x1 = c * x1 - s * l1;
                x2 = c * x2 - s * l2;
                x3 = c * x3 - s * l3;
            }
            xi = [x0, x1, x2, x3];
        } else {
            for (col, (c, s)) in rotations.iter().enumerate() {
                for g in 0..group {
                    let l = src[old(a + g) + index + 1 + col];
                    out[new(a + g) + index + col] = c * l + s * xi[g];
                    xi[g] = c * xi[g] - s * l;
                }
            }
        }
        // Within the group, one row after the other: row g takes the rotations of the rows
        // before it in the group, then makes its own from its diagonal.
        for g in 0..group {
            let (o, w) = (old(a + g), new(a + g));
            let mut x = xi[g];
            for col in a..a + g {
                let (c, s) = rotations[col];
                let l = src[o + index + 1 + col];
                out[w + index + col] = c * l + s * x;
                x = c * x - s * l;
            }
            let diag = src[o + index + 1 + a + g];
            let r = diag.hypot(x);
            rotations.push((diag / r, x / r));
            out[w + index + a + g] = r;
        }
        a += group;
    }
    rotations
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
