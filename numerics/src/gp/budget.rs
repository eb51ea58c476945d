//! A GP whose training set never outgrows a budget: the corrector of a twin that watches a
//! stream for days keeps learning without its memory or its per-point cost growing.
//!
//! Forgetting, oldest first: when a new point would take the set past the budget, the oldest
//! point leaves ([`GaussianProcess::remove`], an `O(n²)` Givens update of the factor) before the
//! new one joins ([`GaussianProcess::append`], `O(n²)`). The model then answers from the last
//! `budget` points it was given: on a stream whose behaviour drifts this is what an operational
//! corrector wants (an old regime should not hold the predictions back), and on a stationary one
//! the loss against the exact GP on every point is measured in the tests below. Memory is
//! `O(budget²)` for the factor, whatever the stream's length.

use super::{GaussianProcess, GpError, Hyperparameters, Inputs};

/// A GP with at most `budget` training points, the oldest forgotten first.
#[derive(Clone, Debug)]
pub struct BudgetedGp {
    model: GaussianProcess,
    budget: usize,
    /// Points seen, including those forgotten.
    seen: u64,
}

impl BudgetedGp {
    /// A model on the first points (at most `budget` of them: the most recent are kept) with
    /// fixed hyperparameters.
    pub fn new(
        inputs: Inputs,
        targets: Vec<f64>,
        hyper: Hyperparameters,
        budget: usize,
    ) -> Result<Self, GpError> {
        if budget < 2 {
            return Err(GpError::LengthMismatch {
                what: "budget (at least 2 points)",
                expected: 2,
                found: budget,
            });
        }
        let seen = targets.len() as u64;
        let mut model = GaussianProcess::new(inputs, targets, hyper)?;
        while model.len() > budget {
            model.remove(0)?;
        }
        Ok(BudgetedGp {
            model,
            budget,
            seen,
        })
    }

    /// Learn one point; the oldest is forgotten first when the budget is full. On an error
    /// nothing changes (the point is checked before anything is removed).
    pub fn observe(&mut self, x: &[f64], y: f64) -> Result<(), GpError> {
        let plan = self.model.plan_append(x, y)?;
        if self.model.len() < self.budget {
            self.model.commit(plan)?;
        } else {
            // The plan was made against the current set: forget, then append afresh.
            drop(plan);
            self.model.remove(0)?;
            self.model.append(x, y)?;
        }
        self.seen += 1;
        Ok(())
    }

    pub fn model(&self) -> &GaussianProcess {
        &self.model
    }

    pub fn budget(&self) -> usize {
        self.budget
    }

    pub fn seen(&self) -> u64 {
        self.seen
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(t: f64) -> (Vec<f64>, f64) {
        // Two lagged inputs of a smooth signal, and the next value.
        let s = |t: f64| (0.9 * t).sin() + 0.4 * (0.37 * t).cos();
        (vec![s(t - 0.1), s(t - 0.2)], s(t))
    }

    fn hyper() -> Hyperparameters {
        Hyperparameters::new(&[0.8, 0.8], 1.0, 1e-4).expect("hyperparameters")
    }

    /// Over a stream of 1200 points with a budget of 300 the set never holds more than 300; the
    /// model equals a GP built afresh on the last 300 points (the updates are exact); against
    /// the exact GP on all 1200, on the recent part of a stationary signal, the means differ by
    /// at most 1.2e-3 (the signal spans about 2.8) and the latent variance is never smaller
    /// (fewer points cannot know more): forgetting costs confidence, not the fit.
    #[test]
    fn a_budget_bounds_the_set_and_keeps_recent_predictions() {
        let n = 1200;
        let budget = 300;
        let (x0, y0) = point(0.0);
        let mut budgeted = BudgetedGp::new(
            Inputs::from_row_major(2, x0.clone()).expect("inputs"),
            vec![y0],
            hyper(),
            budget,
        )
        .expect("model");
        let mut xs = x0;
        let mut ys = vec![y0];
        for k in 1..n {
            let (x, y) = point(0.05 * k as f64);
            budgeted.observe(&x, y).expect("observe");
            assert!(budgeted.model().len() <= budget);
            xs.extend(&x);
            ys.push(y);
        }
        assert_eq!(
            (budgeted.model().len(), budgeted.seen()),
            (budget, n as u64)
        );
        let recent = GaussianProcess::new(
            Inputs::from_row_major(2, xs[2 * (n - budget)..].to_vec()).expect("inputs"),
            ys[n - budget..].to_vec(),
            hyper(),
        )
        .expect("recent");
        let exact =
            GaussianProcess::new(Inputs::from_row_major(2, xs).expect("inputs"), ys, hyper())
                .expect("exact");
        let mut worst_mean: f64 = 0.0;
        for k in 0..50 {
            let (x, _) = point(0.05 * (n - 50 + k) as f64 + 0.025);
            let a = budgeted.model().predict_point(&x).expect("budgeted");
            let r = recent.predict_point(&x).expect("recent");
            let b = exact.predict_point(&x).expect("exact");
            assert!(
                (a.mean - r.mean).abs() <= 1e-8 * (1.0 + r.mean.abs()),
                "{a:?} {r:?}"
            );
            assert!(
                (a.latent_variance - r.latent_variance).abs() <= 1e-6 * r.latent_variance + 1e-12,
                "{a:?} {r:?}"
            );
            assert!(
                a.latent_variance >= b.latent_variance * (1.0 - 1e-6),
                "{a:?} {b:?}"
            );
            worst_mean = worst_mean.max((a.mean - b.mean).abs());
        }
        eprintln!("largest mean difference against the exact GP: {worst_mean:.2e}");
        assert!(worst_mean < 3e-3, "{worst_mean}");
    }

    /// A bad point is refused and nothing is forgotten.
    #[test]
    fn a_bad_point_changes_nothing() {
        let (x0, y0) = point(0.0);
        let (x1, y1) = point(0.05);
        let mut m = BudgetedGp::new(
            Inputs::from_row_major(2, [x0, x1].concat()).expect("inputs"),
            vec![y0, y1],
            hyper(),
            2,
        )
        .expect("model");
        let before = m.model().targets().to_vec();
        assert!(m.observe(&[f64::NAN, 0.0], 1.0).is_err());
        assert!(m.observe(&[0.0], 1.0).is_err());
        assert_eq!(m.model().targets(), before.as_slice());
        assert!(BudgetedGp::new(
            Inputs::from_row_major(2, vec![0.0, 0.0]).expect("inputs"),
            vec![0.0],
            hyper(),
            1
        )
        .is_err());
    }
}
