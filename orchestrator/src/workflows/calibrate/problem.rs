//! The least-squares problem in the standardised parameters for fixed noise weights, and its
//! finite-difference columns over the cores the starts leave idle.

use super::lm;
use super::target::{raw_residuals, sensitivity_normals, simulators, ModelNormals, Target};
use crate::twin::simulator::Simulator;
use nalgebra::{DMatrix, DVector};
use std::cell::RefCell;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The least-squares problem in `z` for fixed noise variances.
pub(super) struct Problem<'s, 'a> {
    pub(super) sims: RefCell<&'s mut [Simulator<'a>]>,
    pub(super) target: &'s Target<'a>,
    /// Each residual's weight `e^{−s/2}`, by the noise variance of its block.
    pub(super) weights: Vec<f64>,
    pub(super) buf: RefCell<Vec<Vec<f64>>>,
    /// Simulations used, a Jacobian from sensitivities counted as the p runs it replaces: what
    /// the budget bounds.
    pub(super) evaluations: RefCell<usize>,
    /// FMU runs made.
    pub(super) runs: RefCell<usize>,
    /// The model's normal equations from the last trial's sensitivities, and where they were
    /// taken.
    pub(super) at_hand: RefCell<Option<(Vec<f64>, ModelNormals)>>,
    /// The last trial and its residuals `y − ŷ`: where the fit ended, the noise's next estimate
    /// needs no run of its own.
    pub(super) last: RefCell<Option<(Vec<f64>, Vec<f64>)>>,
    /// Simulations this least-squares solve may use.
    pub(super) budget: usize,
}

impl Problem<'_, '_> {
    pub(super) fn weighted(&self, z: &[f64]) -> Option<DVector<f64>> {
        // A point whose normals are at hand (the fit before ended there) is not run again:
        // its residuals are those normals'.
        let known = self
            .at_hand
            .borrow()
            .as_ref()
            .filter(|(at, _)| at.as_slice() == z)
            .map(|(_, model)| model.r.clone());
        let r = match known {
            Some(r) => r,
            None => self.run(z)?,
        };
        let weighted = with_prior_rows(&r, &self.weights, z);
        *self.last.borrow_mut() = Some((z.to_vec(), r));
        Some(weighted)
    }

    /// The residuals `y − ŷ` of a run at `z`, counted.
    fn run(&self, z: &[f64]) -> Option<Vec<f64>> {
        *self.evaluations.borrow_mut() += 1;
        *self.runs.borrow_mut() += self.target.records.len();
        let mut sims = self.sims.borrow_mut();
        // With sensitivities, every trial runs with them: an accepted trial's Jacobian is then
        // at hand, for less than a run of its own.
        match sensitivity_normals(&mut sims, self.target, z) {
            Some(model) => {
                let r = model.r.clone();
                *self.at_hand.borrow_mut() = Some((z.to_vec(), model));
                Some(r)
            }
            None => raw_residuals(&mut sims, self.target, z, &mut self.buf.borrow_mut()),
        }
    }

    /// The forward-difference Jacobian at `z` (`base` its residuals), one run per parameter:
    /// through [`Problem::weighted`] while the FMU's sensitivities are on, else as plain runs
    /// by [`over_columns`] (over the cores the starts leave idle, when worth it). The same
    /// columns either way.
    pub(super) fn forward_differences(
        &self,
        z: &[f64],
        base: &DVector<f64>,
    ) -> Option<DMatrix<f64>> {
        let plain = self
            .target
            .sensitivity
            .as_ref()
            .is_none_or(|s| s.failed.load(Ordering::Relaxed));
        let mut jac = DMatrix::zeros(base.len(), z.len());
        if !plain {
            for j in 0..z.len() {
                let h = 1e-6 * z[j].abs().max(1.0);
                let mut shifted = z.to_vec();
                shifted[j] += h;
                jac.set_column(j, &((self.weighted(&shifted)? - base) / h));
            }
            return Some(jac);
        }
        *self.evaluations.borrow_mut() += z.len();
        *self.runs.borrow_mut() += z.len() * self.target.records.len();
        let (target, weights) = (self.target, &self.weights);
        let columns = over_columns(
            &mut self.sims.borrow_mut(),
            &mut self.buf.borrow_mut(),
            target,
            z.len(),
            |sims, buf, j| {
                let h = 1e-6 * z[j].abs().max(1.0);
                let mut shifted = z.to_vec();
                shifted[j] += h;
                let r = raw_residuals(sims, target, &shifted, buf)?;
                Some((with_prior_rows(&r, weights, &shifted) - base) / h)
            },
        )?;
        for (j, c) in columns.iter().enumerate() {
            jac.set_column(j, c);
        }
        Some(jac)
    }
}

/// Below this much work left after the first column (its time × the columns left), the rest
/// run on this thread: another thread's simulators (an FMU instance per record) and its start
/// cost a few milliseconds, more than a three-storey record's few columns take.
pub(super) const COLUMNS_WORTH_THREADS: Duration = Duration::from_millis(40);

/// `column(sims, buf, j)` for every `j` in `0..count`, in order. Column 0 on this thread,
/// timed; when the rest is worth it ([`COLUMNS_WORTH_THREADS`]), column j on thread
/// `(j − 1) mod t`, `t` the target's [`Target::columns_threads`], thread 0 this one with `sims`,
/// each other with simulators of its own; else the rest here too. The same columns either way.
/// None when any column is.
pub(super) fn over_columns<'a, T: Send>(
    sims: &mut [Simulator<'a>],
    buf: &mut Vec<Vec<f64>>,
    target: &Target<'a>,
    count: usize,
    column: impl Fn(&mut [Simulator<'a>], &mut Vec<Vec<f64>>, usize) -> Option<T> + Sync,
) -> Option<Vec<T>> {
    if count == 0 {
        return Some(Vec::new());
    }
    let timed = Instant::now();
    let first = column(sims, buf, 0)?;
    let rest = timed.elapsed() * (count - 1) as u32;
    let threads = target.columns_threads.min(count - 1).max(1);
    if threads == 1 || rest < COLUMNS_WORTH_THREADS {
        return std::iter::once(Some(first))
            .chain((1..count).map(|j| column(sims, buf, j)))
            .collect();
    }
    let column = &column;
    let parts: Vec<Option<Vec<(usize, T)>>> = std::thread::scope(|scope| {
        let others: Vec<_> = (1..threads)
            .map(|t| {
                scope.spawn(move || {
                    let mut sims = simulators(target, "differences").ok()?;
                    let mut buf = Vec::new();
                    (1 + t..count)
                        .step_by(threads)
                        .map(|j| Some((j, column(&mut sims, &mut buf, j)?)))
                        .collect()
                })
            })
            .collect();
        let mine = (1..count)
            .step_by(threads)
            .map(|j| Some((j, column(sims, buf, j)?)))
            .collect();
        std::iter::once(mine)
            .chain(others.into_iter().map(|h| h.join().ok().flatten()))
            .collect()
    });
    let mut out: Vec<Option<T>> = std::iter::once(Some(first))
        .chain((1..count).map(|_| None))
        .collect();
    for part in parts {
        for (j, c) in part? {
            out[j] = Some(c);
        }
    }
    out.into_iter().collect()
}

/// The weighted residuals `r ∘ w` followed by the prior's rows `z` (the standardised
/// parameters): the least-squares vector of a trial.
pub(super) fn with_prior_rows(r: &[f64], weights: &[f64], z: &[f64]) -> DVector<f64> {
    let mut out = DVector::zeros(r.len() + z.len());
    for (i, (x, w)) in r.iter().zip(weights).enumerate() {
        out[i] = x * w;
    }
    for (j, zj) in z.iter().enumerate() {
        out[r.len() + j] = *zj;
    }
    out
}

/// Simulations one start may use by default. Starts that reach the optimum need 350–800 on the examples
/// (9 parameters); starts that wander in a flat region used up to 15,000 without improving.
pub const SIMULATIONS_PER_START: usize = 1500;

impl lm::LeastSquares for Problem<'_, '_> {
    fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>> {
        self.weighted(z)
    }

    fn jacobian(&mut self, z: &[f64], base: &DVector<f64>) -> Option<DMatrix<f64>> {
        self.forward_differences(z, base)
    }

    fn normal(&mut self, z: &[f64], base: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
        // A start that has not settled within its budget is abandoned.
        if *self.evaluations.borrow() > self.budget {
            return None;
        }
        // The normals at hand stay (not taken): where the fit ends, the next outer iteration
        // starts from them.
        let held = self
            .at_hand
            .borrow()
            .as_ref()
            .is_some_and(|(at, _)| at.as_slice() == z);
        if !held {
            let mut sims = self.sims.borrow_mut();
            let model = sensitivity_normals(&mut sims, self.target, z);
            if model.is_some() {
                *self.runs.borrow_mut() += self.target.records.len();
            }
            *self.at_hand.borrow_mut() = model.map(|m| (z.to_vec(), m));
        }
        if let Some((_, model)) = self.at_hand.borrow().as_ref() {
            // Counted as the p runs it replaces, so a start's budget buys the same iterations.
            *self.evaluations.borrow_mut() += z.len();
            let block_weights: Vec<f64> = self
                .target
                .blocks()
                .iter()
                .map(|&(start, _)| self.weights.get(start).copied().unwrap_or(0.0))
                .collect();
            return Some(model.weighted(&block_weights, z));
        }
        let jac = self.forward_differences(z, base)?;
        let jt = jac.transpose();
        Some((&jt * &jac, &jt * base))
    }
}
