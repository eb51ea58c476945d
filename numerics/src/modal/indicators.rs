//! Indicators that compare and qualify mode shapes.

use super::Complex;

/// The modal assurance criterion |aᴴ b|² / (aᴴa · bᴴb): 1 for shapes that are multiples of each
/// other, 0 for orthogonal ones. 0 when either shape is zero or they differ in length.
pub fn mac(a: &[Complex], b: &[Complex]) -> f64 {
    if a.len() != b.len() {
        return 0.0;
    }
    let cross: Complex = a.iter().zip(b).map(|(x, y)| x.conj() * y).sum();
    let aa: f64 = a.iter().map(|x| x.norm_sqr()).sum();
    let bb: f64 = b.iter().map(|x| x.norm_sqr()).sum();
    if aa == 0.0 || bb == 0.0 {
        return 0.0;
    }
    cross.norm_sqr() / (aa * bb)
}

/// MAC of every shape of `rows` against every shape of `cols`.
pub fn mac_matrix(rows: &[Vec<Complex>], cols: &[Vec<Complex>]) -> Vec<Vec<f64>> {
    rows.iter()
        .map(|a| cols.iter().map(|b| mac(a, b)).collect())
        .collect()
}

/// Real shapes as complex ones (for MAC against identified complex shapes).
pub fn complex_shape(shape: &[f64]) -> Vec<Complex> {
    shape.iter().map(|&x| Complex::new(x, 0.0)).collect()
}

/// The modal phase collinearity `|Σ φᵢ²|² / (Σ |φᵢ|²)²`, in [0, 1]: 1 for a shape whose
/// components share one phase (up to sign), as a classically damped structure's do. It is the
/// squared ratio of the spread of the components in the complex plane along their principal
/// axis and across it (Pappa's eigenvalue form, written without the 2×2 eigenproblem).
pub fn mpc(phi: &[Complex]) -> f64 {
    let squares: Complex = phi.iter().map(|v| v * v).sum();
    let power: f64 = phi.iter().map(|v| v.norm_sqr()).sum();
    if power > 0.0 {
        squares.norm_sqr() / (power * power)
    } else {
        0.0
    }
}

/// The mean phase deviation, degrees in [0, 90]: the modulus-weighted mean angle between each
/// component and the straight line through the origin that fits the components best (its
/// direction is half the argument of `Σ φᵢ²`). 0 for a real shape.
pub fn mpd(phi: &[Complex]) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let squares: Complex = phi.iter().map(|v| v * v).sum();
    let axis = squares.arg() / 2.0;
    let mut weighted = 0.0;
    let mut weight = 0.0;
    for v in phi {
        let modulus = v.norm();
        if modulus == 0.0 {
            continue;
        }
        // The angle to the line, folded into [0, π/2].
        let mut angle = (v.arg() - axis).rem_euclid(PI);
        if angle > FRAC_PI_2 {
            angle = PI - angle;
        }
        weighted += modulus * angle;
        weight += modulus;
    }
    if weight > 0.0 {
        (weighted / weight).to_degrees()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mac_is_one_for_scaled_shapes_and_zero_for_orthogonal_ones() {
        let a = complex_shape(&[1.0, 2.0, 3.0]);
        let b: Vec<Complex> = a.iter().map(|x| x * Complex::new(0.0, -2.5)).collect();
        assert!((mac(&a, &b) - 1.0).abs() < 1e-15);
        let c = complex_shape(&[3.0, 0.0, -1.0]);
        assert!(mac(&a, &c).abs() < 1e-15);
        assert_eq!(mac(&a, &complex_shape(&[1.0])), 0.0);
        let m = mac_matrix(&[a.clone(), c.clone()], &[a, c]);
        assert!((m[0][0] - 1.0).abs() < 1e-15 && m[0][1].abs() < 1e-15);
    }

    #[test]
    fn a_real_shape_rotated_is_collinear_and_a_travelling_wave_is_not() {
        let rotation = Complex::from_polar(1.0, 0.7);
        let real: Vec<Complex> = complex_shape(&[0.3, -1.0, 0.8])
            .iter()
            .map(|v| v * rotation)
            .collect();
        assert!((mpc(&real) - 1.0).abs() < 1e-12);
        assert!(mpd(&real) < 1e-9, "{}", mpd(&real));
        // Components a quarter period apart, equal moduli: no preferred line.
        let wave = [Complex::new(1.0, 0.0), Complex::new(0.0, 1.0)];
        assert!(mpc(&wave) < 1e-12);
        assert!((mpd(&wave) - 45.0).abs() < 1e-9, "{}", mpd(&wave));
    }
}
