//! A site's sensitivity: the response at the sensors of the base model's linear part to a unit
//! coefficient's force, by the RK4 sample step formed once as matrices.

use super::{LinearPart, SUBSTEPS};
use nalgebra::{DMatrix, DVector};
use structure::channel::Quantity;
use structure::effects::Site;

/// The response at `sensors` (floor from 0, quantity: absolute acceleration, or velocity or
/// displacement relative to the ground, each a row of the state or its derivative) of the base
/// model's linear part driven by the force `−P φ(t)` of a unit coefficient at `site` (`φ`
/// linear between samples), from rest; one series per sensor.
///
/// Integrated by RK4 with [`SUBSTEPS`] fixed sub-steps per sample. With the force linear between
/// samples that sample step is itself linear in the state and the two end values of `φ`, so it
/// is formed once as a matrix (the RK4 step applied to each unit state and unit input) and each
/// sample costs one product with it: `2N` by `2N` for `N` storeys, instead of `4·SUBSTEPS`
/// evaluations of the structure's dynamics.
pub(super) fn sensitivity(
    linear: &LinearPart,
    site: Site,
    phi: &[f64],
    dt: f64,
    sensors: &[(usize, Quantity)],
) -> Vec<Vec<f64>> {
    let forced = ForcedLinear::new(linear, site);
    SampleStep::new(&forced, dt).respond(phi, sensors)
}

/// The base model's linear part under a unit coefficient's force pattern `−P` at a site:
/// `M⁻¹` (as a vector), the storeys' `C` and `K`.
pub(super) struct ForcedLinear {
    pub(super) storeys: usize,
    pub(super) m_inv: DVector<f64>,
    pub(super) c: DMatrix<f64>,
    pub(super) k: DMatrix<f64>,
    pub(super) p: DVector<f64>,
}

impl ForcedLinear {
    pub(super) fn new(linear: &LinearPart, site: Site) -> Self {
        let storeys = linear.storeys();
        let m_inv = DVector::from_iterator(storeys, linear.mass.iter().map(|m| 1.0 / m));
        let storey = |c: &[f64]| {
            let mut m = DMatrix::zeros(storeys, storeys);
            for i in 0..storeys {
                m[(i, i)] += c[i];
                if i + 1 < storeys {
                    m[(i, i)] += c[i + 1];
                    m[(i, i + 1)] -= c[i + 1];
                    m[(i + 1, i)] -= c[i + 1];
                }
            }
            m
        };
        let mut pattern = vec![0.0; storeys];
        site.add_force(1.0, &mut pattern);
        ForcedLinear {
            storeys,
            m_inv,
            c: storey(&linear.damping),
            k: storey(&linear.stiffness),
            p: -DVector::from_vec(pattern),
        }
    }

    pub(super) fn accel(&self, y: &DVector<f64>, v: &DVector<f64>, u: f64) -> DVector<f64> {
        (&self.p * u - &self.c * v - &self.k * y).component_mul(&self.m_inv)
    }

    /// One sample of RK4 sub-steps from (y, v) with the force from u0 to u1: the state after.
    pub(super) fn sample(
        &self,
        mut y: DVector<f64>,
        mut v: DVector<f64>,
        u0: f64,
        u1: f64,
        dt: f64,
    ) -> DVector<f64> {
        let h = dt / f64::from(SUBSTEPS);
        for i in 0..SUBSTEPS {
            let s = f64::from(i) / f64::from(SUBSTEPS);
            let u = |tau: f64| u0 + (u1 - u0) * (s + tau / dt);
            let k1v = self.accel(&y, &v, u(0.0));
            let k1y = v.clone();
            let k2v = self.accel(
                &(&y + &k1y * (h / 2.0)),
                &(&v + &k1v * (h / 2.0)),
                u(h / 2.0),
            );
            let k2y = &v + &k1v * (h / 2.0);
            let k3v = self.accel(
                &(&y + &k2y * (h / 2.0)),
                &(&v + &k2v * (h / 2.0)),
                u(h / 2.0),
            );
            let k3y = &v + &k2v * (h / 2.0);
            let k4v = self.accel(&(&y + &k3y * h), &(&v + &k3v * h), u(h));
            let k4y = &v + &k3v * h;
            y += (k1y + k2y * 2.0 + k3y * 2.0 + k4y) * (h / 6.0);
            v += (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (h / 6.0);
        }
        let storeys = self.storeys;
        let mut x = DVector::zeros(2 * storeys);
        x.rows_mut(0, storeys).copy_from(&y);
        x.rows_mut(storeys, storeys).copy_from(&v);
        x
    }
}

/// One sample as matrices: `x' = A x + B0 u0 + B1 u1`, and the accelerations `a = Cx x + D u`.
pub(super) struct SampleStep {
    pub(super) storeys: usize,
    pub(super) a: DMatrix<f64>,
    pub(super) b0: DVector<f64>,
    pub(super) b1: DVector<f64>,
    pub(super) cx: DMatrix<f64>,
    pub(super) d: DVector<f64>,
}

impl SampleStep {
    /// The RK4 sample step applied to each unit state and unit input.
    pub(super) fn new(forced: &ForcedLinear, dt: f64) -> Self {
        let storeys = forced.storeys;
        let zero = || DVector::zeros(storeys);
        let unit = |i: usize| {
            let mut e = DVector::zeros(storeys);
            e[i] = 1.0;
            e
        };
        let mut a = DMatrix::zeros(2 * storeys, 2 * storeys);
        let mut cx = DMatrix::zeros(storeys, 2 * storeys);
        for i in 0..storeys {
            a.set_column(i, &forced.sample(unit(i), zero(), 0.0, 0.0, dt));
            a.set_column(storeys + i, &forced.sample(zero(), unit(i), 0.0, 0.0, dt));
            cx.set_column(i, &forced.accel(&unit(i), &zero(), 0.0));
            cx.set_column(storeys + i, &forced.accel(&zero(), &unit(i), 0.0));
        }
        SampleStep {
            storeys,
            a,
            b0: forced.sample(zero(), zero(), 1.0, 0.0, dt),
            b1: forced.sample(zero(), zero(), 0.0, 1.0, dt),
            cx,
            d: forced.accel(&zero(), &zero(), 1.0),
        }
    }

    /// The response at `sensors` to the force `φ`, from rest: one series per sensor.
    pub(super) fn respond(&self, phi: &[f64], sensors: &[(usize, Quantity)]) -> Vec<Vec<f64>> {
        let storeys = self.storeys;
        let n = phi.len();
        let mut out = vec![vec![0.0; n]; sensors.len()];
        let mut x = DVector::zeros(2 * storeys);
        let mut next = DVector::zeros(2 * storeys);
        let mut acc = DVector::zeros(storeys);
        let accelerations = sensors
            .iter()
            .any(|&(_, q)| !matches!(q, Quantity::Velocity | Quantity::Displacement));
        for j in 0..n {
            if accelerations {
                acc.gemv(1.0, &self.cx, &x, 0.0);
                acc.axpy(phi[j], &self.d, 1.0);
            }
            for (&(f, q), out) in sensors.iter().zip(out.iter_mut()) {
                out[j] = match q {
                    Quantity::Displacement => x[f],
                    Quantity::Velocity => x[storeys + f],
                    _ => acc[f],
                };
            }
            if j + 1 == n {
                break;
            }
            next.gemv(1.0, &self.a, &x, 0.0);
            next.axpy(phi[j], &self.b0, 1.0);
            next.axpy(phi[j + 1], &self.b1, 1.0);
            std::mem::swap(&mut x, &mut next);
        }
        out
    }
}
