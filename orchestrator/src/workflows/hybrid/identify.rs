//! The contact law learned from a hybrid test's interface measurements.
//!
//! The physical substructure's measured force is storey 3's shear with the bumper:
//! `F_m = k₃ y_r + c₃ ẏ_r + k_nl max(0, y_r − d)`, `y_r = y₂ₚ − y₃` from the two measured
//! displacements. For a fixed gap `d` the law is linear in `(k₃, c₃, k_nl)`: least squares,
//! with `ẏ_r` by central differences. The gap is the minimiser of the residual over `d`: a
//! coarse scan over the measured `y_r` range, then golden-section refinement. Uncertainty: the
//! least-squares covariance `σ² (XᵀX)⁻¹` for the linear coefficients at the best gap, and for
//! the gap the curvature of the profile residual (`sd_d² = 2σ² / (∂²SSE/∂d²)`).
//!
//! When the specimen holds floor 2 (the paper's split) the measured force carries floor 2's
//! inertia too: `F_m = m₂ a₂ + k₃ y_r + c₃ ẏ_r + k_nl max(0, y_r − d)` with `a₂` the
//! specimen's floor-2 accelerometer, still linear for a fixed gap: `m₂` is a fourth
//! coefficient, identified with the others (`specimen_mass`).
//!
//! Identified from the *commanded* displacement `y₂ₙ` instead of the measured `y₂ₚ`, the same
//! fit shows how an actuator's amplitude error biases the law: its `y_r` is off by
//! `a_err · y₂ₙ`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// An identified contact law with its posterior sd.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ContactLaw {
    pub gap: f64,
    pub gap_sd: f64,
    pub contact_stiffness: f64,
    pub contact_stiffness_sd: f64,
    /// Storey 3's linear stiffness and damping, identified with it.
    pub storey_stiffness: f64,
    pub storey_damping: f64,
    /// RMS of the force residual (N).
    pub residual_rms: f64,
    /// Samples with the bumper closed under the identified gap.
    pub closed_samples: usize,
    /// Floor 2's mass, identified with the law when the measured force carries its inertia
    /// (the specimen holds floor 2); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specimen_mass: Option<f64>,
}

struct Fit {
    sse: f64,
    theta: DVector<f64>,
    gram: DMatrix<f64>,
}

/// The regressors at one sample: `y_r`, `ẏ_r`, `max(0, y_r − d)` and floor 2's acceleration
/// when there is one.
fn regressors(d: f64, y: f64, v: f64, a: Option<f64>) -> DVector<f64> {
    match a {
        Some(a) => DVector::from_column_slice(&[y, v, (y - d).max(0.0), a]),
        None => DVector::from_column_slice(&[y, v, (y - d).max(0.0)]),
    }
}

fn fit_at(d: f64, yr: &[f64], vr: &[f64], ar: Option<&[f64]>, force: &[f64]) -> Option<Fit> {
    let p = if ar.is_some() { 4 } else { 3 };
    let mut gram = DMatrix::zeros(p, p);
    let mut rhs = DVector::zeros(p);
    for (k, ((&y, &v), &f)) in yr.iter().zip(vr).zip(force).enumerate() {
        let x = regressors(d, y, v, ar.map(|a| a[k]));
        gram += &x * x.transpose();
        rhs += &x * f;
    }
    let theta = gram.clone().try_inverse().map(|g| g * rhs)?;
    let sse = yr
        .iter()
        .zip(vr)
        .zip(force)
        .enumerate()
        .map(|(k, ((&y, &v), &f))| {
            let x = regressors(d, y, v, ar.map(|a| a[k]));
            (f - x.dot(&theta)).powi(2)
        })
        .sum();
    Some(Fit { sse, theta, gram })
}

/// Identify the law from `y2` (floor 2's displacement on the physical side, or the command),
/// `y3` and the measured force, sampled every `dt`, with `a2` floor 2's measured acceleration
/// when the force carries its inertia. `None` when the bumper never closes far enough to be
/// seen (fewer than 10 samples beyond the best gap) or the fit is singular.
pub fn identify(
    y2: &[f64],
    y3: &[f64],
    a2: Option<&[f64]>,
    force: &[f64],
    dt: f64,
) -> Option<ContactLaw> {
    let mut n = y2.len().min(y3.len()).min(force.len());
    if let Some(a) = a2 {
        n = n.min(a.len());
    }
    if n < 10 {
        return None;
    }
    let yr_all: Vec<f64> = (0..n).map(|k| y2[k] - y3[k]).collect();
    // Central differences on the interior samples.
    let yr: Vec<f64> = yr_all[1..n - 1].to_vec();
    let vr: Vec<f64> = (1..n - 1)
        .map(|k| (yr_all[k + 1] - yr_all[k - 1]) / (2.0 * dt))
        .collect();
    let f: Vec<f64> = force[1..n - 1].to_vec();
    let ar: Option<Vec<f64>> = a2.map(|a| a[1..n - 1].to_vec());
    let ar = ar.as_deref();
    let top = yr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(top > 0.0) {
        return None;
    }
    // Coarse scan of d over (0, top), then golden section around the best.
    let scan = 200;
    let mut best = (f64::INFINITY, 0.0);
    for i in 1..scan {
        let d = top * i as f64 / scan as f64;
        if let Some(fit) = fit_at(d, &yr, &vr, ar, &f) {
            if fit.sse < best.0 {
                best = (fit.sse, d);
            }
        }
    }
    let step = top / scan as f64;
    let (mut a, mut b) = ((best.1 - step).max(0.0), (best.1 + step).min(top));
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    let sse = |d: f64| {
        fit_at(d, &yr, &vr, ar, &f)
            .map(|x| x.sse)
            .unwrap_or(f64::INFINITY)
    };
    for _ in 0..80 {
        let c = b - golden * (b - a);
        let e = a + golden * (b - a);
        if sse(c) < sse(e) {
            b = e;
        } else {
            a = c;
        }
    }
    let d = 0.5 * (a + b);
    let fit = fit_at(d, &yr, &vr, ar, &f)?;
    let closed = yr.iter().filter(|&&y| y > d).count();
    if closed < 10 {
        return None;
    }
    let dof = (yr.len() as f64 - 1.0 - fit.theta.len() as f64).max(1.0);
    let sigma2 = fit.sse / dof;
    let cov = fit.gram.try_inverse()? * sigma2;
    // The profile's curvature in d, by central differences of width h.
    let h = 1e-3 * d.max(1e-9);
    let curvature = (sse(d + h) - 2.0 * fit.sse + sse(d - h)) / (h * h);
    let gap_sd = if curvature > 0.0 {
        (2.0 * sigma2 / curvature).sqrt()
    } else {
        f64::NAN
    };
    Some(ContactLaw {
        gap: d,
        gap_sd,
        contact_stiffness: fit.theta[2],
        contact_stiffness_sd: cov[(2, 2)].max(0.0).sqrt(),
        storey_stiffness: fit.theta[0],
        storey_damping: fit.theta[1],
        residual_rms: (fit.sse / yr.len() as f64).sqrt(),
        closed_samples: closed,
        specimen_mass: ar.map(|_| fit.theta[3]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A force made by a known law along a swept relative motion is identified back.
    #[test]
    fn a_known_law_is_identified_back() {
        let dt = 1.0 / 2048.0;
        let n = 20_000;
        let (k3, c3, knl, d) = (4650.0, 2.6, 9000.0, 5e-4);
        let y2: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * dt;
                8e-4 * (2.0 * std::f64::consts::PI * 9.6 * t).sin() * (0.5 + 0.5 * (0.7 * t).sin())
            })
            .collect();
        let y3 = vec![0.0; n];
        let force: Vec<f64> = (0..n)
            .map(|k| {
                let y = y2[k];
                let v = if k == 0 || k + 1 == n {
                    0.0
                } else {
                    (y2[k + 1] - y2[k - 1]) / (2.0 * dt)
                };
                k3 * y + c3 * v + knl * (y - d).max(0.0)
            })
            .collect();
        let law = identify(&y2, &y3, None, &force, dt).expect("identified");
        assert!((law.gap - d).abs() < 1e-3 * d, "{law:?}");
        assert!((law.contact_stiffness - knl).abs() < 1e-3 * knl, "{law:?}");
        assert!((law.storey_stiffness - k3).abs() < 1e-3 * k3, "{law:?}");
        assert!(law.specimen_mass.is_none());
        // The specimen holding floor 2: its inertia in the force, its acceleration measured.
        let m2 = 5.3;
        let a2: Vec<f64> = (0..n)
            .map(|k| {
                if k == 0 || k + 1 == n {
                    0.0
                } else {
                    (y2[k + 1] - 2.0 * y2[k] + y2[k - 1]) / (dt * dt)
                }
            })
            .collect();
        let with_inertia: Vec<f64> = force.iter().zip(&a2).map(|(f, a)| f + m2 * a).collect();
        let law = identify(&y2, &y3, Some(&a2), &with_inertia, dt).expect("identified");
        assert!((law.gap - d).abs() < 1e-3 * d, "{law:?}");
        assert!((law.contact_stiffness - knl).abs() < 1e-3 * knl, "{law:?}");
        let mass = law.specimen_mass.expect("a mass");
        assert!((mass - m2).abs() < 1e-3 * m2, "{law:?}");
    }
}
