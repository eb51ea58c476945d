//! `twin compare`'s options and work: the twin on a record's excitation (open loop, or in a
//! closed loop with a `twin control` report's controller), compared with every measured
//! channel.

use crate::evaluation::compare::DEFAULT_TRANSIENT;
use crate::evaluation::frf::{comparison_responses, ComparisonResponses};
use crate::evaluation::stats::variance;
use crate::twin::data::Measurement;
use crate::twin::run::{compare_with, run_and_compare_with, Compared, RunError};
use crate::twin::Twin;
use crate::workflows::control::{predict_controlled, ControlError, ControllerSpec};
use crate::workflows::learn::PAPER_THRESHOLD;
use crate::workflows::options::{check_tolerance, check_transient_leaves, InvalidOption};

/// `twin compare`'s options (what it writes aside).
#[derive(Clone, Debug, PartialEq)]
pub struct CompareOptions {
    /// Seconds at the start left out of the error measures.
    pub transient: f64,
    /// Practical significance, NMSE % (None: the twin's default, see `Tolerance::resolve`).
    pub tolerance: Option<f64>,
    /// Threshold line of the latent-variance view, (m/s²)² (None: the twin's noise variances).
    pub latent_threshold: Option<f64>,
    /// Which design of a controller's report (None: the first stable one).
    pub controller_q: Option<f64>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            transient: DEFAULT_TRANSIENT,
            tolerance: None,
            latent_threshold: None,
            controller_q: None,
        }
    }
}

impl CompareOptions {
    /// The options alone (the record's length is checked by [`CompareOptions::validate_for`]).
    pub fn validate(&self) -> Result<(), InvalidOption> {
        if let Some(t) = self.latent_threshold {
            if !(t > 0.0 && t.is_finite()) {
                return Err(InvalidOption(format!(
                    "--latent-threshold must be a positive number, was {t}"
                )));
            }
        }
        check_tolerance(self.tolerance)
    }

    /// The options against the record: the transient must leave something of it.
    pub fn validate_for(&self, data: &Measurement) -> Result<(), InvalidOption> {
        check_transient_leaves(self.transient, data)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error(transparent)]
    Options(#[from] InvalidOption),
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Control(#[from] ControlError),
}

/// Run the twin on `data` (with `controller` in the loop when given) and compare.
pub fn compare(
    twin: &Twin,
    data: &Measurement,
    options: &CompareOptions,
    controller: Option<&ControllerSpec>,
    mut progress: impl FnMut(u64, u64),
) -> Result<Compared, CompareError> {
    options.validate()?;
    options.validate_for(data)?;
    Ok(match controller {
        None => run_and_compare_with(twin, data, options.transient, options.tolerance, progress)?,
        Some(spec) => {
            let prediction =
                predict_controlled(twin, data, spec, options.controller_q, &mut progress)?;
            compare_with(
                twin,
                data,
                options.transient,
                options.tolerance,
                prediction,
                None,
            )?
        }
    })
}

/// What `twin compare --plot PATH [--frf]` draws (`report::plot_compared`), computed here: the
/// title, the frequency view's estimates (with `--frf`) and, with a corrector, the latent
/// variance of each channel it corrects with its threshold.
#[derive(Debug, Clone)]
pub struct ComparePlot {
    pub title: String,
    pub responses: Option<ComparisonResponses>,
    pub latent: Vec<LatentVariance>,
}

/// A corrected channel's latent variance `V(f)` and the threshold above which active learning
/// would query a point.
#[derive(Debug, Clone)]
pub struct LatentVariance {
    /// The channel's position in the comparison.
    pub channel: usize,
    pub values: Vec<f64>,
    pub threshold: f64,
}

/// The plot of a comparison: the threshold of a corrected channel is `options.latent_threshold`
/// when given, else its calibrated noise variance, else [`PAPER_THRESHOLD`] × its measured
/// variance after the transient on this record; an error in words when the frequency view
/// cannot be estimated.
pub fn compare_plot(
    twin: &Twin,
    data: &Measurement,
    compared: &Compared,
    options: &CompareOptions,
    frequency_view: bool,
) -> Result<ComparePlot, String> {
    let comparison = &compared.comparison;
    let responses = frequency_view
        .then(|| comparison_responses(comparison, &data.excitation))
        .transpose()?;
    let latent = comparison
        .channels
        .iter()
        .enumerate()
        .filter_map(|(c, channel)| {
            let values = compared.prediction.get(*channel)?.latent_var.clone()?;
            let threshold = match (options.latent_threshold, twin.noise_variance_of(*channel)) {
                (Some(t), _) => t,
                (None, Some(v)) => v,
                (None, None) => {
                    PAPER_THRESHOLD * variance(&comparison.measured[c][comparison.first..])
                }
            };
            Some(LatentVariance {
                channel: c,
                values,
                threshold,
            })
        })
        .collect();
    Ok(ComparePlot {
        title: format!("{} on {}", twin.describe(), data.path.display()),
        responses,
        latent,
    })
}

/// One channel of `twin compare --frf FRF`: the measured and the twin's magnitude over the band
/// (dB re 1 SI unit per unit excitation; the measured one less the gain offset, if any), the
/// twin's ±3σ band from its parameters' posterior, and the error.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FrfChannelView {
    pub channel: String,
    pub measured_db: Vec<f64>,
    pub twin_db: Vec<f64>,
    /// The twin's sd of 20 log10|H| (dB) from its posterior covariance; None when uncalibrated.
    pub twin_sd_db: Option<Vec<f64>>,
    /// RMS over the band of the difference of the log magnitudes, measured − twin, dB.
    pub rms_error_db: f64,
    /// The share of lines where the measured magnitude is inside the twin's ±3σ band.
    pub inside_band: Option<f64>,
}

/// The measured FRF against the twin's: per channel, the resonances of both.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FrfView {
    pub record: String,
    pub twin: String,
    /// Hz, the band's lines.
    pub frequency: Vec<f64>,
    pub channels: Vec<FrfChannelView>,
    /// The error measure, in words.
    pub error_measure: &'static str,
    /// The constant (dB) taken off the measured magnitudes when their reference is unknown:
    /// the mean difference measured − twin over every channel and line.
    pub gain_offset_db: Option<f64>,
    pub twin_modes: Vec<crate::workflows::calibrate::frf::TwinMode>,
    pub measured_peaks: Vec<crate::workflows::calibrate::frf::MeasuredPeak>,
    /// How the measured resonances were found.
    pub peak_method: &'static str,
}

/// The posterior over the structure's own parameters (others, e.g. an effect's, are not in the
/// linear FRF).
fn structure_covariance(
    cov: &crate::twin::ParameterCovariance,
    structure: &::structure::Structure,
) -> crate::twin::ParameterCovariance {
    let keep: Vec<usize> = (0..cov.names.len())
        .filter(|&a| structure.get(&cov.names[a]).is_some())
        .collect();
    crate::twin::ParameterCovariance {
        names: keep.iter().map(|&a| cov.names[a].clone()).collect(),
        matrix: keep
            .iter()
            .map(|&a| keep.iter().map(|&b| cov.matrix[a][b]).collect())
            .collect(),
    }
}

/// Channel `c`'s view (its name left to the caller): the measured magnitude less `offset`
/// (dB), the twin's with its ±sd from `covariance` (the first-order sd of 20 log10|H|), the
/// RMS error and the share of lines inside ±3 sd.
fn channel_view(
    model: &crate::evaluation::frf::StructureFrf,
    c: usize,
    measured: &[f64],
    twin_db: &[f64],
    offset: f64,
    covariance: Option<&crate::twin::ParameterCovariance>,
) -> FrfChannelView {
    let to_db = 20.0 / std::f64::consts::LN_10;
    let lines = twin_db.len();
    let measured_db: Vec<f64> = measured.iter().map(|m| m - offset).collect();
    let twin_sd_db = covariance.map(|cov| {
        (0..lines)
            .map(|k| {
                let g: Vec<f64> = (0..cov.names.len())
                    .map(|j| to_db * (model.sensitivities[c][j][k] / model.values[c][k]).re)
                    .collect();
                let mut v = 0.0;
                for a in 0..g.len() {
                    for b in 0..g.len() {
                        v += g[a] * cov.matrix[a][b] * g[b];
                    }
                }
                v.max(0.0).sqrt()
            })
            .collect::<Vec<f64>>()
    });
    let n = lines as f64;
    let rms_error_db = (measured_db
        .iter()
        .zip(twin_db)
        .map(|(m, t)| (m - t).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let inside_band = twin_sd_db.as_ref().map(|sd| {
        measured_db
            .iter()
            .zip(twin_db)
            .zip(sd)
            .filter(|((m, t), s)| (*m - *t).abs() <= 3.0 * *s)
            .count() as f64
            / n
    });
    FrfChannelView {
        channel: String::new(),
        measured_db,
        twin_db: twin_db.to_vec(),
        twin_sd_db,
        rms_error_db,
        inside_band,
    }
}

/// `twin compare --frf FRF`: the twin's exact FRF (its linear structure: any effect it carries
/// is linearised away) against the measured one over `band` (every line above 0 Hz when None).
pub fn frf_view(
    twin: &Twin,
    frf: &crate::record::frf::MeasuredFrf,
    band: Option<(f64, f64)>,
    gain_offset: bool,
) -> Result<FrfView, crate::workflows::calibrate::CalibrateError> {
    use crate::evaluation::frf::structure_frf;
    use crate::record::frf::db;
    use crate::workflows::calibrate::frf::{band_lines, measured_peaks, twin_modes};
    use crate::workflows::calibrate::CalibrateError;
    let structure = twin.structure()?;
    let lines = band_lines(frf, band);
    if lines.len() < 2 {
        return Err(CalibrateError::Setup(format!(
            "{}: {} frequency lines in the band; at least 2 are needed",
            frf.path.display(),
            lines.len()
        )));
    }
    let frequency: Vec<f64> = lines.iter().map(|&k| frf.frequency[k]).collect();
    let channels: Vec<_> = frf.channels.iter().map(|c| c.channel).collect();
    for c in &channels {
        c.check(&c.name(), &structure)
            .map_err(|e| CalibrateError::Setup(format!("{}: {e}", frf.path.display())))?;
    }
    // The posterior over the structure's own parameters (others, e.g. an effect's, are not in
    // the linear FRF).
    let covariance = twin
        .parameter_covariance
        .as_ref()
        .map(|cov| structure_covariance(cov, &structure));
    let names = covariance
        .as_ref()
        .map(|c| c.names.clone())
        .unwrap_or_default();
    let model = structure_frf(&structure, &channels, &frequency, &names)
        .map_err(|e| CalibrateError::Setup(format!("{}: {e}", frf.path.display())))?;
    let measured: Vec<Vec<f64>> = frf
        .channels
        .iter()
        .map(|c| {
            let all = c.values.magnitude_db();
            lines.iter().map(|&k| all[k]).collect()
        })
        .collect();
    let twin_db: Vec<Vec<f64>> = model
        .values
        .iter()
        .map(|h| h.iter().map(|h| db(h.norm())).collect())
        .collect();
    let offset = gain_offset.then(|| {
        let (sum, n) = measured
            .iter()
            .zip(&twin_db)
            .flat_map(|(m, t)| m.iter().zip(t).map(|(m, t)| m - t))
            .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
        sum / n as f64
    });
    let views = (0..channels.len())
        .map(|c| FrfChannelView {
            channel: channels[c].name(),
            ..channel_view(
                &model,
                c,
                &measured[c],
                &twin_db[c],
                offset.unwrap_or(0.0),
                covariance.as_ref(),
            )
        })
        .collect();
    Ok(FrfView {
        record: frf.path.display().to_string(),
        twin: twin.describe(),
        error_measure:
            "RMS over the band's lines of 20 log10|H_measured| − 20 log10|H_twin| (dB), \
                        unweighted",
        gain_offset_db: offset,
        twin_modes: twin_modes(&structure, covariance.as_ref()),
        measured_peaks: measured_peaks(&frequency, &measured),
        peak_method: "peaks of the channels' summed power standing 10 dB above their valleys; \
                      damping from the half-power (−3 dB) bandwidth",
        frequency,
        channels: views,
    })
}
