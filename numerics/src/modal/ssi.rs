//! Covariance-driven stochastic subspace identification (SSI-COV), output-only.
//!
//! The outputs' correlations `R_k = E[y(t+k) y(t)ᵀ]` (FFT-based, so an hour-long record costs a
//! few transforms) fill the block Toeplitz matrix `T = [R_i … R_1; …; R_2i−1 … R_i]`
//! (`i` block rows), which factors as the observability matrix times the controllability one.
//! One SVD of `T` at the largest order serves every order `n`: `O_n = U_n S_n^½`, `C` its first
//! block row, `A` from the shift of `O_n` (least squares). The eigenvalues `μ` of `A` give the
//! poles `λ = ln μ / dt`, its eigenvectors `ψ` the shapes `C ψ`.

use faer::Mat;
use nalgebra::DMatrix;

use super::Complex;
use rustfft::FftPlanner;
use serde::{Deserialize, Serialize};

use super::error::{check_channels, check_dt, IdentificationError};
use super::spectral::Run;
use super::stabilisation::{ModelOrder, Pole};

/// The model orders of an SSI-COV run and the size of its Toeplitz matrix.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SsiOptions {
    /// Orders `min_order, min_order + order_step, …, max_order` (state dimensions; two per mode).
    pub min_order: usize,
    pub max_order: usize,
    pub order_step: usize,
    /// Block rows `i` of the Toeplitz matrix (lags up to `2i − 1`); `None`: enough for
    /// `max_order` and at least [`DEFAULT_MIN_BLOCK_ROWS`].
    pub block_rows: Option<usize>,
}

/// The fewest block rows chosen by default: enough lags for lightly damped modes to show
/// their decay even on few channels.
pub const DEFAULT_MIN_BLOCK_ROWS: usize = 20;

impl Default for SsiOptions {
    fn default() -> Self {
        SsiOptions {
            min_order: 2,
            max_order: 40,
            order_step: 2,
            block_rows: None,
        }
    }
}

impl SsiOptions {
    /// The block rows used on `channels` outputs.
    pub fn block_rows_for(&self, channels: usize) -> usize {
        self.block_rows.unwrap_or_else(|| {
            (self.max_order.div_ceil(channels.max(1)) + 1).max(DEFAULT_MIN_BLOCK_ROWS)
        })
    }

    /// Checks the orders against each other and against the Toeplitz matrix on `channels`.
    pub fn validate(&self, channels: usize) -> Result<(), IdentificationError> {
        let option = |what, value: usize, rule: String| {
            Err(IdentificationError::Option {
                what,
                value: value as f64,
                rule,
            })
        };
        if self.order_step == 0 {
            return option("order step", 0, "at least 1".into());
        }
        if self.min_order < 2 {
            return option(
                "least model order",
                self.min_order,
                "at least 2 (one mode)".into(),
            );
        }
        if self.max_order < self.min_order {
            return option(
                "largest model order",
                self.max_order,
                format!("at least the least order, {}", self.min_order),
            );
        }
        let rows = self.block_rows_for(channels);
        if rows < 2 {
            return option("block rows", rows, "at least 2".into());
        }
        let shifted = channels * (rows - 1);
        if self.max_order > shifted {
            return option(
                "largest model order",
                self.max_order,
                format!(
                    "at most channels × (block rows − 1) = {channels} × {} = {shifted}",
                    rows - 1
                ),
            );
        }
        Ok(())
    }
}

/// The outputs' correlation matrices `R_0..=R_max_lag` (channels × channels; `R_k[a][b]` =
/// mean of `y_a(t+k) y_b(t)`), each channel's mean removed, pooled over the runs.
pub fn output_correlations(
    runs: &[Run<'_>],
    max_lag: usize,
) -> Result<Vec<DMatrix<f64>>, IdentificationError> {
    let first = runs
        .first()
        .ok_or(IdentificationError::NoChannels { what: "the runs" })?;
    let channels = first.outputs.len();
    let mut sums = vec![DMatrix::<f64>::zeros(channels, channels); max_lag + 1];
    let mut counts = vec![0usize; max_lag + 1];
    let mut planner = FftPlanner::<f64>::new();
    for (r, run) in runs.iter().enumerate() {
        let n = check_channels("the responses", run.outputs)?;
        if run.outputs.len() != channels {
            return Err(IdentificationError::Length {
                what: format!("run {} (channels)", r + 1),
                got: run.outputs.len(),
                expected: channels,
                reference: "run 1".into(),
            });
        }
        if n <= max_lag {
            return Err(IdentificationError::TooShort {
                what: format!("run {}", r + 1),
                samples: n,
                needed: max_lag + 1,
                why: format!("correlations up to lag {max_lag}"),
            });
        }
        let size = (n + max_lag).next_power_of_two();
        let forward = planner.plan_fft_forward(size);
        let inverse = planner.plan_fft_inverse(size);
        let spectra: Vec<Vec<Complex>> = run
            .outputs
            .iter()
            .map(|y| {
                let mean = y.iter().sum::<f64>() / n as f64;
                let mut buffer: Vec<Complex> = y
                    .iter()
                    .map(|v| Complex::new(v - mean, 0.0))
                    .chain(std::iter::repeat_n(Complex::new(0.0, 0.0), size - n))
                    .collect();
                forward.process(&mut buffer);
                buffer
            })
            .collect();
        // Two real correlations per inverse transform: Y_a conj(Y_b) has a real inverse, so
        // P + iQ carries one pair in the real part and another in the imaginary part. The
        // inverse at index k is Σ_t y_a(t+k) y_b(t); at size − k it is the lag −k, i.e. the
        // pair (b, a) at lag k.
        let pairs: Vec<(usize, usize)> = (0..channels)
            .flat_map(|a| (a..channels).map(move |b| (a, b)))
            .collect();
        let mut buffer = vec![Complex::new(0.0, 0.0); size];
        for chunk in pairs.chunks(2) {
            let (a, b) = chunk[0];
            let second = chunk.get(1).copied();
            for (k, v) in buffer.iter_mut().enumerate() {
                let p = spectra[a][k] * spectra[b][k].conj();
                *v = match second {
                    Some((c, d)) => p + Complex::i() * (spectra[c][k] * spectra[d][k].conj()),
                    None => p,
                };
            }
            inverse.process(&mut buffer);
            let scale = 1.0 / size as f64;
            for (lag, sum) in sums.iter_mut().enumerate() {
                let ahead = buffer[lag] * scale;
                let behind = buffer[(size - lag) % size] * scale;
                sum[(a, b)] += ahead.re;
                if a != b {
                    sum[(b, a)] += behind.re;
                }
                if let Some((c, d)) = second {
                    sum[(c, d)] += ahead.im;
                    if c != d {
                        sum[(d, c)] += behind.im;
                    }
                }
            }
        }
        for (lag, count) in counts.iter_mut().enumerate() {
            *count += n - lag;
        }
    }
    Ok(sums
        .into_iter()
        .zip(counts)
        .map(|(sum, count)| sum / count as f64)
        .collect())
}

/// The poles of every order of `options` identified from the outputs of `runs` sampled every
/// `dt` s (the runs' inputs, if any, unused).
pub fn ssi_cov(
    runs: &[Run<'_>],
    dt: f64,
    options: &SsiOptions,
) -> Result<Vec<ModelOrder>, IdentificationError> {
    check_dt(dt)?;
    let channels = runs
        .first()
        .map(|r| r.outputs.len())
        .ok_or(IdentificationError::NoChannels { what: "the runs" })?;
    if channels == 0 {
        return Err(IdentificationError::NoChannels {
            what: "the responses",
        });
    }
    options.validate(channels)?;
    let rows = options.block_rows_for(channels);
    let max_lag = 2 * rows - 1;
    // The statistics of lag 2i − 1 need many more samples than lags; 10× is a floor, not a
    // guarantee of accuracy.
    let needed = 10 * (max_lag + 1);
    for (r, run) in runs.iter().enumerate() {
        let n = run.outputs.first().map_or(0, |y| y.len());
        if n < needed {
            return Err(IdentificationError::TooShort {
                what: format!("run {}", r + 1),
                samples: n,
                needed,
                why: format!("SSI-COV with {rows} block rows (lags up to {max_lag})"),
            });
        }
    }
    let correlations = output_correlations(runs, max_lag)?;
    let size = channels * rows;
    let mut toeplitz = DMatrix::<f64>::zeros(size, size);
    for a in 0..rows {
        for b in 0..rows {
            toeplitz
                .view_mut((a * channels, b * channels), (channels, channels))
                .copy_from(&correlations[rows + a - b]);
        }
    }
    let svd = toeplitz.svd(true, false);
    let (Some(u), singular) = (svd.u.as_ref(), &svd.singular_values) else {
        return Err(IdentificationError::Numerical {
            what: "SSI-COV",
            why: "the SVD of the Toeplitz matrix gave no left vectors".into(),
        });
    };
    // nalgebra's SVD leaves the singular values unsorted: order them, largest first.
    let mut by_size: Vec<usize> = (0..singular.len()).collect();
    by_size.sort_by(|&i, &j| singular[j].total_cmp(&singular[i]));
    let mut orders = Vec::new();
    let mut order = options.min_order;
    while order <= options.max_order {
        let observability = DMatrix::from_fn(size, order, |r, c| {
            u[(r, by_size[c])] * singular[by_size[c]].max(0.0).sqrt()
        });
        orders.push(ModelOrder {
            order,
            poles: poles_of(&observability, channels, dt)?,
        });
        order += options.order_step;
    }
    Ok(orders)
}

/// The poles of the model whose observability matrix is `observability` (block rows of
/// `channels`).
fn poles_of(
    observability: &DMatrix<f64>,
    channels: usize,
    dt: f64,
) -> Result<Vec<Pole>, IdentificationError> {
    let (rows, order) = observability.shape();
    let upper = observability.rows(0, rows - channels).into_owned();
    let lower = observability.rows(channels, rows - channels).into_owned();
    let state = upper
        .svd(true, true)
        .solve(&lower, 1e-12 * observability.norm())
        .map_err(|why| IdentificationError::Numerical {
            what: "SSI-COV (state matrix)",
            why: why.to_owned(),
        })?;
    let output = observability.rows(0, channels);
    let eigen = Mat::<f64>::from_fn(order, order, |r, c| state[(r, c)])
        .eigen()
        .map_err(|why| IdentificationError::Numerical {
            what: "SSI-COV (eigenvalues of the state matrix)",
            why: format!("{why:?}"),
        })?;
    let values = eigen.S().column_vector();
    let vectors = eigen.U();
    let mut poles = Vec::new();
    for k in 0..order {
        let mu = values[k];
        // One of each conjugate pair; real eigenvalues are no vibration.
        if mu.im <= 0.0 {
            continue;
        }
        let eigenvalue = mu.ln() / dt;
        let shape = (0..channels)
            .map(|r| {
                (0..order)
                    .map(|c| vectors[(c, k)] * output[(r, c)])
                    .sum::<Complex>()
            })
            .collect();
        poles.push(Pole::new(eigenvalue, shape));
    }
    poles.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
    Ok(poles)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The FFT correlations equal the direct sums.
    #[test]
    fn correlations_match_the_direct_sums() {
        let n = 500;
        let channels: Vec<Vec<f64>> = (0..3)
            .map(|c| {
                (0..n)
                    .map(|t| ((t * (c + 2)) as f64 * 0.37).sin() + 0.1 * c as f64)
                    .collect()
            })
            .collect();
        let views: Vec<&[f64]> = channels.iter().map(|c| c.as_slice()).collect();
        let run = Run {
            input: None,
            outputs: &views,
        };
        let r = output_correlations(&[run], 7).expect("correlations");
        let centred: Vec<Vec<f64>> = channels
            .iter()
            .map(|c| {
                let m = c.iter().sum::<f64>() / n as f64;
                c.iter().map(|v| v - m).collect()
            })
            .collect();
        for (lag, matrix) in r.iter().enumerate() {
            for a in 0..3 {
                for b in 0..3 {
                    let direct: f64 = (0..n - lag)
                        .map(|t| centred[a][t + lag] * centred[b][t])
                        .sum::<f64>()
                        / (n - lag) as f64;
                    assert!(
                        (matrix[(a, b)] - direct).abs() < 1e-12,
                        "lag {lag} ({a},{b})"
                    );
                }
            }
        }
    }

    #[test]
    fn orders_beyond_the_toeplitz_matrix_are_refused() {
        let options = SsiOptions {
            max_order: 50,
            block_rows: Some(10),
            ..SsiOptions::default()
        };
        let err = options.validate(3).expect_err("too large");
        assert!(err.to_string().contains("largest model order"), "{err}");
        let y = vec![0.0; 100];
        let outputs = [y.as_slice()];
        let err = ssi_cov(
            &[Run {
                input: None,
                outputs: &outputs,
            }],
            0.01,
            &SsiOptions::default(),
        )
        .expect_err("too short");
        assert!(err.to_string().contains("run 1"), "{err}");
    }
}
