//! The few statistics the twin's error measures are made of: mean, variance (population, 1/N),
//! RMS and the NMSE, the worst of a per-floor measure, and the first sample a measure counts.

/// The largest of `x` (the worst floor or channel of an NMSE per floor); −∞ for none.
pub fn worst(x: &[f64]) -> f64 {
    x.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

/// `Σ x / N`; NaN for no samples.
pub fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// `Σ (x − x̄)² / N` (the population variance); NaN for no samples.
pub fn variance(x: &[f64]) -> f64 {
    let m = mean(x);
    x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len() as f64
}

/// `√(Σ x² / N)`; 0 for no samples.
pub fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// `100 / (N var(y)) Σ (y − ŷ)²` over the given samples; NaN for none.
pub fn nmse(measured: &[f64], predicted: &[f64]) -> f64 {
    if measured.is_empty() {
        return f64::NAN;
    }
    let sse: f64 = measured
        .iter()
        .zip(predicted)
        .map(|(y, p)| (y - p).powi(2))
        .sum();
    100.0 * sse / (measured.len() as f64 * variance(measured))
}

/// Index of the first sample at least `transient` seconds after the first one (`time.len()`
/// when there is none): where every error measure, fit and stream starts.
pub fn first_after_transient(time: &[f64], transient: f64) -> usize {
    time.iter()
        .position(|&t| t - time[0] >= transient)
        .unwrap_or(time.len())
}
