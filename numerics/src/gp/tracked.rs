//! Latent variances and means at a fixed set of `m` points, kept in step with a model whose
//! training set changes: what stream-based active learning needs at every point of a record
//! after every query.
//!
//! With `V = L⁻¹ K(X, X*)` (`n × m`) and `ŷ = L⁻¹ y`, the latent variance at test point `j` is
//! `σ_f² − Σ_i V_ij²` and the mean `Σ_i V_ij ŷ_i` (`= k*ᵀ α`). `V` is built once by a blocked
//! triangular solve (`O(n² m)`, faer), then follows the model through its change log:
//!
//! - an append adds row `(k(x, X*) − wᵀ V) / d`, where `[wᵀ, d]` is the model's new factor
//!   row: the last step of the forward solve with the grown factor, `O(n m)`; variances and
//!   means change by that row's contribution only;
//! - a removal of point `k` deletes row `k` and applies the rotations the model used on its
//!   factor to the rows below and the removed row, `O(n m)`: if `[L₂₂ | l] Q = [L₂₂' | 0]`
//!   (`Q` the rotations), the new trailing rows of `V` are the first rows of `Qᵀ [V₂; v_k]`,
//!   and since `Q` is orthogonal, what is left of `v_k` (`r`, and `ρ` of `ŷ_k`) is what the
//!   point contributed: `Σ V²` loses `r²` and the mean `r ρ`;
//! - anything else (new hyperparameters, a refactorisation with jitter, a model the log does
//!   not reach) rebuilds.
//!
//! The results agree with [`GaussianProcess::predict`] to rounding (the tests check it over
//! long sequences of appends and removals).

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Mat, Par};

use super::kernel::{clear_upper_vector_state, dot, matern32, scaled_sq_distance};
use super::model::{Change, GaussianProcess};
use super::{check_len, GpError, Inputs};

/// Test points solved per block when rebuilding (bounds the `n × block` buffer).
const BLOCK: usize = 256;
/// Fewer new points than this are solved one by one.
const FEW: usize = 16;

/// Latent variances and means of a model at fixed points (see the module doc).
#[derive(Clone, Debug)]
pub struct TrackedPoints {
    points: Inputs,
    /// The model version the values are for.
    version: u64,
    signal_variance: f64,
    inverse_lengthscales: Vec<f64>,
    /// Row `i` of `V = L⁻¹ K(X, X*)`: training point `i` against every tracked point.
    rows: Vec<Vec<f64>>,
    /// `Σ_i V_ij²` per tracked point.
    explained: Vec<f64>,
    /// `Σ_i V_ij ŷ_i` per tracked point.
    mean: Vec<f64>,
    rebuilds: usize,
    updates: usize,
}

/// What [`TrackedPoints::sync`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tracking {
    /// Already in step.
    Current,
    /// Followed the model's logged changes (`O(n m)` each).
    Updated,
    /// Solved again (`O(n² m)`).
    Rebuilt,
}

impl TrackedPoints {
    /// Tracks `points` under `model`: one blocked solve, `O(n² m)`.
    pub fn new(model: &GaussianProcess, points: Inputs) -> Result<Self, GpError> {
        check_len("tracked points' dimension", model.dim(), points.dim())?;
        let mut tracked = TrackedPoints {
            points,
            version: 0,
            signal_variance: 0.0,
            inverse_lengthscales: Vec::new(),
            rows: Vec::new(),
            explained: Vec::new(),
            mean: Vec::new(),
            rebuilds: 0,
            updates: 0,
        };
        tracked.rebuild(model);
        Ok(tracked)
    }

    /// Brings the values to `model`'s current state: incrementally when its change log reaches
    /// back to the state last seen, else by solving again.
    pub fn sync(&mut self, model: &GaussianProcess) -> Result<Tracking, GpError> {
        check_len("tracked points' dimension", model.dim(), self.points.dim())?;
        if model.version() == self.version {
            return Ok(Tracking::Current);
        }
        let Some(changes) = model.changes_since(self.version) else {
            self.rebuild(model);
            return Ok(Tracking::Rebuilt);
        };
        for logged in changes {
            match &logged.change {
                Change::Appended { x, w, d, whitened } => {
                    self.append(x, w, *d, *whitened);
                }
                Change::Removed {
                    index,
                    rotations,
                    leftover,
                } => self.remove(*index, rotations, *leftover),
            }
            self.updates += 1;
        }
        if self.rows.len() != model.len() {
            // Cannot happen with a consistent log; solving again is always right.
            self.rebuild(model);
            return Ok(Tracking::Rebuilt);
        }
        self.version = model.version();
        Ok(Tracking::Updated)
    }

    /// Number of tracked points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    pub fn points(&self) -> &Inputs {
        &self.points
    }

    /// `V(f*)` at tracked point `j`, clamped at 0 against rounding (as
    /// [`GaussianProcess::predict_point`]). Panics if `j >= len()`.
    pub fn latent_variance(&self, j: usize) -> f64 {
        (self.signal_variance - self.explained[j]).max(0.0)
    }

    /// `V(f*)` at every tracked point.
    pub fn latent_variances(&self) -> Vec<f64> {
        (0..self.len()).map(|j| self.latent_variance(j)).collect()
    }

    /// `E(f*)` at every tracked point.
    pub fn means(&self) -> &[f64] {
        &self.mean
    }

    /// How many times the values were solved from scratch (construction included).
    pub fn rebuilds(&self) -> usize {
        self.rebuilds
    }

    /// How many logged changes were followed incrementally.
    pub fn updates(&self) -> usize {
        self.updates
    }

    /// Adds `points` to the tracked ones: brings the values to `model` first, then solves for
    /// the new points only (`O(n² m_new)`, one blocked solve).
    pub fn extend(
        &mut self,
        model: &GaussianProcess,
        points: &Inputs,
    ) -> Result<Tracking, GpError> {
        check_len("tracked points' dimension", self.points.dim(), points.dim())?;
        let outcome = self.sync(model)?;
        if points.is_empty() {
            return Ok(outcome);
        }
        let start = self.points.len();
        for x in points.rows() {
            self.points.push(x);
        }
        let m = self.points.len();
        self.explained.resize(m, 0.0);
        self.mean.resize(m, 0.0);
        for row in &mut self.rows {
            row.resize(m, 0.0);
        }
        self.solve(model, start);
        Ok(outcome)
    }

    fn rebuild(&mut self, model: &GaussianProcess) {
        let n = model.len();
        let m = self.points.len();
        let hyper = model.hyperparameters();
        self.signal_variance = hyper.signal_variance();
        self.inverse_lengthscales = hyper.inverse_lengthscales();
        self.rows = vec![vec![0.0; m]; n];
        self.explained = vec![0.0; m];
        self.mean = vec![0.0; m];
        self.solve(model, 0);
        self.version = model.version();
        self.rebuilds += 1;
    }

    /// Solves for the tracked points from `start` on, in blocks (their slots exist); a few
    /// points one by one on the packed factor (unpacking it costs more).
    fn solve(&mut self, model: &GaussianProcess, start: usize) {
        let n = model.len();
        let m = self.points.len();
        let whitened = model.whitened();
        if m - start < FEW {
            for j in start..m {
                let col = model.forward_solve(&model.cross_covariance(self.points.row(j)));
                self.explained[j] = dot(&col, &col);
                self.mean[j] = dot(&col, whitened);
                for (row, v) in self.rows.iter_mut().zip(&col) {
                    row[j] = *v;
                }
            }
            return;
        }
        let factor = model.dense_factor();
        let mut start = start;
        while start < m {
            let width = BLOCK.min(m - start);
            let mut block = Mat::zeros(n, width);
            for j in 0..width {
                block
                    .col_as_slice_mut(j)
                    .copy_from_slice(&model.cross_covariance(self.points.row(start + j)));
            }
            solve_lower_triangular_in_place(factor.as_ref(), block.as_mut(), Par::Seq);
            clear_upper_vector_state();
            for j in 0..width {
                let col = block.col_as_slice(j);
                self.explained[start + j] = dot(col, col);
                self.mean[start + j] = dot(col, whitened);
                for (row, v) in self.rows.iter_mut().zip(col) {
                    row[start + j] = *v;
                }
            }
            start += width;
        }
    }

    /// A point `x` joined with factor row `[wᵀ, d]` and `L⁻¹y` entry `whitened`.
    fn append(&mut self, x: &[f64], w: &[f64], d: f64, whitened: f64) {
        let mut row: Vec<f64> = self
            .points
            .rows()
            .map(|p| {
                matern32(
                    self.signal_variance,
                    scaled_sq_distance(x, p, &self.inverse_lengthscales).sqrt(),
                )
            })
            .collect();
        for (wi, vi) in w.iter().zip(&self.rows) {
            for (r, v) in row.iter_mut().zip(vi) {
                *r -= wi * v;
            }
        }
        for ((r, e), mu) in row.iter_mut().zip(&mut self.explained).zip(&mut self.mean) {
            *r /= d;
            *e += *r * *r;
            *mu += *r * whitened;
        }
        self.rows.push(row);
    }

    /// Point `index` left; the rows below it rotate against its row as the factor's did, and
    /// what is left of its row leaves the sums.
    fn remove(&mut self, index: usize, rotations: &[(f64, f64)], leftover: f64) {
        let mut x = self.rows.remove(index);
        for (row, (c, s)) in self.rows[index..].iter_mut().zip(rotations) {
            for (v, xj) in row.iter_mut().zip(&mut x) {
                let (a, b) = (*v, *xj);
                *v = c * a + s * b;
                *xj = c * b - s * a;
            }
        }
        for ((r, e), mu) in x.iter().zip(&mut self.explained).zip(&mut self.mean) {
            *e -= r * r;
            *mu -= r * leftover;
        }
    }
}
