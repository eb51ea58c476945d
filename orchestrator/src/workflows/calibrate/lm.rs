//! Levenberg–Marquardt on the normal equations, for the calibration's few parameters and many
//! residuals.
//!
//! Written here rather than taken from the `levenberg-marquardt` crate (MINPACK's algorithm,
//! which the calibration used before): that one factors the whole `m × p` Jacobian by a pivoted
//! Householder QR with MINPACK's scaled norms at every iteration, a quarter of a calibration's
//! time once the Jacobian came from the FMU's sensitivities in one run (m ≈ 2,700 residuals,
//! p = 9). Here an iteration forms `JᵀJ` and `Jᵀr` once (one matrix product) and solves
//! `(JᵀJ + μ D) h = −Jᵀr` by a `p × p` Cholesky per trial damping. Squaring the condition number
//! costs nothing here: the calibration's residuals include the standardised prior, whose rows add
//! the identity to `JᵀJ`.
//!
//! The damping follows Madsen, Nielsen & Tingleff (*Methods for non-linear least squares
//! problems*, 2004, algorithm 3.16), scaled by `D = diag(JᵀJ)` as Marquardt's (invariant to the
//! parameters' scales); the stopping rules are MINPACK's relative reduction (`ftol`) and step
//! (`xtol`), and an absolute floor on the reduction the model predicts (`min_predicted`): where
//! the cost is a negative log-likelihood, a step that can gain less than a fraction of a nat
//! moves the parameters by a vanishing share of their posterior width, and costs a run.

use nalgebra::{DMatrix, DVector};

/// A least-squares problem `min ½‖r(z)‖²`.
pub trait LeastSquares {
    /// The residuals at `z`; None where the model refuses `z` (a trial there is rejected).
    fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>>;
    /// The Jacobian `∂r/∂z` at `z`, where `r` are the residuals; None stops the minimisation
    /// (a budget spent, or no Jacobian to be had).
    fn jacobian(&mut self, z: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>>;
    /// `JᵀJ` and `Jᵀr` at `z`: by default from [`LeastSquares::jacobian`]; a problem that can
    /// form them without the `m × p` Jacobian (a Gram matrix of fewer columns) says so here.
    /// None stops the minimisation.
    fn normal(&mut self, z: &[f64], r: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
        let jac = self.jacobian(z, r)?;
        // Jᵀ J as a matrix product (blocked), where `tr_mul` takes a dot product per entry:
        // 18 % of a 20-storey calibration (20,480 residuals, 60 parameters).
        let jt = jac.transpose();
        Some((&jt * &jac, &jt * r))
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Stop when an accepted step lowers the cost by less than this share of it.
    pub ftol: f64,
    /// Stop when the step is shorter than this share of ‖z‖ (plus `xtol`).
    pub xtol: f64,
    /// Stop after this many rejected trials in a row.
    pub rejections: usize,
    /// Stop, without trying it, when the step the model predicts gains less than this (in the
    /// cost's own units; 0: never).
    pub min_predicted: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            ftol: 1e-9,
            xtol: 1e-9,
            rejections: 25,
            min_predicted: 0.0,
        }
    }
}

/// Minimise from `z0` (whose residuals are `r0`); the best point reached and its residuals.
pub fn minimize(
    problem: &mut impl LeastSquares,
    z0: Vec<f64>,
    r0: DVector<f64>,
    settings: Settings,
) -> (Vec<f64>, DVector<f64>) {
    let mut z = z0;
    let mut r = r0;
    let mut cost = 0.5 * r.norm_squared();
    let p = z.len();
    let mut mu: Option<f64> = None;
    let mut nu = 2.0;
    'outer: while let Some((a, g)) = problem.normal(&z, &r) {
        if !g.iter().all(|x| x.is_finite()) || g.amax() == 0.0 {
            break;
        }
        let largest = (0..p).map(|i| a[(i, i)]).fold(0.0, f64::max);
        let d: Vec<f64> = (0..p).map(|i| a[(i, i)].max(1e-12 * largest)).collect();
        let mut damping = *mu.get_or_insert(1e-3);
        let mut rejected = 0;
        loop {
            let mut system = a.clone();
            for i in 0..p {
                system[(i, i)] += damping * d[i];
            }
            let Some(chol) = system.cholesky() else {
                damping *= nu;
                nu *= 2.0;
                rejected += 1;
                if rejected > settings.rejections {
                    break 'outer;
                }
                continue;
            };
            let h = chol.solve(&(-&g));
            let z_norm = z.iter().map(|x| x * x).sum::<f64>().sqrt();
            if h.norm() <= settings.xtol * (z_norm + settings.xtol) {
                break 'outer;
            }
            let trial: Vec<f64> = z.iter().zip(h.iter()).map(|(a, b)| a + b).collect();
            // Predicted reduction ½ hᵀ(μ D h − g), positive for a descent step.
            let predicted = 0.5
                * (0..p)
                    .map(|i| h[i] * (damping * d[i] * h[i] - g[i]))
                    .sum::<f64>();
            if predicted < settings.min_predicted && rejected == 0 {
                break 'outer;
            }
            let accepted = problem.residuals(&trial).and_then(|r_trial| {
                let cost_trial = 0.5 * r_trial.norm_squared();
                (cost_trial.is_finite() && cost_trial < cost).then_some((r_trial, cost_trial))
            });
            match accepted {
                Some((r_trial, cost_trial)) => {
                    let rho = (cost - cost_trial) / predicted.max(f64::MIN_POSITIVE);
                    let reduction = cost - cost_trial;
                    z = trial;
                    r = r_trial;
                    let before = cost;
                    cost = cost_trial;
                    mu = Some(damping * (1.0 / 3.0f64).max(1.0 - (2.0 * rho - 1.0).powi(3)));
                    nu = 2.0;
                    if reduction <= settings.ftol * before {
                        break 'outer;
                    }
                    continue 'outer;
                }
                None => {
                    damping *= nu;
                    nu *= 2.0;
                    rejected += 1;
                    if rejected > settings.rejections {
                        break 'outer;
                    }
                }
            }
        }
    }
    (z, r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's valley as residuals `[10 (z₁ − z₀²), 1 − z₀]`, from (−1.2, 1).
    struct Rosenbrock {
        evaluations: usize,
    }

    impl LeastSquares for Rosenbrock {
        fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>> {
            self.evaluations += 1;
            Some(DVector::from_vec(vec![
                10.0 * (z[1] - z[0] * z[0]),
                1.0 - z[0],
            ]))
        }
        fn jacobian(&mut self, z: &[f64], _r: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(DMatrix::from_row_slice(
                2,
                2,
                &[-20.0 * z[0], 10.0, -1.0, 0.0],
            ))
        }
    }

    #[test]
    fn it_finds_the_bottom_of_rosenbrocks_valley() {
        let mut problem = Rosenbrock { evaluations: 0 };
        let z0 = vec![-1.2, 1.0];
        let r0 = problem.residuals(&z0).expect("residuals");
        let (z, r) = minimize(&mut problem, z0, r0, Settings::default());
        assert!(
            (z[0] - 1.0).abs() < 1e-6 && (z[1] - 1.0).abs() < 1e-6,
            "{z:?}"
        );
        assert!(r.norm() < 1e-6);
        assert!(problem.evaluations < 100, "{}", problem.evaluations);
    }

    /// A linear problem whose model refuses `z₀ > 3.5`: the minimum at (3, −1) is reached from
    /// far beyond the refused region, a trial there rejected and the damping raised.
    struct Refusing;

    impl LeastSquares for Refusing {
        fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>> {
            (z[0] < 3.5).then(|| DVector::from_vec(vec![z[0] - 3.0, 2.0 * (z[1] + 1.0)]))
        }
        fn jacobian(&mut self, _z: &[f64], _r: &DVector<f64>) -> Option<DMatrix<f64>> {
            Some(DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 2.0]))
        }
    }

    #[test]
    fn it_solves_a_linear_problem_next_to_a_refused_region() {
        let z0 = vec![3.4, 5.0];
        let r0 = Refusing.residuals(&z0).expect("residuals");
        let (z, _) = minimize(&mut Refusing, z0, r0, Settings::default());
        assert!(
            (z[0] - 3.0).abs() < 1e-9 && (z[1] + 1.0).abs() < 1e-9,
            "{z:?}"
        );
    }
}
