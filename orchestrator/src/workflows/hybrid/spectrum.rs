//! The spectrum of a hybrid test's response (the reference paper's Fig. 15, bottom): Welch's
//! power spectral density, its peaks, and which of them are harmonics of the fundamental.

use std::f64::consts::PI;

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Serialize;

/// A one-sided power spectral density.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Spectrum {
    pub frequency: Vec<f64>,
    /// Power per Hz (unit² / Hz).
    pub power: Vec<f64>,
}

/// Welch's estimate: Hann segments of `segment` samples, 50 % overlap, each mean removed.
pub fn welch(x: &[f64], dt: f64, segment: usize) -> Spectrum {
    let segment = segment.min(x.len()).max(4);
    let window: Vec<f64> = (0..segment)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / segment as f64).cos())
        .collect();
    let norm: f64 = window.iter().map(|w| w * w).sum::<f64>() / dt;
    let fft = FftPlanner::<f64>::new().plan_fft_forward(segment);
    let bins = segment / 2 + 1;
    let mut power = vec![0.0; bins];
    let mut count = 0;
    let mut start = 0;
    while start + segment <= x.len() {
        let part = &x[start..start + segment];
        let mean = part.iter().sum::<f64>() / segment as f64;
        let mut buffer: Vec<Complex<f64>> = part
            .iter()
            .zip(&window)
            .map(|(v, w)| Complex::new((v - mean) * w, 0.0))
            .collect();
        fft.process(&mut buffer);
        for (b, p) in power.iter_mut().enumerate() {
            let one_sided = if b == 0 || 2 * b == segment { 1.0 } else { 2.0 };
            *p += one_sided * buffer[b].norm_sqr() / norm;
        }
        count += 1;
        start += segment / 2;
    }
    let count = count.max(1) as f64;
    Spectrum {
        frequency: (0..bins)
            .map(|b| b as f64 / (segment as f64 * dt))
            .collect(),
        power: power.into_iter().map(|p| p / count).collect(),
    }
}

/// A spectral peak.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Peak {
    pub frequency: f64,
    /// Power relative to the largest peak, dB.
    pub relative_db: f64,
}

/// The fundamental, the peaks and the harmonics found.
#[derive(Clone, Debug, Serialize)]
pub struct Harmonics {
    pub fundamental_hz: f64,
    /// Local maxima within `floor_db` of the largest, strongest first (at most 12).
    pub peaks: Vec<Peak>,
    /// Integer multiples `n ≥ 2` of the fundamental with a peak within one bin, that is not
    /// one of the structure's own modes (within two bins of a natural frequency).
    pub harmonics: Vec<(u32, Peak)>,
}

/// Peaks above 1 Hz within `floor_db` (e.g. 40) of the largest, and the harmonics of the
/// largest (the fundamental) among them, leaving out the structure's `modes` (Hz).
pub fn harmonics(s: &Spectrum, floor_db: f64, modes: &[f64]) -> Option<Harmonics> {
    let n = s.power.len();
    if n < 5 {
        return None;
    }
    let df = s.frequency[1] - s.frequency[0];
    let mut peaks: Vec<(usize, f64)> = (1..n - 1)
        .filter(|&b| s.frequency[b] > 1.0)
        .filter(|&b| s.power[b] > s.power[b - 1] && s.power[b] >= s.power[b + 1])
        .map(|b| (b, s.power[b]))
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    let &(top_bin, top) = peaks.first()?;
    let db = |p: f64| 10.0 * (p / top).log10();
    peaks.retain(|&(_, p)| db(p) >= -floor_db);
    let fundamental = s.frequency[top_bin];
    let as_peak = |(b, p): (usize, f64)| Peak {
        frequency: s.frequency[b],
        relative_db: db(p),
    };
    let mut found = Vec::new();
    for order in 2..=((s.frequency[n - 1] / fundamental) as u32) {
        let target = order as f64 * fundamental;
        let is_mode = |f: f64| modes.iter().any(|m| (f - m).abs() <= 2.0 * df);
        if let Some(&hit) = peaks.iter().find(|&&(b, _)| {
            (s.frequency[b] - target).abs() <= df * 1.01 && !is_mode(s.frequency[b])
        }) {
            found.push((order, as_peak(hit)));
        }
    }
    Some(Harmonics {
        fundamental_hz: fundamental,
        peaks: peaks.iter().take(12).map(|&x| as_peak(x)).collect(),
        harmonics: found,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 Hz square-ish wave (sine plus its third and fifth harmonics) shows its fundamental
    /// and the harmonics 3 and 5, and Parseval holds for a white signal's level.
    #[test]
    fn harmonics_of_a_distorted_sine_are_found() {
        let dt = 1.0 / 512.0;
        let x: Vec<f64> = (0..20_000)
            .map(|k| {
                let t = k as f64 * dt;
                let w = 2.0 * PI * 10.0 * t;
                w.sin() + 0.2 * (3.0 * w).sin() + 0.1 * (5.0 * w).sin()
            })
            .collect();
        let s = welch(&x, dt, 2048);
        let h = harmonics(&s, 40.0, &[]).expect("peaks");
        assert!((h.fundamental_hz - 10.0).abs() < 0.3, "{h:?}");
        let orders: Vec<u32> = h.harmonics.iter().map(|x| x.0).collect();
        assert!(orders.contains(&3) && orders.contains(&5), "{orders:?}");
        assert!(!orders.contains(&2) && !orders.contains(&4), "{orders:?}");
        // Parseval: the integral of the PSD is the variance (0.5 + 0.02 + 0.005).
        let df = s.frequency[1];
        let variance: f64 = s.power.iter().sum::<f64>() * df;
        assert!((variance - 0.525).abs() < 0.01, "{variance}");
    }
}
