//! Welch-averaged spectra of records: the complex H1 estimate of several outputs to one input
//! with each output's ordinary coherence, and the outputs' auto and cross spectra for
//! output-only use. Hann window, 50 % overlap, each segment's mean removed; samples past the
//! last whole segment of a run are unused. Several runs (records of one test) average together.

use std::f64::consts::PI;
use std::sync::Arc;

use super::Complex;
use rustfft::{Fft, FftPlanner};

use super::error::{check_channels, check_dt, IdentificationError};

/// One run of a test: the measured excitation (when there is one) and the responses, each a
/// channel sampled every `dt` s, all of one length.
#[derive(Debug, Clone, Copy)]
pub struct Run<'a> {
    pub input: Option<&'a [f64]>,
    pub outputs: &'a [&'a [f64]],
}

/// The H1 frequency-response estimate `H = G_yx / G_xx` per output, with its coherence.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// Hz, bins 0 (DC) to Nyquist, `1 / (segment · dt)` apart.
    pub frequencies: Vec<f64>,
    /// Per output, per frequency: response per unit input (complex).
    pub response: Vec<Vec<Complex>>,
    /// Per output, per frequency: `|G_yx|² / (G_xx G_yy)`, in [0, 1]; 0 where either has no power.
    pub coherence: Vec<Vec<f64>>,
    /// Segments averaged over every run.
    pub segments: usize,
}

/// One-sided auto and cross spectral densities of the outputs (unit² / Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct OutputSpectra {
    /// Hz, bins 0 (DC) to Nyquist.
    pub frequencies: Vec<f64>,
    /// `cross[f][i * outputs + j]` = `G_ij(f)` = E[Y_i Y_j*] scaled to a one-sided density.
    pub cross: Vec<Vec<Complex>>,
    pub outputs: usize,
    pub segments: usize,
}

impl OutputSpectra {
    /// The auto spectrum (PSD) of output `i`.
    pub fn auto(&self, i: usize) -> Vec<f64> {
        self.cross
            .iter()
            .map(|g| g[i * self.outputs + i].re)
            .collect()
    }

    /// The sum of the outputs' auto spectra: the spectrum a stabilisation diagram is drawn over.
    pub fn total(&self) -> Vec<f64> {
        self.cross
            .iter()
            .map(|g| (0..self.outputs).map(|i| g[i * self.outputs + i].re).sum())
            .collect()
    }
}

/// Welch's averaging: Hann-windowed segments of `segment_length` samples, 50 % overlap.
#[derive(Clone)]
pub struct Welch {
    dt: f64,
    segment_length: usize,
    window: Vec<f64>,
    fft: Arc<dyn Fft<f64>>,
}

impl std::fmt::Debug for Welch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Welch")
            .field("dt", &self.dt)
            .field("segment_length", &self.segment_length)
            .finish_non_exhaustive()
    }
}

/// The shortest segment accepted: below it a spectrum has too few bins to mean anything.
pub const MIN_SEGMENT: usize = 16;

impl Welch {
    /// Checks `dt` (positive, finite) and the segment length (at least [`MIN_SEGMENT`]).
    pub fn new(dt: f64, segment_length: usize) -> Result<Welch, IdentificationError> {
        check_dt(dt)?;
        if segment_length < MIN_SEGMENT {
            return Err(IdentificationError::Option {
                what: "segment length",
                value: segment_length as f64,
                rule: format!("a Welch segment holds at least {MIN_SEGMENT} samples"),
            });
        }
        // Periodic Hann window.
        let window = (0..segment_length)
            .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / segment_length as f64).cos())
            .collect();
        let fft = FftPlanner::<f64>::new().plan_fft_forward(segment_length);
        Ok(Welch {
            dt,
            segment_length,
            window,
            fft,
        })
    }

    /// The window's samples (periodic Hann).
    pub fn window(&self) -> &[f64] {
        &self.window
    }

    pub fn segment_length(&self) -> usize {
        self.segment_length
    }

    /// Bins 0..=segment/2, Hz.
    pub fn frequencies(&self) -> Vec<f64> {
        let df = 1.0 / (self.segment_length as f64 * self.dt);
        (0..=self.segment_length / 2)
            .map(|k| k as f64 * df)
            .collect()
    }

    /// The windowed spectrum of one segment, bins 0..=segment/2.
    fn segment_spectrum(&self, samples: &[f64], buffer: &mut Vec<Complex>) {
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        buffer.clear();
        buffer.extend(
            samples
                .iter()
                .zip(&self.window)
                .map(|(s, w)| Complex::new((s - mean) * w, 0.0)),
        );
        self.fft.process(buffer);
        buffer.truncate(self.segment_length / 2 + 1);
    }

    fn segment_starts(&self, samples: usize) -> impl Iterator<Item = usize> {
        let length = self.segment_length;
        (0..)
            .map(move |s| s * (length / 2))
            .take_while(move |start| start + length <= samples)
    }

    /// Checks every run (lengths, finite values, at least one whole segment; the input present
    /// when `need_input`); the number of outputs.
    fn check_runs(&self, runs: &[Run<'_>], need_input: bool) -> Result<usize, IdentificationError> {
        let first = runs
            .first()
            .ok_or(IdentificationError::NoChannels { what: "the runs" })?;
        let outputs = first.outputs.len();
        for (r, run) in runs.iter().enumerate() {
            let n = check_channels("the responses", run.outputs)?;
            if run.outputs.len() != outputs {
                return Err(IdentificationError::Length {
                    what: format!("run {} (channels)", r + 1),
                    got: run.outputs.len(),
                    expected: outputs,
                    reference: "run 1".into(),
                });
            }
            if n < self.segment_length {
                return Err(IdentificationError::TooShort {
                    what: format!("run {}", r + 1),
                    samples: n,
                    needed: self.segment_length,
                    why: "one Welch segment".into(),
                });
            }
            match (need_input, run.input) {
                (true, None) => {
                    return Err(IdentificationError::NoChannels {
                        what: "the excitation (H1 needs the measured input)",
                    })
                }
                (_, Some(input)) => {
                    check_channels("the excitation", &[input])?;
                    if input.len() != n {
                        return Err(IdentificationError::Length {
                            what: format!("run {} excitation", r + 1),
                            got: input.len(),
                            expected: n,
                            reference: "its responses".into(),
                        });
                    }
                }
                (false, None) => {}
            }
        }
        Ok(outputs)
    }

    /// The H1 estimate of every output to the input, averaged over every segment of every run.
    pub fn h1(&self, runs: &[Run<'_>]) -> Result<Frf, IdentificationError> {
        let outputs = self.check_runs(runs, true)?;
        let bins = self.segment_length / 2 + 1;
        let mut gxx = vec![0.0; bins];
        let mut gyx = vec![vec![Complex::new(0.0, 0.0); bins]; outputs];
        let mut gyy = vec![vec![0.0; bins]; outputs];
        let mut x = Vec::with_capacity(self.segment_length);
        let mut y = Vec::with_capacity(self.segment_length);
        let mut segments = 0;
        for run in runs {
            let Some(input) = run.input else { continue };
            for start in self.segment_starts(input.len()) {
                let end = start + self.segment_length;
                self.segment_spectrum(&input[start..end], &mut x);
                for (k, xk) in x.iter().enumerate() {
                    gxx[k] += xk.norm_sqr();
                }
                for (o, output) in run.outputs.iter().enumerate() {
                    self.segment_spectrum(&output[start..end], &mut y);
                    for k in 0..bins {
                        gyx[o][k] += y[k] * x[k].conj();
                        gyy[o][k] += y[k].norm_sqr();
                    }
                }
                segments += 1;
            }
        }
        let mut response = Vec::with_capacity(outputs);
        let mut coherence = Vec::with_capacity(outputs);
        for o in 0..outputs {
            let (h, c): (Vec<_>, Vec<_>) = (0..bins)
                .map(|k| {
                    if gxx[k] > 0.0 && gyy[o][k] > 0.0 {
                        (
                            gyx[o][k] / gxx[k],
                            (gyx[o][k].norm_sqr() / (gxx[k] * gyy[o][k])).min(1.0),
                        )
                    } else {
                        (Complex::new(0.0, 0.0), 0.0)
                    }
                })
                .unzip();
            response.push(h);
            coherence.push(c);
        }
        Ok(Frf {
            frequencies: self.frequencies(),
            response,
            coherence,
            segments,
        })
    }

    /// The outputs' one-sided auto and cross spectral densities, averaged over every segment of
    /// every run (the input, if any, unused).
    pub fn output_spectra(&self, runs: &[Run<'_>]) -> Result<OutputSpectra, IdentificationError> {
        let outputs = self.check_runs(runs, false)?;
        let bins = self.segment_length / 2 + 1;
        let mut cross = vec![vec![Complex::new(0.0, 0.0); outputs * outputs]; bins];
        let mut spectra = vec![Vec::with_capacity(self.segment_length); outputs];
        let mut segments = 0;
        for run in runs {
            let n = run.outputs[0].len();
            for start in self.segment_starts(n) {
                let end = start + self.segment_length;
                for (o, output) in run.outputs.iter().enumerate() {
                    self.segment_spectrum(&output[start..end], &mut spectra[o]);
                }
                for (k, g) in cross.iter_mut().enumerate() {
                    for i in 0..outputs {
                        for j in 0..outputs {
                            g[i * outputs + j] += spectra[i][k] * spectra[j][k].conj();
                        }
                    }
                }
                segments += 1;
            }
        }
        // One-sided density: 2 / (fs Σw²) per segment, DC and Nyquist not doubled.
        let power: f64 = self.window.iter().map(|w| w * w).sum();
        let scale = self.dt / (power * segments.max(1) as f64);
        let nyquist = self.segment_length.is_multiple_of(2).then_some(bins - 1);
        for (k, g) in cross.iter_mut().enumerate() {
            let one_sided = if k == 0 || Some(k) == nyquist {
                1.0
            } else {
                2.0
            };
            for v in g.iter_mut() {
                *v *= scale * one_sided;
            }
        }
        Ok(OutputSpectra {
            frequencies: self.frequencies(),
            cross,
            outputs,
            segments,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// White noise through a known FIR filter: H1 recovers the filter's response, the coherence
    /// is ~1, and the PSD of unit white noise is 2·dt one-sided.
    #[test]
    fn h1_recovers_a_known_filter_and_the_psd_of_white_noise() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let normal = Normal::new(0.0, 1.0).expect("unit normal");
        let n = 1 << 16;
        let dt = 0.01;
        let x: Vec<f64> = (0..n).map(|_| normal.sample(&mut rng)).collect();
        // y[t] = 0.5 x[t] + 0.25 x[t-1]: H(f) = 0.5 + 0.25 e^{-i 2π f dt}.
        let y: Vec<f64> = (0..n)
            .map(|t| 0.5 * x[t] + if t > 0 { 0.25 * x[t - 1] } else { 0.0 })
            .collect();
        let welch = Welch::new(dt, 256).expect("valid options");
        let outputs = [y.as_slice()];
        let run = Run {
            input: Some(&x),
            outputs: &outputs,
        };
        let frf = welch.h1(&[run]).expect("h1");
        let mut worst: f64 = 0.0;
        for (k, f) in frf.frequencies.iter().enumerate().skip(1) {
            let exact = Complex::new(0.5, 0.0) + Complex::from_polar(0.25, -2.0 * PI * f * dt);
            worst = worst.max((frf.response[0][k] - exact).norm() / exact.norm());
            assert!(
                frf.coherence[0][k] > 0.99,
                "coherence {}",
                frf.coherence[0][k]
            );
        }
        // Measured 2e-16-level (the filter is exact within a segment but for its first
        // sample, a leakage of order 1/segment): 4e-3 bounds it with margin.
        assert!(worst < 4e-3, "worst relative H1 error {worst}");

        let psd = welch.output_spectra(&[run]).expect("spectra");
        let inputs = [x.as_slice()];
        let white = welch
            .output_spectra(&[Run {
                input: None,
                outputs: &inputs,
            }])
            .expect("spectra");
        let mean: f64 = white.auto(0)[1..128].iter().sum::<f64>() / 127.0;
        // 127 bins of 255 segments average to 2·dt within a few per cent (measured 0.4 %).
        assert!((mean / (2.0 * dt) - 1.0).abs() < 0.03, "PSD {mean}");
        assert_eq!(psd.outputs, 1);
    }

    #[test]
    fn bad_input_is_named() {
        assert!(matches!(
            Welch::new(0.0, 64),
            Err(IdentificationError::SamplingInterval(_))
        ));
        let welch = Welch::new(0.1, 64).expect("valid");
        let short = vec![0.0; 10];
        let outputs = [short.as_slice()];
        let err = welch
            .h1(&[Run {
                input: Some(&short),
                outputs: &outputs,
            }])
            .expect_err("too short");
        assert!(err.to_string().contains("run 1"), "{err}");
        let long = vec![0.0; 100];
        let err = welch
            .h1(&[Run {
                input: None,
                outputs: &[long.as_slice()],
            }])
            .expect_err("no input");
        assert!(err.to_string().contains("excitation"), "{err}");
    }
}
