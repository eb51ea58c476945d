//! The Matérn 3/2 ARD covariance, `k(x, x') = σ_f² (1 + √3 r) exp(−√3 r)` with
//! `r² = Σ_d (x_d − x'_d)² / l_d²`, and the pieces of it the likelihood and the model share.
//!
//! Its derivatives with respect to the log-hyperparameters (used in likelihood.rs):
//!
//! - `∂k/∂r = σ_f² [√3 e^{−√3r} − √3 (1 + √3r) e^{−√3r}] = −3 σ_f² r e^{−√3r}`;
//! - `∂r/∂log l_d = (1/2r) ∂r²/∂log l_d = −(x_d − x'_d)² / (l_d² r)`;
//! - so `∂k/∂log l_d = 3 σ_f² e^{−√3r} (x_d − x'_d)² / l_d²`, which is finite (zero) at
//!   `r = 0`: no division by `r` is needed;
//! - `∂k/∂log σ_f² = k` and, on the diagonal of `K`, `∂(σ_n² I)/∂log σ_n² = σ_n² I`.

use faer::linalg::matmul::{self, triangular::BlockStructure};
use faer::{Accum, Mat, Par};

pub(crate) const SQRT3: f64 = 1.732_050_807_568_877_2;

/// `σ_f² (1 + √3 r) e^{−√3 r}`.
#[inline]
pub(crate) fn matern32(signal_variance: f64, r: f64) -> f64 {
    let s = SQRT3 * r;
    signal_variance * (1.0 + s) * (-s).exp()
}

/// `aᵀb` with four partial sums: a single running sum is a chain of dependent additions the
/// compiler may not reorder, four let it pipeline and vectorise (≈ 3× faster on the `O(n²)`
/// triangular solves of predictions and updates).
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut lanes = [0.0; 4];
    let (a4, a_rest) = a.split_at(n - n % 4);
    let (b4, b_rest) = b.split_at(n - n % 4);
    for (x, y) in a4.chunks_exact(4).zip(b4.chunks_exact(4)) {
        for k in 0..4 {
            lanes[k] += x[k] * y[k];
        }
    }
    let tail: f64 = a_rest.iter().zip(b_rest).map(|(x, y)| x * y).sum();
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
}

/// `Σ_d ((a_d − b_d) / l_d)²`, with `inv_l` holding `1/l_d` (four partial sums, as [`dot`]).
#[inline]
pub(crate) fn scaled_sq_distance(a: &[f64], b: &[f64], inv_l: &[f64]) -> f64 {
    let n = a.len().min(b.len()).min(inv_l.len());
    let split = n - n % 4;
    let mut lanes = [0.0; 4];
    for ((x, y), s) in a[..split]
        .chunks_exact(4)
        .zip(b[..split].chunks_exact(4))
        .zip(inv_l[..split].chunks_exact(4))
    {
        for k in 0..4 {
            let u = (x[k] - y[k]) * s[k];
            lanes[k] += u * u;
        }
    }
    let tail: f64 = a[split..n]
        .iter()
        .zip(&b[split..n])
        .zip(&inv_l[split..n])
        .map(|((x, y), s)| {
            let u = (x - y) * s;
            u * u
        })
        .sum();
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
}

/// The points divided by their lengthscales, minus their mean (which changes no difference
/// `z_i − z_j` and keeps `‖z‖²` small for the Gram-matrix form of `r²` below), as an `n × d`
/// column-major matrix for faer's products.
pub(crate) fn scaled_centred(values: &[f64], inv_l: &[f64]) -> Mat<f64> {
    let dim = inv_l.len();
    let n = values.len() / dim;
    let mut means = vec![0.0; dim];
    for row in values.chunks_exact(dim) {
        for ((m, x), s) in means.iter_mut().zip(row).zip(inv_l) {
            *m += x * s;
        }
    }
    for m in &mut means {
        *m /= n.max(1) as f64;
    }
    Mat::from_fn(n, dim, |i, t| values[i * dim + t] * inv_l[t] - means[t])
}

/// Fills the lower triangle (diagonal included) of the noise-free covariance `K_f` of the
/// scaled points `z` (rows), and, when `dk` is given, the lower triangle of
/// `3 σ_f² e^{−√3 r}`, the factor shared by all `∂K/∂log l_d` (see the module doc). The strict
/// upper triangles are left untouched.
///
/// `r²_ij = ‖z_i‖² + ‖z_j‖² − 2 z_i·z_j` with the Gram matrix `Z Zᵀ` from one faer product
/// (`O(n² d)` at matrix-product speed rather than `n²/2` scalar distance loops). Its rounding
/// error, `ε ‖z‖²`, is harmless: `k` is smooth in `r²` at 0 (`k = σ_f² (1 − 3r²/2 + O(r³))`).
pub(crate) fn fill_lower(
    z: &Mat<f64>,
    signal_variance: f64,
    kf: &mut Mat<f64>,
    mut dk: Option<&mut Mat<f64>>,
) {
    let n = kf.nrows();
    matmul::triangular::matmul(
        kf.as_mut(),
        BlockStructure::TriangularLower,
        Accum::Replace,
        z.as_ref(),
        BlockStructure::Rectangular,
        z.as_ref().transpose(),
        BlockStructure::Rectangular,
        1.0,
        Par::Seq,
    );
    clear_upper_vector_state();
    let sq_norms: Vec<f64> = (0..n).map(|i| kf[(i, i)]).collect();
    // Each column in three passes, so that the two without a call vectorise: r, then
    // e^{−√3 r} (a libm call per entry), then K_f and the derivative factor from them. The
    // operations and their order per entry are those of `matern32`.
    let with_dk = dk.is_some();
    let mut exps = if with_dk { Vec::new() } else { vec![0.0; n] };
    for j in 0..n {
        let kcol = &mut kf.col_as_slice_mut(j)[j..];
        kcol[0] = signal_variance;
        let kcol = &mut kcol[1..];
        let qj = sq_norms[j];
        for (k, q) in kcol.iter_mut().zip(&sq_norms[j + 1..]) {
            *k = (q + qj - 2.0 * *k).max(0.0).sqrt();
        }
        let exps: &mut [f64] = match dk.as_deref_mut() {
            Some(d) => {
                let dcol = &mut d.col_as_slice_mut(j)[j..];
                dcol[0] = 3.0 * signal_variance;
                &mut dcol[1..]
            }
            None => &mut exps[j + 1..],
        };
        for (e, r) in exps.iter_mut().zip(kcol.iter()) {
            *e = (-SQRT3 * r).exp();
        }
        for (k, e) in kcol.iter_mut().zip(exps.iter()) {
            *k = signal_variance * (1.0 + SQRT3 * *k) * e;
        }
        if with_dk {
            for e in exps.iter_mut() {
                *e *= 3.0 * signal_variance;
            }
        }
    }
}

/// Clears the upper halves of the vector registers after a faer product, factorisation or
/// solve, before scalar code runs again.
///
/// faer's matrix products run AVX-512 kernels where the CPU has them and return with the
/// registers' upper halves in use. Until a `vzeroupper`, every legacy-SSE instruction after
/// them (the baseline x86-64 code that all of this crate's scalar loops and libm's calls
/// compile to) pays a merge with those upper halves: measured on this project's Sapphire Rapids
/// machine, the `n²/2` exponentials of [`fill_lower`] took 50× longer after a faer product than
/// before it (105 ms against 2 ms at n = 1000), and a whole GP fit 3–4× longer. The instruction
/// changes no value. Elsewhere (no AVX, other architectures) this does nothing.
#[inline]
pub(crate) fn clear_upper_vector_state() {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        simd.avx._mm256_zeroupper();
    }
}
