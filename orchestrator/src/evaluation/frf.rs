//! Frequency responses estimated from records: the Welch-averaged H1 estimate (on rustfft).

use std::f64::consts::PI;

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

/// Samples per Welch segment of the frequency views (`twin compare --frf`, `twin control`): at
/// 51.2 Hz, 5 s and 0.2 Hz resolution.
pub const FRF_SEGMENT: usize = 256;

/// A frequency-response estimate, DC left out (every segment has its mean removed).
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// Hz, from one bin (1 / (segment · dt)) up to Nyquist.
    pub frequency: Vec<f64>,
    /// 20 log10 |H|; not finite where the input has no power.
    pub magnitude_db: Vec<f64>,
    /// Segments averaged.
    pub segments: usize,
}

/// H1 estimate `H = Σ conj(X)·Y / Σ |X|²` of the response `output` to `input` (sampled every
/// `dt` s), Welch-averaged over Hann-windowed segments of `segment_len` samples with 50 %
/// overlap, each with its mean removed; trailing samples that do not fill a segment are
/// unused. A record shorter than one segment is one segment. `None` if the two signals differ
/// in length, `dt` is not positive, or there are fewer than 4 samples.
pub fn welch_h1(
    input: &[f64],
    output: &[f64],
    dt: f64,
    segment_len: usize,
) -> Option<FrequencyResponse> {
    let n = input.len();
    let segment_len = segment_len.min(n);
    if output.len() != n || !(dt.is_finite() && dt > 0.0) || segment_len < 4 {
        return None;
    }
    // Periodic Hann window; its scale cancels in the ratio.
    let window: Vec<f64> = (0..segment_len)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / segment_len as f64).cos())
        .collect();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(segment_len);
    let windowed = |samples: &[f64]| -> Vec<Complex<f64>> {
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        samples
            .iter()
            .zip(&window)
            .map(|(s, w)| Complex::new((s - mean) * w, 0.0))
            .collect()
    };
    let bins = segment_len / 2;
    let mut sxx = vec![0.0; bins + 1];
    let mut sxy = vec![Complex::new(0.0, 0.0); bins + 1];
    let mut segments = 0;
    let step = segment_len / 2;
    let mut start = 0;
    while start + segment_len <= n {
        let mut x = windowed(&input[start..start + segment_len]);
        let mut y = windowed(&output[start..start + segment_len]);
        fft.process(&mut x);
        fft.process(&mut y);
        for k in 1..=bins {
            sxx[k] += x[k].norm_sqr();
            sxy[k] += x[k].conj() * y[k];
        }
        segments += 1;
        start += step;
    }
    let df = 1.0 / (segment_len as f64 * dt);
    Some(FrequencyResponse {
        frequency: (1..=bins).map(|k| k as f64 * df).collect(),
        magnitude_db: (1..=bins)
            .map(|k| 20.0 * (sxy[k].norm() / sxx[k]).log10())
            .collect(),
        segments,
    })
}
