//! A mode's damping read off its FDD bell by fitting it, in the frequency domain, as what a
//! Welch estimate makes of a single-degree-of-freedom resonance: the resonance's spectrum
//! (a Lorentzian in frequency, half-power half-width ζ f₀) smoothed by the estimate's window
//! kernel (the squared magnitude of the window's transform, which is what averaging windowed
//! segments does to any spectrum). A mode whose half-power width is a bin or less has a bell
//! that is mostly that kernel; its correlation function (EFDD) then decays as the kernel's
//! transform does, while the fit sees the kernel for what it is and reads the width beneath.

use rustfft::FftPlanner;

use super::Complex;

/// Samples of the window kernel per bin.
const KERNEL_STEPS: usize = 8;
/// Bins either side of a bin over which the kernel is summed (the Hann kernel's side lobes
/// fall as the sixth power of the offset: at 6 bins they are 10⁻⁶ of its peak).
const KERNEL_REACH: usize = 6;

/// The window's kernel, |W(u)|² at `u` = −[`KERNEL_REACH`] … [`KERNEL_REACH`] bins in steps of
/// 1 / [`KERNEL_STEPS`] bin, normalised to 1 at 0.
pub(crate) fn window_kernel(window: &[f64]) -> Vec<f64> {
    let padded = window.len() * KERNEL_STEPS;
    let mut buffer: Vec<Complex> = window
        .iter()
        .map(|w| Complex::new(*w, 0.0))
        .chain(std::iter::repeat(Complex::new(0.0, 0.0)))
        .take(padded)
        .collect();
    FftPlanner::new()
        .plan_fft_forward(padded)
        .process(&mut buffer);
    let reach = KERNEL_REACH * KERNEL_STEPS;
    let peak = buffer[0].norm_sqr();
    (0..=2 * reach)
        .map(|i| {
            let m = i as isize - reach as isize;
            let k = m.rem_euclid(padded as isize) as usize;
            buffer[k].norm_sqr() / peak
        })
        .collect()
}

/// The Welch estimate's expectation, up to scale, at bin offsets `bins` (from the peak's bin)
/// of a resonance at `centre` bins with half-power half-width `half` bins.
fn smoothed(kernel: &[f64], bins: &[f64], centre: f64, half: f64) -> Vec<f64> {
    let reach = (kernel.len() / 2) as isize;
    let steps = KERNEL_STEPS as f64;
    bins.iter()
        .map(|b| {
            kernel
                .iter()
                .enumerate()
                .map(|(i, k)| {
                    let nu = b - (i as isize - reach) as f64 / steps - centre;
                    k / (nu * nu + half * half)
                })
                .sum()
        })
        .collect()
}

/// The log misfit of the bell `values` (at bin offsets `bins`) to a smoothed resonance at
/// `centre` with half-width `half`, its scale fitted.
fn misfit(kernel: &[f64], bins: &[f64], values: &[f64], centre: f64, half: f64) -> f64 {
    let model = smoothed(kernel, bins, centre, half);
    let residuals: Vec<f64> = values
        .iter()
        .zip(&model)
        .map(|(v, m)| v.ln() - m.ln())
        .collect();
    let mean = residuals.iter().sum::<f64>() / residuals.len() as f64;
    residuals.iter().map(|r| (r - mean).powi(2)).sum()
}

/// A bell's resonance (`values`, the bell's bins, its peak at index `peak`): its centre and
/// half-power half-width in bins (the centre from the peak's bin), with the half-width's
/// standard error, fitted on an 11 × 11 grid refined five times round its best point. None with
/// fewer than four bins or a value that is not positive.
pub(crate) fn fit_bell(kernel: &[f64], values: &[f64], peak: usize) -> Option<(f64, f64, f64)> {
    if values.len() < 4 || !values.iter().all(|v| *v > 0.0) {
        return None;
    }
    let bins: Vec<f64> = (0..values.len()).map(|k| k as f64 - peak as f64).collect();
    let cost = |c: f64, h: f64| misfit(kernel, &bins, values, c, h);
    // Centre within a bin of the peak; half-width 0.01 to 100 bins on a log scale.
    let (mut centre, mut log_half) = (0.0, 0.0_f64);
    let (mut span_c, mut span_h) = (1.0, (100.0_f64).ln());
    for _ in 0..6 {
        let mut best = (f64::INFINITY, centre, log_half);
        for i in 0..=10 {
            let c = centre + span_c * (i as f64 / 5.0 - 1.0);
            for j in 0..=10 {
                let lh = log_half + span_h * (j as f64 / 5.0 - 1.0);
                let e = cost(c, lh.exp());
                if e < best.0 {
                    best = (e, c, lh);
                }
            }
        }
        (centre, log_half) = (best.1, best.2);
        span_c /= 2.5;
        span_h /= 2.5;
    }
    let half = log_half.exp();
    // The half-width's standard error from the misfit's curvature in log half-width.
    let step = 0.01;
    let e0 = cost(centre, half);
    let curvature = (cost(centre, (log_half + step).exp()) - 2.0 * e0
        + cost(centre, (log_half - step).exp()))
        / (step * step);
    let dof = values.len().saturating_sub(3).max(1) as f64;
    let log_sd = if curvature > 0.0 {
        (2.0 * e0 / dof / curvature).sqrt()
    } else {
        f64::INFINITY
    };
    Some((centre, half, half * log_sd))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hann(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos())
            .collect()
    }

    /// A resonance narrower than a bin, smoothed by a Hann window's kernel: the fit reads its
    /// half-width back from the few bins the kernel spreads it over (exact data: within 1 %).
    #[test]
    fn a_resonance_under_a_bin_wide_is_read_beneath_the_kernel() {
        let kernel = window_kernel(&hann(1024));
        for (centre, half) in [(0.3, 0.4), (-0.2, 1.5), (0.0, 6.0)] {
            let bins: Vec<f64> = (-4..=4).map(f64::from).collect();
            let values = smoothed(&kernel, &bins, centre, half);
            let (c, h, _) = fit_bell(&kernel, &values, 4).expect("fitted");
            assert!((c - centre).abs() < 0.01, "centre {c} for {centre}");
            assert!((h / half - 1.0).abs() < 0.01, "half-width {h} for {half}");
        }
    }
}
