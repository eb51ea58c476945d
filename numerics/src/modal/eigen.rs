//! The exact modes of `M ÿ + C ẏ + K y = f`: the eigenvalues λ of the first-order system (one of
//! each complex-conjugate pair, Im λ > 0), their natural frequency |λ| / 2π, damping ratio
//! −Re λ / |λ| and displacement shape φ, and the first-order sensitivity of λ to a change of
//! M, C and K.
//!
//! For symmetric M, C, K the left and right eigenvectors of the quadratic problem
//! `(λ² M + λ C + K) φ = 0` coincide (transposed, not conjugated), so
//! `dλ = −φᵀ (λ² dM + λ dC + dK) φ / φᵀ (2 λ M + C) φ`. The eigen-decomposition is faer's
//! (general real matrix, complex eigenvectors).

use nalgebra::DMatrix;

use super::Complex;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ModalError {
    #[error("{what}: expected a {expected}×{expected} matrix, got {rows}×{cols}")]
    Shape {
        what: &'static str,
        expected: usize,
        rows: usize,
        cols: usize,
    },
    #[error("the mass matrix is singular")]
    SingularMass,
    #[error("{what} holds a value that is not finite")]
    NotFinite { what: &'static str },
    #[error("the eigen-decomposition did not converge")]
    NoConvergence,
}

/// One underdamped mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// The eigenvalue with positive imaginary part, rad/s.
    pub eigenvalue: Complex,
    /// Natural frequency |λ| / 2π, Hz.
    pub frequency: f64,
    /// Damping ratio −Re λ / |λ|.
    pub damping: f64,
    /// Displacement shape, scaled so that its largest component is 1 (real).
    pub shape: Vec<Complex>,
}

impl Mode {
    /// The shape as real numbers (the real part of the normalised shape: for proportional
    /// damping the shape is real, for light non-proportional damping nearly so).
    pub fn real_shape(&self) -> Vec<f64> {
        self.shape.iter().map(|c| c.re).collect()
    }

    /// dλ for the changes `dm`, `dc`, `dk` of the matrices (first order).
    pub fn eigenvalue_change(
        &self,
        m: &DMatrix<f64>,
        c: &DMatrix<f64>,
        dm: &DMatrix<f64>,
        dc: &DMatrix<f64>,
        dk: &DMatrix<f64>,
    ) -> Complex {
        let l = self.eigenvalue;
        let quadratic = |a: &DMatrix<f64>, scale: Complex| -> Complex {
            let mut sum = Complex::new(0.0, 0.0);
            for i in 0..a.nrows() {
                for j in 0..a.ncols() {
                    if a[(i, j)] != 0.0 {
                        sum += self.shape[i] * self.shape[j] * a[(i, j)];
                    }
                }
            }
            sum * scale
        };
        let numerator =
            quadratic(dm, l * l) + quadratic(dc, l) + quadratic(dk, Complex::new(1.0, 0.0));
        let denominator = quadratic(m, l * 2.0) + quadratic(c, Complex::new(1.0, 0.0));
        -numerator / denominator
    }

    /// (d frequency [Hz], d damping) for an eigenvalue change `dl`.
    pub fn frequency_damping_change(&self, dl: Complex) -> (f64, f64) {
        let l = self.eigenvalue;
        let r = l.norm();
        let dr = (l.conj() * dl).re / r;
        let df = dr / (2.0 * std::f64::consts::PI);
        let dz = -dl.re / r + l.re * dr / (r * r);
        (df, dz)
    }
}

fn check_square(what: &'static str, a: &DMatrix<f64>, n: usize) -> Result<(), ModalError> {
    if a.nrows() != n || a.ncols() != n {
        return Err(ModalError::Shape {
            what,
            expected: n,
            rows: a.nrows(),
            cols: a.ncols(),
        });
    }
    if a.iter().any(|x| !x.is_finite()) {
        return Err(ModalError::NotFinite { what });
    }
    Ok(())
}

/// The underdamped modes of `M ÿ + C ẏ + K y`, by increasing frequency. Overdamped (real)
/// eigenvalues have no mode and are left out.
pub fn modes(
    m: &DMatrix<f64>,
    c: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Result<Vec<Mode>, ModalError> {
    let n = m.nrows();
    check_square("the mass matrix", m, n)?;
    check_square("the damping matrix", c, n)?;
    check_square("the stiffness matrix", k, n)?;
    let m_inv = m.clone().try_inverse().ok_or(ModalError::SingularMass)?;
    let mk = &m_inv * k;
    let mc = &m_inv * c;
    let a = faer::Mat::<f64>::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
        (true, true) => 0.0,
        (true, false) => {
            if j - n == i {
                1.0
            } else {
                0.0
            }
        }
        (false, true) => -mk[(i - n, j)],
        (false, false) => -mc[(i - n, j - n)],
    });
    let eigen = faer::linalg::solvers::Eigen::new_from_real(a.as_ref())
        .map_err(|_| ModalError::NoConvergence)?;
    let values = eigen.S();
    let vectors = eigen.U();
    let mut out = Vec::with_capacity(n);
    for col in 0..2 * n {
        let l = values.column_vector()[col];
        // One of each pair; a real eigenvalue is an overdamped motion, not a mode.
        if l.im <= 1e-12 * l.norm().max(1.0) {
            continue;
        }
        let raw: Vec<Complex> = (0..n).map(|i| vectors[(i, col)]).collect();
        let largest = raw
            .iter()
            .copied()
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap_or(Complex::new(1.0, 0.0));
        if largest.norm() == 0.0 {
            continue;
        }
        let shape = raw.iter().map(|v| v / largest).collect();
        let r = l.norm();
        out.push(Mode {
            eigenvalue: l,
            frequency: r / (2.0 * std::f64::consts::PI),
            damping: -l.re / r,
            shape,
        });
    }
    out.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shear(m: &[f64], c: &[f64], k: &[f64]) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let n = m.len();
        let storey = |v: &[f64]| {
            DMatrix::from_fn(n, n, |i, j| {
                let above = if i + 1 < n { v[i + 1] } else { 0.0 };
                if i == j {
                    v[i] + above
                } else if j == i + 1 {
                    -v[j]
                } else if i == j + 1 {
                    -v[i]
                } else {
                    0.0
                }
            })
        };
        (
            DMatrix::from_diagonal(&nalgebra::DVector::from_row_slice(m)),
            storey(c),
            storey(k),
        )
    }

    #[test]
    fn one_storey_is_the_textbook_oscillator() {
        let (m, c, k) = shear(&[2.0], &[0.4], &[800.0]);
        let modes = modes(&m, &c, &k).unwrap();
        assert_eq!(modes.len(), 1);
        let wn: f64 = (800.0f64 / 2.0).sqrt();
        assert!((modes[0].frequency - wn / (2.0 * std::f64::consts::PI)).abs() < 1e-12);
        assert!((modes[0].damping - 0.4 / (2.0 * (800.0f64 * 2.0).sqrt())).abs() < 1e-14);
    }

    #[test]
    fn undamped_frequencies_are_the_generalised_eigenvalues() {
        // Two equal storeys, m = 1, k = 1: ω² = (3 ∓ √5) / 2.
        let (m, c, k) = shear(&[1.0, 1.0], &[0.0, 0.0], &[1.0, 1.0]);
        let modes = modes(&m, &c, &k).unwrap();
        let expected = [(3.0 - 5f64.sqrt()) / 2.0, (3.0 + 5f64.sqrt()) / 2.0];
        for (mode, w2) in modes.iter().zip(expected) {
            assert!((mode.frequency * 2.0 * std::f64::consts::PI - w2.sqrt()).abs() < 1e-12);
            assert!(mode.damping.abs() < 1e-12);
        }
        // First mode: both floors in phase, the top one moving most (1 : φ with φ = (1+√5)/2).
        let phi = modes[0].real_shape();
        assert!((phi[1] - 1.0).abs() < 1e-12 && (phi[0] - 2.0 / (1.0 + 5f64.sqrt())).abs() < 1e-12);
        assert!(phi[0] > 0.0);
    }

    #[test]
    fn eigenvalue_sensitivity_matches_central_differences() {
        let mass = [5.2, 5.1, 5.3, 4.9];
        let damp = [0.9, 0.7, 1.1, 0.8];
        let stiff = [4021.0, 3900.0, 4100.0, 3800.0];
        let (m, c, k) = shear(&mass, &damp, &stiff);
        let base = modes(&m, &c, &k).unwrap();
        for (which, storey) in [(0usize, 1usize), (1, 2), (2, 0)] {
            // which: 0 mass, 1 damping, 2 stiffness; a relative step of 1e-4 (truncation ~1e-8,
            // the eigen-solver's rounding over the step ~1e-9).
            let mut values = [mass.to_vec(), damp.to_vec(), stiff.to_vec()];
            let theta = values[which][storey];
            let h = theta * 1e-4;
            let perturbed = |sign: f64| {
                let mut v = values.clone();
                v[which][storey] += sign * h;
                let (m, c, k) = shear(&v[0], &v[1], &v[2]);
                modes(&m, &c, &k).unwrap()
            };
            let (plus, minus) = (perturbed(1.0), perturbed(-1.0));
            values[which] = vec![0.0; mass.len()];
            values[which][storey] = 1.0;
            let (dm, dc, dk) = shear(&values[0], &values[1], &values[2]);
            let zero = DMatrix::zeros(mass.len(), mass.len());
            let (dm, dc, dk) = match which {
                0 => (dm, zero.clone(), zero),
                1 => (zero.clone(), dc, zero),
                _ => (zero.clone(), zero, dk),
            };
            for (i, mode) in base.iter().enumerate() {
                let analytic = mode.eigenvalue_change(&m, &c, &dm, &dc, &dk);
                let numeric = (plus[i].eigenvalue - minus[i].eigenvalue) / (2.0 * h);
                // Compared as elasticities (the change per relative change of the parameter),
                // so that a derivative near zero (the frequency's to a damping) is not held to a
                // relative bar it cannot meet; seen: ≤ 3.8e-9 (λ, frequency) and 1.3e-10 (damping).
                let lambda = mode.eigenvalue.norm();
                assert!(
                    (analytic - numeric).norm() * theta / lambda < 1e-7,
                    "mode {i}, parameter {which}/{storey}: {analytic} vs {numeric}"
                );
                let (df, dz) = mode.frequency_damping_change(analytic);
                let dfn = (plus[i].frequency - minus[i].frequency) / (2.0 * h);
                let dzn = (plus[i].damping - minus[i].damping) / (2.0 * h);
                assert!(
                    (df - dfn).abs() * theta / mode.frequency < 1e-7,
                    "df {df} vs {dfn}"
                );
                assert!((dz - dzn).abs() * theta < 1e-9, "dz {dz} vs {dzn}");
            }
        }
    }

    #[test]
    fn bad_matrices_are_refused_naming_them() {
        let (m, c, _) = shear(&[1.0, 1.0], &[0.0, 0.0], &[1.0, 1.0]);
        let k = DMatrix::zeros(3, 3);
        assert!(matches!(
            modes(&m, &c, &k),
            Err(ModalError::Shape {
                what: "the stiffness matrix",
                ..
            })
        ));
        let zero = DMatrix::zeros(2, 2);
        assert_eq!(modes(&zero, &c, &c), Err(ModalError::SingularMass));
    }
}
