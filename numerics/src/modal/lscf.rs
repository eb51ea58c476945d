//! Input–output identification on FRFs: the least-squares complex frequency-domain method
//! (LSCF; with one measured input the poly-reference form is this common-denominator one),
//! then the shapes by a least-squares frequency-domain fit (LSFD).
//!
//! LSCF fits, over a band, `H_o(ω) ≈ N_o(Ω) / D(Ω)` with `Ω = e^{iωT}` (the z-domain basis,
//! `T = 1 / (2 f_max)` so the band's top is the basis' Nyquist) and real polynomial
//! coefficients, linearised as `N_o − H_o D ≈ 0`. The numerators are eliminated from the normal
//! equations (`M = Σ_o T_o − S_oᵀ R⁻¹ S_o`), the denominator's last coefficient is fixed at 1,
//! and the roots `z` of `D` give the poles `λ = ln z / T`. LSFD then fits
//! `H_o(ω) = Σ_r R_or / (iω − λ_r) + conj(R_or) / (iω − conj λ_r) + U_o + L_o / (iω)² + V_o (iω)²`
//! (linear in the residues and the residual terms) and the residues across outputs are the
//! shapes.

use nalgebra::DMatrix;

use super::Complex;
use serde::{Deserialize, Serialize};

use super::error::IdentificationError;
use super::spectral::Frf;
use super::stabilisation::{ModelOrder, Pole};

/// The band and polynomial orders of an LSCF run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LscfOptions {
    /// Hz; the FRF's bins in [low, high] are fitted.
    pub band: (f64, f64),
    /// Denominator orders `min_order, min_order + order_step, …, max_order` (poles per order).
    pub min_order: usize,
    pub max_order: usize,
    pub order_step: usize,
    /// How much each bin of each output counts in the fit.
    #[serde(default)]
    pub weighting: Weighting,
}

/// The weight of each FRF bin in LSCF's least squares (applied to the linearised residual
/// `N_o − H_o D`, so the normal equations carry its square).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Weighting {
    /// Every bin alike; each output scaled by its rms FRF over the band, so outputs of
    /// different size or unit count alike.
    Uniform,
    /// Each bin by its coherence γ² (each output scaled as for `Uniform`): bins where the
    /// response is not explained by the force (noise, a band the force does not reach) count
    /// for little.
    #[default]
    Coherence,
    /// Each bin by the inverse of H1's variance, `σ²_H ≈ |H|² (1 − γ²) / (2 n_d γ²)` (n_d the
    /// segments averaged; the relative variance floored at [`VARIANCE_FLOOR`]): the maximum
    /// likelihood weighting when the FRF's errors are random.
    Variance,
}

/// The least relative variance of an FRF bin under [`Weighting::Variance`]: a coherence of
/// 1 (a noise-free record) would otherwise give a bin infinite weight.
pub const VARIANCE_FLOOR: f64 = 1e-4;

impl Weighting {
    pub fn name(self) -> &'static str {
        match self {
            Weighting::Uniform => "uniform",
            Weighting::Coherence => "coherence",
            Weighting::Variance => "variance",
        }
    }

    pub fn parse(text: &str) -> Option<Weighting> {
        [
            Weighting::Uniform,
            Weighting::Coherence,
            Weighting::Variance,
        ]
        .into_iter()
        .find(|w| w.name() == text)
    }
}

impl LscfOptions {
    /// Orders 2 to 40 by 2 over `band`.
    pub fn over(band: (f64, f64)) -> LscfOptions {
        LscfOptions {
            band,
            min_order: 2,
            max_order: 40,
            order_step: 2,
            weighting: Weighting::default(),
        }
    }

    pub fn validate(&self) -> Result<(), IdentificationError> {
        let (low, high) = self.band;
        if !(low.is_finite() && high.is_finite() && low >= 0.0 && high > low) {
            return Err(IdentificationError::Option {
                what: "band's upper frequency",
                value: high,
                rule: format!("a band is 0 <= low < high Hz; low is {low}"),
            });
        }
        let option = |what, value: usize, rule: &str| {
            Err(IdentificationError::Option {
                what,
                value: value as f64,
                rule: rule.into(),
            })
        };
        if self.order_step == 0 {
            return option("order step", 0, "at least 1");
        }
        if self.min_order < 2 {
            return option("least model order", self.min_order, "at least 2 (one mode)");
        }
        if self.max_order < self.min_order {
            return option(
                "largest model order",
                self.max_order,
                "at least the least order",
            );
        }
        Ok(())
    }
}

/// The FRF's bins inside `band`: (index, ω rad/s).
/// The highest (even) model order the bins of `frf` within `band` can fit: each order needs
/// `order + 2` bins (more equations than unknowns). 0 when not even order 2 fits.
pub fn highest_order(frf: &Frf, band: (f64, f64)) -> usize {
    band_bins(frf, band).len().saturating_sub(2) & !1
}

fn band_bins(frf: &Frf, band: (f64, f64)) -> Vec<(usize, f64)> {
    frf.frequencies
        .iter()
        .enumerate()
        .filter(|(_, f)| **f >= band.0 && **f <= band.1 && **f > 0.0)
        .map(|(k, f)| (k, 2.0 * std::f64::consts::PI * f))
        .collect()
}

fn check_frf(frf: &Frf) -> Result<(), IdentificationError> {
    if frf.response.is_empty() {
        return Err(IdentificationError::NoChannels { what: "the FRF" });
    }
    for (o, h) in frf.response.iter().enumerate() {
        if h.len() != frf.frequencies.len() {
            return Err(IdentificationError::Length {
                what: format!("FRF of output {}", o + 1),
                got: h.len(),
                expected: frf.frequencies.len(),
                reference: "the frequencies".into(),
            });
        }
        if let Some(index) = h
            .iter()
            .position(|v| !(v.re.is_finite() && v.im.is_finite()))
        {
            return Err(IdentificationError::NonFinite {
                what: format!("FRF of output {}", o + 1),
                index,
            });
        }
    }
    Ok(())
}

/// One output's sums over the bins that fill LSCF's Toeplitz matrices: `Σ w Ω^d`,
/// `Σ w H Ω^d`, `Σ w H Ω^−d` and `Σ w |H|² Ω^d`, `d = 0..=max`.
#[derive(Clone)]
struct ToeplitzSums {
    basis: Vec<Complex>,
    forward: Vec<Complex>,
    backward: Vec<Complex>,
    squared: Vec<Complex>,
}

impl ToeplitzSums {
    fn new(size: usize) -> Self {
        let zero = vec![Complex::new(0.0, 0.0); size];
        ToeplitzSums {
            basis: zero.clone(),
            forward: zero.clone(),
            backward: zero.clone(),
            squared: zero,
        }
    }
}

/// The poles (and their LSFD shapes) of every order of `options`, fitted to `frf`.
pub fn lscf(frf: &Frf, options: &LscfOptions) -> Result<Vec<ModelOrder>, IdentificationError> {
    options.validate()?;
    check_frf(frf)?;
    let bins = band_bins_for_order(frf, options)?;
    let period = 1.0 / (2.0 * options.band.1);
    let weights = bin_weights(frf, &bins, options.weighting);
    let normal = NormalMatrices::of(&toeplitz_sums(
        frf,
        &bins,
        &weights,
        period,
        options.max_order + 1,
    ));
    let mut orders = Vec::new();
    let mut order = options.min_order;
    while order <= options.max_order {
        let reduced = match normal.reduced(order) {
            Ok(reduced) => reduced,
            // A narrow band's basis (a short arc of the unit circle) loses rank as the order
            // grows: the orders below are the diagram; none at all is an error.
            Err(output) if orders.is_empty() => {
                return Err(IdentificationError::Numerical {
                    what: "LSCF",
                    why: format!(
                        "the basis' normal matrix of order {order} (output {}) is \
                         singular: too few bins of weight in the band",
                        output + 1
                    ),
                });
            }
            Err(_) => break,
        };
        let eigenvalues = denominator_poles(&reduced, order, period, options.band)?;
        let shapes = lsfd(frf, options.band, &eigenvalues)?;
        let mut poles: Vec<Pole> = eigenvalues
            .into_iter()
            .zip(shapes)
            .map(|(l, shape)| Pole::new(l, shape))
            .collect();
        poles.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
        orders.push(ModelOrder { order, poles });
        order += options.order_step;
    }
    Ok(orders)
}

/// The band's bins, enough of them for the largest order: each order needs more equations than
/// unknowns, 2 per bin (real and imaginary parts).
fn band_bins_for_order(
    frf: &Frf,
    options: &LscfOptions,
) -> Result<Vec<(usize, f64)>, IdentificationError> {
    let bins = band_bins(frf, options.band);
    let needed = options.max_order + 2;
    if bins.len() < needed {
        return Err(IdentificationError::TooShort {
            what: "the FRF's band".into(),
            samples: bins.len(),
            needed,
            why: format!(
                "LSCF of order {} over {:?} Hz (bins are {} Hz apart)",
                options.max_order,
                options.band,
                frf.frequencies.get(1).copied().unwrap_or(f64::NAN)
            ),
        });
    }
    Ok(bins)
}

/// Per output, the sums over the bins of `w Ω^d`, `w H Ω^d`, `w H Ω^−d` and `w |H|² Ω^d`,
/// `d = 0..size` (O(bins · max) where the matrices entry by entry are O(bins · max²)).
fn toeplitz_sums(
    frf: &Frf,
    bins: &[(usize, f64)],
    weights: &[Vec<f64>],
    period: f64,
    size: usize,
) -> Vec<ToeplitzSums> {
    let mut sums = vec![ToeplitzSums::new(size); frf.response.len()];
    for (b, (k, w_bin)) in bins.iter().enumerate() {
        let omega = Complex::from_polar(1.0, w_bin * period);
        for (o, sum) in sums.iter_mut().enumerate() {
            let w = weights[o][b];
            let h = frf.response[o][*k];
            let (wh, wh2) = (h * w, w * h.norm_sqr());
            let mut power = Complex::new(1.0, 0.0);
            for d in 0..size {
                sum.basis[d] += power * w;
                sum.forward[d] += wh * power;
                sum.backward[d] += wh * power.conj();
                sum.squared[d] += power * wh2;
                power *= omega;
            }
        }
    }
    sums
}

/// Per output R_o, S_o and T_o at the largest order; each order takes the leading block. With
/// w the squared weight: R_jm = Re Σ w conj(Ω^j) Ω^m; S_jm = Re Σ w conj(Ω^j) (−H Ω^m);
/// T_jm = Re Σ w |H|² conj(Ω^j) Ω^m. On the unit circle conj(Ω^j) Ω^m = Ω^(m−j): all three
/// are Toeplitz, from the [`ToeplitzSums`].
struct NormalMatrices {
    r: Vec<DMatrix<f64>>,
    s: Vec<DMatrix<f64>>,
    t: Vec<DMatrix<f64>>,
}

impl NormalMatrices {
    fn of(sums: &[ToeplitzSums]) -> Self {
        let size = sums.first().map_or(0, |t| t.basis.len());
        let r = sums
            .iter()
            .map(|t| DMatrix::from_fn(size, size, |j, m| t.basis[j.abs_diff(m)].re))
            .collect();
        let s = sums
            .iter()
            .map(|t| {
                DMatrix::from_fn(size, size, |j, m| {
                    if m >= j {
                        -t.forward[m - j].re
                    } else {
                        -t.backward[j - m].re
                    }
                })
            })
            .collect();
        let t = sums
            .iter()
            .map(|t| DMatrix::from_fn(size, size, |j, m| t.squared[j.abs_diff(m)].re))
            .collect();
        NormalMatrices { r, s, t }
    }

    /// The reduced normal matrix of `order`, `Σ_o T_o − S_oᵀ R_o⁻¹ S_o` over the leading
    /// blocks; Err(o) when output o's basis block is singular.
    fn reduced(&self, order: usize) -> Result<DMatrix<f64>, usize> {
        let n = order + 1;
        let mut reduced = DMatrix::<f64>::zeros(n, n);
        for o in 0..self.r.len() {
            let Some(r_chol) = self.r[o].view((0, 0), (n, n)).into_owned().cholesky() else {
                return Err(o);
            };
            let s_n = self.s[o].view((0, 0), (n, n)).into_owned();
            reduced += self.t[o].view((0, 0), (n, n)) - s_n.transpose() * r_chol.solve(&s_n);
        }
        Ok(reduced)
    }
}

/// The denominator of `order` solved from the reduced normal matrix (α_order = 1: the other
/// coefficients solve the leading block), its roots as continuous-time poles of positive
/// frequency inside `band`.
fn denominator_poles(
    reduced: &DMatrix<f64>,
    order: usize,
    period: f64,
    band: (f64, f64),
) -> Result<Vec<Complex>, IdentificationError> {
    let lead = reduced.view((0, 0), (order, order)).into_owned();
    let rhs = -reduced.view((0, order), (order, 1)).into_owned();
    let alpha = lead
        .svd(true, true)
        .solve(&rhs, 1e-14 * reduced.norm())
        .map_err(|why| IdentificationError::Numerical {
            what: "LSCF (denominator)",
            why: why.to_owned(),
        })?;
    // Companion matrix of z^order + Σ α_j z^j.
    let mut companion = DMatrix::<f64>::zeros(order, order);
    for j in 0..order {
        companion[(0, j)] = -alpha[order - 1 - j];
        if j + 1 < order {
            companion[(j + 1, j)] = 1.0;
        }
    }
    let roots = companion.complex_eigenvalues();
    Ok(roots
        .iter()
        .filter(|z| z.im > 0.0 && z.norm() > 0.0)
        .map(|z| z.ln() / period)
        .filter(|l| {
            let f = l.norm() / (2.0 * std::f64::consts::PI);
            f >= band.0 && f <= band.1
        })
        .collect())
}

/// The squared weight of each band bin (`bins`' order) of each output under `weighting`.
fn bin_weights(frf: &Frf, bins: &[(usize, f64)], weighting: Weighting) -> Vec<Vec<f64>> {
    let segments = frf.segments.max(1) as f64;
    frf.response
        .iter()
        .zip(&frf.coherence)
        .map(|(h, coherence)| {
            let power =
                bins.iter().map(|(k, _)| h[*k].norm_sqr()).sum::<f64>() / bins.len().max(1) as f64;
            let scale = if power > 0.0 { 1.0 / power } else { 1.0 };
            bins.iter()
                .map(|(k, _)| {
                    let g = coherence.get(*k).copied().unwrap_or(1.0).clamp(0.0, 1.0);
                    match weighting {
                        Weighting::Uniform => scale,
                        Weighting::Coherence => scale * g,
                        Weighting::Variance => {
                            let size = h[*k].norm_sqr();
                            if g <= 0.0 || size <= 0.0 {
                                0.0
                            } else {
                                let relative =
                                    ((1.0 - g) / (2.0 * segments * g)).max(VARIANCE_FLOOR);
                                1.0 / (relative * size)
                            }
                        }
                    }
                })
                .collect()
        })
        .collect()
}

/// The residues of the poles `eigenvalues` (rad/s, positive imaginary part) in every output of
/// `frf` over `band`: per pole, its shape across the outputs (unscaled).
pub fn lsfd(
    frf: &Frf,
    band: (f64, f64),
    eigenvalues: &[Complex],
) -> Result<Vec<Vec<Complex>>, IdentificationError> {
    check_frf(frf)?;
    let bins = band_bins(frf, band);
    let modes = eigenvalues.len();
    // Unknowns per output: Re and Im of each residue, then U, L, V (real).
    let unknowns = 2 * modes + 3;
    if 2 * bins.len() < unknowns {
        return Err(IdentificationError::TooShort {
            what: "the FRF's band".into(),
            samples: bins.len(),
            needed: unknowns.div_ceil(2),
            why: format!("LSFD of {modes} poles"),
        });
    }
    let mut design = DMatrix::<f64>::zeros(2 * bins.len(), unknowns);
    for (b, (_, w)) in bins.iter().enumerate() {
        let s = Complex::new(0.0, *w);
        for (r, l) in eigenvalues.iter().enumerate() {
            let direct = 1.0 / (s - l);
            let mirrored = 1.0 / (s - l.conj());
            // R = a + ib: a (1/(s−λ) + 1/(s−λ*)) + b i (1/(s−λ) − 1/(s−λ*)).
            let real_part = direct + mirrored;
            let imaginary_part = Complex::i() * (direct - mirrored);
            design[(2 * b, 2 * r)] = real_part.re;
            design[(2 * b + 1, 2 * r)] = real_part.im;
            design[(2 * b, 2 * r + 1)] = imaginary_part.re;
            design[(2 * b + 1, 2 * r + 1)] = imaginary_part.im;
        }
        let residuals = [Complex::new(1.0, 0.0), 1.0 / (s * s), s * s];
        for (c, v) in residuals.iter().enumerate() {
            design[(2 * b, 2 * modes + c)] = v.re;
            design[(2 * b + 1, 2 * modes + c)] = v.im;
        }
    }
    // Columns of very different scale (1/ω², ω²): equilibrate before the least squares.
    let scales = super::equilibrate_columns(&mut design);
    // One QR of the tall design matrix serves every output: x = R⁻¹ (Qᵀ h). An SVD of the
    // same matrix took most of an hour-long record's identification.
    let mut targets = DMatrix::from_fn(2 * bins.len(), frf.response.len(), |row, o| {
        let value = frf.response[o][bins[row / 2].0];
        if row % 2 == 0 {
            value.re
        } else {
            value.im
        }
    });
    let qr = design.qr();
    qr.q_tr_mul(&mut targets);
    let projected = targets.rows(0, unknowns).into_owned();
    let r = qr.r();
    let solution = match r.solve_upper_triangular(&projected) {
        Some(x) if x.iter().all(|v| v.is_finite()) => x,
        // Nearly equal poles make R singular: fall back to the SVD's least-squares solution.
        _ => r.svd(true, true).solve(&projected, 1e-12).map_err(|why| {
            IdentificationError::Numerical {
                what: "LSFD",
                why: why.to_owned(),
            }
        })?,
    };
    let mut residues = vec![vec![Complex::new(0.0, 0.0); frf.response.len()]; modes];
    for o in 0..frf.response.len() {
        for (r, residue) in residues.iter_mut().enumerate() {
            residue[o] = Complex::new(
                solution[(2 * r, o)] * scales[2 * r],
                solution[(2 * r + 1, o)] * scales[2 * r + 1],
            );
        }
    }
    Ok(residues)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The exact FRF of two modes, sampled finely: LSCF finds both poles and LSFD their
    /// residues. A continuous-time FRF is not a rational function of the z-domain basis, so
    /// order 4 is close, not exact: measured 4e-4 relative on the eigenvalues (bar 2e-3).
    /// LSFD on the exact poles is exact: measured 1e-13-level (bar 1e-8).
    #[test]
    fn an_exact_two_mode_frf_is_recovered() {
        let poles = [
            Complex::new(-0.02 * 2.0 * PI * 3.0, 2.0 * PI * 3.0),
            Complex::new(-0.01 * 2.0 * PI * 7.0, 2.0 * PI * 7.0),
        ];
        let residues = [
            [Complex::new(0.0, -1.0), Complex::new(0.0, -0.5)],
            [Complex::new(0.0, -0.3), Complex::new(0.0, 0.6)],
        ];
        let frequencies: Vec<f64> = (0..=2000).map(|k| k as f64 * 0.01).collect();
        let response = (0..2)
            .map(|o| {
                frequencies
                    .iter()
                    .map(|f| {
                        let s = Complex::new(0.0, 2.0 * PI * f);
                        (0..2)
                            .map(|r| {
                                residues[r][o] / (s - poles[r])
                                    + residues[r][o].conj() / (s - poles[r].conj())
                            })
                            .sum()
                    })
                    .collect()
            })
            .collect();
        let frf = Frf {
            coherence: vec![vec![1.0; frequencies.len()]; 2],
            frequencies,
            response,
            segments: 1,
        };
        let orders = lscf(
            &frf,
            &LscfOptions {
                min_order: 4,
                max_order: 4,
                ..LscfOptions::over((1.0, 10.0))
            },
        )
        .expect("lscf");
        let found = &orders[0].poles;
        assert_eq!(found.len(), 2, "{found:?}");
        for (pole, exact) in found.iter().zip(&poles) {
            assert!(
                (pole.eigenvalue - exact).norm() / exact.norm() < 2e-3,
                "{pole:?}"
            );
        }
        let fitted = lsfd(&frf, (1.0, 10.0), &poles).expect("lsfd");
        for r in 0..2 {
            for o in 0..2 {
                assert!(
                    (fitted[r][o] - residues[r][o]).norm() < 1e-8,
                    "{:?}",
                    fitted[r][o]
                );
            }
        }
    }

    #[test]
    fn a_band_without_bins_is_refused() {
        let frf = Frf {
            frequencies: vec![0.0, 1.0, 2.0],
            response: vec![vec![Complex::new(1.0, 0.0); 3]],
            coherence: vec![vec![1.0; 3]],
            segments: 1,
        };
        let err = lscf(&frf, &LscfOptions::over((0.5, 1.5))).expect_err("too few bins");
        assert!(err.to_string().contains("band"), "{err}");
    }
}
