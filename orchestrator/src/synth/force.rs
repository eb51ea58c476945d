//! The band-limited force and its amplitude windows.

use super::{Result, SynthError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

use super::scenario::{in_band, BetweenSamples, ForceWindow, Scenario};
use super::{FORCE_STREAM, GENERATOR_OVERSAMPLE};

/// The force on the fine grid (`samples · oversample` points over one period of the record):
/// see the module documentation. Also returns the number of frequency bins used.
pub fn band_limited_force(s: &Scenario) -> Result<(Vec<f64>, usize)> {
    s.validate("scenario")?;
    let n = s.samples();
    let period = n as f64 / s.sample_rate;
    let ng = n * GENERATOR_OVERSAMPLE;
    let hg = period / ng as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(FORCE_STREAM);
    let envelope: Vec<f64> = (0..ng)
        .map(|j| envelope(&s.force.windows, j as f64 * hg))
        .collect();
    let mut spectrum: Vec<Complex<f64>> = envelope
        .iter()
        .map(|e| {
            let w: f64 = StandardNormal.sample(&mut rng);
            Complex::new(w * e, 0.0)
        })
        .collect();
    let mut planner = FftPlanner::<f64>::new();
    planner.plan_fft_forward(ng).process(&mut spectrum);
    let (low, band) = (s.force.low_hz, s.band_hz());
    let keep: Vec<usize> = (1..=ng / 2)
        .filter(|&k| in_band(k as f64 / period, low, band))
        .collect();
    // The band-limited signal on the generator grid, for the scale.
    let mut z = vec![Complex::new(0.0, 0.0); ng];
    for &k in &keep {
        z[k] = spectrum[k];
        if k != ng - k {
            z[ng - k] = spectrum[ng - k];
        }
    }
    planner.plan_fft_inverse(ng).process(&mut z);
    let power: f64 = z.iter().map(|c| (c.re / ng as f64).powi(2)).sum();
    let envelope_power: f64 = envelope.iter().map(|e| e * e).sum();
    if !(power > 0.0 && envelope_power > 0.0) {
        return Err(SynthError::Record(
            "the force has no power: check force.windows' gains".into(),
        ));
    }
    let scale = s.force.rms / (power / envelope_power).sqrt();
    // The same trigonometric polynomial on the fine grid.
    let nf = n * s.oversample as usize;
    let mut fine = vec![Complex::new(0.0, 0.0); nf];
    for &k in &keep {
        // k < nf / 2 because band ≤ sample_rate / 2 and the band edge is excluded.
        fine[k] = spectrum[k];
        fine[nf - k] = spectrum[ng - k];
    }
    planner.plan_fft_inverse(nf).process(&mut fine);
    let norm = scale / ng as f64;
    let mut fine: Vec<f64> = fine.iter().map(|c| c.re * norm).collect();
    if s.force.between_samples == BetweenSamples::Linear {
        let os = s.oversample as usize;
        for k in 0..n {
            let (a, b) = (fine[k * os], fine[((k + 1) % n) * os]);
            for i in 1..os {
                fine[k * os + i] = a + (b - a) * (i as f64 / os as f64);
            }
        }
    }
    Ok((fine, keep.len()))
}

/// The ground acceleration on the fine grid under `excitation` = base (see
/// [`super::scenario::GroundMotion`]): white Gaussian noise on the generator grid (stream 1, as
/// the force), its spectrum kept inside the band and shaped by the Kanai–Tajimi gain, the same
/// trigonometric polynomial evaluated on the fine grid, scaled so that its RMS over the record
/// is `force.rms`, then multiplied by the Jennings–Housner–Tsai envelope (and any amplitude
/// windows) at each fine time. Also returns the number of frequency bins used.
pub fn ground_motion(s: &Scenario) -> Result<(Vec<f64>, usize)> {
    s.validate("scenario")?;
    let n = s.samples();
    let period = n as f64 / s.sample_rate;
    let ng = n * GENERATOR_OVERSAMPLE;
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(FORCE_STREAM);
    let mut spectrum: Vec<Complex<f64>> = (0..ng)
        .map(|_| {
            let w: f64 = StandardNormal.sample(&mut rng);
            Complex::new(w, 0.0)
        })
        .collect();
    let mut planner = FftPlanner::<f64>::new();
    planner.plan_fft_forward(ng).process(&mut spectrum);
    let (low, band) = (s.force.low_hz, s.band_hz());
    let keep: Vec<usize> = (1..=ng / 2)
        .filter(|&k| in_band(k as f64 / period, low, band))
        .collect();
    let nf = n * s.oversample as usize;
    let mut fine = vec![Complex::new(0.0, 0.0); nf];
    for &k in &keep {
        let gain = s.ground.gain(k as f64 / period);
        fine[k] = spectrum[k] * gain;
        fine[nf - k] = spectrum[ng - k] * gain;
    }
    planner.plan_fft_inverse(nf).process(&mut fine);
    let stationary: Vec<f64> = fine.iter().map(|c| c.re).collect();
    let power = stationary.iter().map(|x| x * x).sum::<f64>() / nf as f64;
    if !(power > 0.0) {
        return Err(SynthError::Record(
            "the ground motion has no power: check force.band_hz and force.low_hz".into(),
        ));
    }
    let scale = s.force.rms / power.sqrt();
    let hf = period / nf as f64;
    let mut fine: Vec<f64> = stationary
        .iter()
        .enumerate()
        .map(|(j, x)| {
            let t = j as f64 * hf;
            x * scale * s.ground.envelope(t) * envelope(&s.force.windows, t)
        })
        .collect();
    if s.force.between_samples == BetweenSamples::Linear {
        let os = s.oversample as usize;
        for k in 0..n {
            let (a, b) = (fine[k * os], fine[((k + 1) % n) * os]);
            for i in 1..os {
                fine[k * os + i] = a + (b - a) * (i as f64 / os as f64);
            }
        }
    }
    Ok((fine, keep.len()))
}

/// The amplitude envelope at time `t`.
pub fn envelope(windows: &[ForceWindow], t: f64) -> f64 {
    windows
        .iter()
        .map(|w| 1.0 + (w.gain - 1.0) * window_shape(w, t))
        .product()
}

/// 0 outside the window, 1 inside, raised-cosine ramps centred on the edges.
fn window_shape(w: &ForceWindow, t: f64) -> f64 {
    let edge = |t0: f64, rising: bool| -> f64 {
        // 0 before t0 − ramp/2, 1 after t0 + ramp/2.
        let x = if w.ramp > 0.0 {
            ((t - (t0 - 0.5 * w.ramp)) / w.ramp).clamp(0.0, 1.0)
        } else if t >= t0 {
            1.0
        } else {
            0.0
        };
        let up = 0.5 - 0.5 * (std::f64::consts::PI * x).cos();
        if rising {
            up
        } else {
            1.0 - up
        }
    };
    edge(w.start, true).min(edge(w.end, false))
}
