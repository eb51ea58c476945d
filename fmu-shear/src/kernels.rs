//! The inner loops of the sensitivity step, compiled for the CPU's widest vectors and chosen at
//! run time (`multiversion`): the FMU is built for the x86-64 baseline (SSE2, two doubles a
//! vector), where a machine with AVX2 or AVX-512 does four or eight. The arithmetic is the
//! same in every version — a multiply and an add per element, never fused — so a result does
//! not depend on the machine that computed it.

use multiversion::multiversion;

/// `y += a · x` over the common length.
#[multiversion(targets("x86_64+avx512f+avx2", "x86_64+avx2", "aarch64+neon"))]
pub fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// `out += Σ_c z[c] · m[c]`, `m` the rows of a row-major matrix with `out.len()` columns (rows
/// whose `z[c]` is zero skipped): a vector times a matrix as a sum of scaled rows.
#[multiversion(targets("x86_64+avx512f+avx2", "x86_64+avx2", "aarch64+neon"))]
pub fn add_rows(z: &[f64], m: &[f64], out: &mut [f64]) {
    let width = out.len();
    for (c, zc) in z.iter().enumerate() {
        if *zc != 0.0 {
            for (o, v) in out.iter_mut().zip(&m[c * width..(c + 1) * width]) {
                *o += zc * v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispatched kernels give the scalar loops' results bit for bit.
    #[test]
    fn the_kernels_are_the_scalar_loops() {
        let x: Vec<f64> = (0..67).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y: Vec<f64> = (0..67).map(|i| (i as f64 * 1.1).cos()).collect();
        let mut want = y.clone();
        for (w, x) in want.iter_mut().zip(&x) {
            *w += 0.3 * x;
        }
        axpy(0.3, &x, &mut y);
        assert_eq!(y, want);
        let z = [0.5, 0.0, -1.25];
        let m: Vec<f64> = (0..3 * 67).map(|i| (i as f64 * 0.013).tan()).collect();
        let mut out = y.clone();
        for (c, zc) in z.iter().enumerate() {
            if *zc != 0.0 {
                for (o, v) in want.iter_mut().zip(&m[c * 67..(c + 1) * 67]) {
                    *o += zc * v;
                }
            }
        }
        add_rows(&z, &m, &mut out);
        assert_eq!(out, want);
    }
}
