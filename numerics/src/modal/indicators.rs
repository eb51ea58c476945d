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
}
