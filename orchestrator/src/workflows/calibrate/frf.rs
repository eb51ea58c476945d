//! MAP calibration of the twin's linear structure on a measured FRF (`twin calibrate --frf`), with
//! its Laplace posterior.
//!
//! The model is the exact FRF of the twin's structure (`evaluation::frf::structure_frf`: M, C, K
//! and the excitation; any effect the twin carries — a contact, a cubic spring — is linearised
//! away, i.e. left out). The residuals, per measured channel, are the log magnitude in dB
//! (`20 log10|H_meas| − 20 log10|H_twin| − g`, `g` a gain offset when the file's dB reference is
//! unknown, else 0) and, where the file gives the complex FRF, the phase difference wrapped to
//! (−π, π]. Each residual is weighted by `w_k = clamp(|H_meas,k| / median |H_meas|, 1,`
//! [`RESONANCE_WEIGHT_CAP`]`)`: a lightly damped resonance spans a handful of frequency lines,
//! and unweighted it would count for little against the hundreds of lines between resonances.
//! Each block (channel, magnitude or phase) has its own noise sd `σ_b`; the negative log
//! posterior is `Σ_b [N_b log σ_b + Σ_k w_k e_k² / (2σ_b²)] + ‖z‖²/2`, `z` the parameters
//! standardised by their priors (the time-domain calibration's priors, `prior.rs`), and a
//! gain offset's prior `N(0, GAIN_PRIOR_SD_DB²)`.
//!
//! Optimiser: for fixed `σ_b`, Levenberg–Marquardt ([`super::lm`]) with the analytic Jacobian
//! from the FRF's parameter sensitivities; then each `σ_b² = Σ w e² / N_b`; the two alternate
//! until the sds settle. Starts: the prior mean and draws from the prior (seeded); the best
//! posterior wins. Uncertainty: the Gauss–Newton Hessian at the optimum (the `σ_b` held at
//! their MAP), inverted.

use std::f64::consts::PI;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::StandardNormal;
use rustfft::num_complex::Complex;
use serde::Serialize;

use ::structure::Structure;

use super::lm;
use super::{
    default_prior, physics_structure, priors_from_json, structure_prior, CalibrateError,
    ParameterEstimate, Prior, PriorSpec, Space,
};
use crate::evaluation::frf::{peaks, structure_frf, structure_modes};
use crate::record::frf::{db, FrfChannel, MeasuredFrf};
use crate::twin::{ParameterCovariance, ParameterValue, Twin, PHYSICS};

/// The largest weight a resonance's lines get over the median line.
pub const RESONANCE_WEIGHT_CAP: f64 = 10.0;
/// The gain offset's prior sd, dB: wide, so the data set it.
pub const GAIN_PRIOR_SD_DB: f64 = 40.0;
/// A measured peak must stand this far (dB) above the valleys beside it.
pub const PEAK_PROMINENCE_DB: f64 = 10.0;

/// What an FRF calibration is asked for.
#[derive(Debug, Clone)]
pub struct FrfSetup {
    /// `m<i>`, `c<i>`, `k<i>` of the twin's structure; empty: all of them.
    pub parameters: Vec<String>,
    /// A priors file over the twin's own priors over the structure's defaults.
    pub prior_spec: Option<PriorSpec>,
    /// The band used, Hz (inclusive); None: every line above 0 Hz.
    pub band: Option<(f64, f64)>,
    /// Fit a gain offset (dB) on the magnitudes: the file's dB reference is unknown.
    pub gain_offset: bool,
    pub starts: usize,
    pub seed: u64,
}

impl Default for FrfSetup {
    fn default() -> Self {
        FrfSetup {
            parameters: Vec::new(),
            prior_spec: None,
            band: None,
            gain_offset: false,
            starts: 4,
            seed: 1,
        }
    }
}

/// A value with its posterior sd.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Estimate {
    pub value: f64,
    pub sd: f64,
}

/// A mode of the calibrated twin: its frequency (with the posterior sd) and damping ratio.
#[derive(Debug, Clone, Serialize)]
pub struct TwinMode {
    pub frequency_hz: Estimate,
    pub damping_ratio: f64,
}

/// A resonance of the measured FRF: its peak and half-power damping ratio (None where a −3 dB
/// point lies outside the band).
#[derive(Debug, Clone, Serialize)]
pub struct MeasuredPeak {
    pub frequency_hz: f64,
    pub damping_ratio: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct FrfCalibration {
    pub record: String,
    pub parameters: Vec<ParameterEstimate>,
    /// Correlation of the calibrated parameters (prior coordinates).
    pub correlation: Vec<Vec<f64>>,
    /// The fitted gain offset, dB (measured − twin), when asked for.
    pub gain_offset_db: Option<Estimate>,
    pub channels: Vec<String>,
    /// The band used, Hz, and its lines.
    pub band_hz: (f64, f64),
    pub lines: usize,
    /// The magnitude residual's sd per channel at the MAP (dB, resonance-weighted).
    pub magnitude_sd_db: Vec<f64>,
    /// The phase residual's sd per channel (rad), where the file gives phase.
    pub phase_sd_rad: Vec<Option<f64>>,
    /// The RMS magnitude error per channel over the band (dB, unweighted, after the gain offset).
    pub rms_error_db: Vec<f64>,
    pub twin_modes: Vec<TwinMode>,
    pub measured_peaks: Vec<MeasuredPeak>,
    pub neg_log_posterior: f64,
    /// Each start's negative log posterior (None: it failed).
    pub starts: Vec<Option<f64>>,
    pub seconds: f64,
}

/// Measured − twin per channel: the magnitude (dB) and, where given, the phase (rad).
type Errors = Vec<(Vec<f64>, Option<Vec<f64>>)>;

/// The measured data in the band, per channel.
struct Block {
    magnitude_db: Vec<f64>,
    phase: Option<Vec<f64>>,
    /// `√w_k`.
    sqrt_weight: Vec<f64>,
}

struct Problem<'a> {
    structure: Structure,
    names: &'a [String],
    priors: &'a [Prior],
    channels: Vec<::structure::channel::Channel>,
    frequency: Vec<f64>,
    blocks: Vec<Block>,
    gain: bool,
    /// Per channel: σ of the magnitude (dB) and of the phase (rad).
    sigma: Vec<(f64, f64)>,
}

/// `x` wrapped to (−π, π].
fn wrap(x: f64) -> f64 {
    let y = (x + PI).rem_euclid(2.0 * PI) - PI;
    if y == -PI {
        PI
    } else {
        y
    }
}

impl Problem<'_> {
    fn parameters(&self) -> usize {
        self.names.len()
    }
    fn values(&self, z: &[f64]) -> Vec<f64> {
        z.iter()
            .zip(self.priors)
            .map(|(z, p)| p.value(p.mean + p.sd() * z))
            .collect()
    }
    fn gain_db(&self, z: &[f64]) -> f64 {
        if self.gain {
            GAIN_PRIOR_SD_DB * z[self.parameters()]
        } else {
            0.0
        }
    }
    fn structure_at(&self, z: &[f64]) -> Option<Structure> {
        let values = self.values(z);
        if values.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut s = self.structure.clone();
        for (name, v) in self.names.iter().zip(values) {
            s.set(name, v);
        }
        s.validate().ok()?;
        Some(s)
    }
    /// Raw errors (measured − twin) per channel: magnitude (dB) and phase (rad).
    fn errors(
        &self,
        z: &[f64],
        with: &[String],
    ) -> Option<(Errors, crate::evaluation::frf::StructureFrf)> {
        let s = self.structure_at(z)?;
        let frf = structure_frf(&s, &self.channels, &self.frequency, with).ok()?;
        let g = self.gain_db(z);
        let errors = self
            .blocks
            .iter()
            .zip(&frf.values)
            .map(|(b, h)| {
                let mag = b
                    .magnitude_db
                    .iter()
                    .zip(h)
                    .map(|(m, h)| m - db(h.norm()) - g)
                    .collect();
                let phase = b
                    .phase
                    .as_ref()
                    .map(|p| p.iter().zip(h).map(|(p, h)| wrap(p - h.arg())).collect());
                (mag, phase)
            })
            .collect();
        Some((errors, frf))
    }
    fn weighted(&self, errors: &[(Vec<f64>, Option<Vec<f64>>)], z: &[f64]) -> DVector<f64> {
        let mut r = Vec::new();
        for ((b, (mag, phase)), (s_mag, s_ph)) in self.blocks.iter().zip(errors).zip(&self.sigma) {
            r.extend(mag.iter().zip(&b.sqrt_weight).map(|(e, w)| e * w / s_mag));
            if let Some(phase) = phase {
                r.extend(phase.iter().zip(&b.sqrt_weight).map(|(e, w)| e * w / s_ph));
            }
        }
        r.extend_from_slice(z);
        DVector::from_vec(r)
    }
    /// Σ_b N_b log σ_b + ½‖r‖².
    fn objective(&self, r: &DVector<f64>) -> f64 {
        let mut j = 0.5 * r.norm_squared();
        for (b, (s_mag, s_ph)) in self.blocks.iter().zip(&self.sigma) {
            let n = b.magnitude_db.len() as f64;
            j += n * s_mag.ln();
            if b.phase.is_some() {
                j += n * s_ph.ln();
            }
        }
        j
    }
    /// Each block's σ at its MAP for these errors: `σ² = Σ w e² / N`.
    fn settle_sigma(&mut self, errors: &[(Vec<f64>, Option<Vec<f64>>)]) -> f64 {
        let mut change: f64 = 0.0;
        for ((b, (mag, phase)), sigma) in self.blocks.iter().zip(errors).zip(&mut self.sigma) {
            let ms = |e: &[f64]| {
                (e.iter()
                    .zip(&b.sqrt_weight)
                    .map(|(e, w)| (e * w).powi(2))
                    .sum::<f64>()
                    / e.len() as f64)
                    .sqrt()
                    .max(1e-9)
            };
            let new_mag = ms(mag);
            change = change.max((new_mag / sigma.0).ln().abs());
            sigma.0 = new_mag;
            if let Some(phase) = phase {
                let new_ph = ms(phase);
                change = change.max((new_ph / sigma.1).ln().abs());
                sigma.1 = new_ph;
            }
        }
        change
    }
}

impl lm::LeastSquares for Problem<'_> {
    fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>> {
        let (errors, _) = self.errors(z, &[])?;
        Some(self.weighted(&errors, z))
    }

    fn jacobian(&mut self, z: &[f64], r: &DVector<f64>) -> Option<DMatrix<f64>> {
        let (_, frf) = self.errors(z, self.names)?;
        let values = self.values(z);
        let p = self.parameters();
        let cols = z.len();
        // ∂u_j/∂z_j: the prior's scale, times the value where the prior is on the log.
        let scale: Vec<f64> = (0..p)
            .map(|j| match self.priors[j].space {
                Space::Linear => self.priors[j].sd(),
                Space::Log => self.priors[j].sd() * values[j],
            })
            .collect();
        let mut jac = DMatrix::zeros(r.len(), cols);
        let to_db = 20.0 / std::f64::consts::LN_10;
        let mut row = 0;
        for (c, (b, (s_mag, s_ph))) in self.blocks.iter().zip(&self.sigma).enumerate() {
            let h = &frf.values[c];
            // d log H / dp = dH/dp / H: its real part is d ln|H|, its imaginary part d arg H.
            let relative =
                |j: usize, k: usize| -> Complex<f64> { frf.sensitivities[c][j][k] / h[k] };
            for k in 0..h.len() {
                let w = b.sqrt_weight[k] / s_mag;
                for j in 0..p {
                    jac[(row + k, j)] = -w * to_db * relative(j, k).re * scale[j];
                }
                if self.gain {
                    jac[(row + k, p)] = -w * GAIN_PRIOR_SD_DB;
                }
            }
            row += h.len();
            if b.phase.is_some() {
                for k in 0..h.len() {
                    let w = b.sqrt_weight[k] / s_ph;
                    for j in 0..p {
                        jac[(row + k, j)] = -w * relative(j, k).im * scale[j];
                    }
                }
                row += h.len();
            }
        }
        for j in 0..cols {
            jac[(row + j, j)] = 1.0;
        }
        jac.iter().all(|x| x.is_finite()).then_some(jac)
    }
}

struct Fit {
    z: Vec<f64>,
    sigma: Vec<(f64, f64)>,
    objective: f64,
}

fn run_start(problem: &mut Problem, z0: Vec<f64>) -> Option<Fit> {
    let mut z = z0;
    // The noise sds settle to 1 % in a few rounds; the LM stops at a relative reduction of
    // 1e-8 (tighter changes nothing a Laplace posterior would show).
    let settings = lm::Settings {
        ftol: 1e-8,
        xtol: 1e-8,
        ..lm::Settings::default()
    };
    for _ in 0..6 {
        let r0 = lm::LeastSquares::residuals(problem, &z)?;
        z = lm::minimize(problem, z, r0, settings).0;
        let (errors, _) = problem.errors(&z, &[])?;
        if problem.settle_sigma(&errors) < 1e-2 {
            break;
        }
    }
    let r = lm::LeastSquares::residuals(problem, &z)?;
    let objective = problem.objective(&r);
    objective.is_finite().then(|| Fit {
        z,
        sigma: problem.sigma.clone(),
        objective,
    })
}

/// The resonances of a measured FRF over its band: the peaks of the channels' summed power.
pub fn measured_peaks(frequency: &[f64], magnitudes_db: &[Vec<f64>]) -> Vec<MeasuredPeak> {
    let summed: Vec<f64> = (0..frequency.len())
        .map(|k| {
            let power: f64 = magnitudes_db.iter().map(|m| 10f64.powf(m[k] / 10.0)).sum();
            10.0 * (power / magnitudes_db.len().max(1) as f64).log10()
        })
        .collect();
    peaks(frequency, &summed, PEAK_PROMINENCE_DB)
        .into_iter()
        .map(|(f, zeta)| MeasuredPeak {
            frequency_hz: f,
            damping_ratio: zeta,
        })
        .collect()
}

/// The modes of `structure` with each frequency's sd from `covariance` (parameters in their own
/// units) through the frequencies' sensitivities (central differences on the eigenvalues).
pub fn twin_modes(
    structure: &Structure,
    covariance: Option<&ParameterCovariance>,
) -> Vec<TwinMode> {
    let modes = structure_modes(structure);
    let mut variance = vec![0.0; modes.len()];
    if let Some(cov) = covariance {
        let gradients: Vec<Option<Vec<f64>>> = cov
            .names
            .iter()
            .map(|name| {
                let value = structure.get(name)?;
                let h = 1e-6 * value.abs().max(1e-12);
                let shifted = |d: f64| {
                    let mut s = structure.clone();
                    s.set(name, value + d);
                    structure_modes(&s)
                };
                let (plus, minus) = (shifted(h), shifted(-h));
                (plus.len() == modes.len() && minus.len() == modes.len()).then(|| {
                    (0..modes.len())
                        .map(|i| (plus[i].0 - minus[i].0) / (2.0 * h))
                        .collect()
                })
            })
            .collect();
        for (i, v) in variance.iter_mut().enumerate() {
            for (a, ga) in gradients.iter().enumerate() {
                for (b, gb) in gradients.iter().enumerate() {
                    if let (Some(ga), Some(gb)) = (ga, gb) {
                        *v += ga[i] * cov.matrix[a][b] * gb[i];
                    }
                }
            }
        }
    }
    modes
        .iter()
        .zip(variance)
        .map(|(&(f, zeta), v)| TwinMode {
            frequency_hz: Estimate {
                value: f,
                sd: v.max(0.0).sqrt(),
            },
            damping_ratio: zeta,
        })
        .collect()
}

/// The lines of `frf` inside `band` (all above 0 Hz when None): their indices.
pub fn band_lines(frf: &MeasuredFrf, band: Option<(f64, f64)>) -> Vec<usize> {
    (0..frf.frequency.len())
        .filter(|&k| {
            let f = frf.frequency[k];
            f > 0.0 && band.is_none_or(|(lo, hi)| f >= lo && f <= hi)
        })
        .collect()
}

/// Calibrate the twin's linear structure on `frf`: the MAP, its Laplace posterior, and the
/// calibrated twin (the values and the posterior covariance stored in it; its noise variances
/// are left unset, since an FRF says nothing of the sensors' noise in time).
pub fn calibrate_frf(
    twin: &Twin,
    frf: &MeasuredFrf,
    setup: &FrfSetup,
) -> Result<(Twin, FrfCalibration), CalibrateError> {
    let started = Instant::now();
    let structure = twin.structure()?;
    let nominal = nominal_structure(twin)?;
    let names = parameter_names(&structure, setup)?;
    check_band(setup.band)?;
    let priors = parameter_priors(twin, setup, &structure, &nominal, &names)?;
    let unknowns = names.len() + usize::from(setup.gain_offset);
    let lines = lines_for(frf, setup.band, unknowns)?;
    let frequency: Vec<f64> = lines.iter().map(|&k| frf.frequency[k]).collect();
    let channels = checked_channels(frf, &structure)?;
    let blocks: Vec<Block> = frf.channels.iter().map(|c| Block::of(c, &lines)).collect();
    let mut problem = Problem {
        structure: structure.clone(),
        names: &names,
        priors: &priors,
        channels,
        frequency: frequency.clone(),
        sigma: vec![(3.0, 0.3); blocks.len()],
        blocks,
        gain: setup.gain_offset,
    };
    let starts = best_of_starts(&mut problem, unknowns, setup, frf)?;
    let cov = posterior_covariance(&mut problem, &starts.best)?;
    let posterior = Posterior::of(&problem, &starts.best, &cov);
    let report = calibration_report(&problem, frf, &frequency, starts, posterior, started)?;
    calibrated_twin(twin, report)
}

/// The nominal structure of the twin's physics FMU.
fn nominal_structure(twin: &Twin) -> Result<Structure, CalibrateError> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    physics_structure(&component.fmu_path)
}

/// The parameters calibrated: those asked for, or all of the structure's; each must be one of
/// the structure's.
fn parameter_names(structure: &Structure, setup: &FrfSetup) -> Result<Vec<String>, CalibrateError> {
    let names: Vec<String> = if setup.parameters.is_empty() {
        structure.parameter_names()
    } else {
        setup.parameters.clone()
    };
    for name in &names {
        if structure.get(name).is_none() {
            return Err(CalibrateError::Setup(format!(
                "'{name}' is not a parameter of the twin's {}-storey structure (m<i>, c<i>, k<i>): \
                 an FRF calibrates the linear structure only",
                structure.storeys()
            )));
        }
    }
    Ok(names)
}

/// Refuses a band that is not an interval of non-negative frequencies.
fn check_band(band: Option<(f64, f64)>) -> Result<(), CalibrateError> {
    if let Some((lo, hi)) = band {
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo) {
            return Err(CalibrateError::Setup(format!(
                "the band {lo}–{hi} Hz is not an interval of non-negative frequencies"
            )));
        }
    }
    Ok(())
}

/// Each parameter's prior: the priors file's, else the twin's own priors', else the nominal
/// structure's default.
fn parameter_priors(
    twin: &Twin,
    setup: &FrfSetup,
    structure: &Structure,
    nominal: &Structure,
    names: &[String],
) -> Result<Vec<Prior>, CalibrateError> {
    let twin_priors = match &twin.priors {
        Some(text) => Some(
            priors_from_json(text, &format!("{} (its priors)", twin.describe()))
                .map_err(CalibrateError::Setup)?,
        ),
        None => None,
    };
    if let Some(spec) = &setup.prior_spec {
        spec.check(nominal, false).map_err(CalibrateError::Setup)?;
    }
    names
        .iter()
        .map(|name| {
            let current = structure.get(name).unwrap_or(0.0);
            let fallback =
                structure_prior(nominal, name).unwrap_or_else(|| default_prior(name, current));
            let from_files = setup
                .prior_spec
                .iter()
                .chain(&twin_priors)
                .find_map(|spec| spec.prior_for(name, fallback))
                .transpose()
                .map_err(CalibrateError::Setup)?;
            Ok(from_files.unwrap_or(fallback))
        })
        .collect::<Result<_, CalibrateError>>()
}

/// An error about the FRF file, naming it.
fn frf_error(frf: &MeasuredFrf, m: String) -> CalibrateError {
    CalibrateError::Setup(format!("{}: {m}", frf.path.display()))
}

/// The lines of `frf` in the band, at least two more than the unknowns.
fn lines_for(
    frf: &MeasuredFrf,
    band: Option<(f64, f64)>,
    unknowns: usize,
) -> Result<Vec<usize>, CalibrateError> {
    let lines = band_lines(frf, band);
    if lines.len() < unknowns + 2 {
        return Err(frf_error(
            frf,
            format!(
                "{} frequency lines in the band, too few for {unknowns} unknowns",
                lines.len()
            ),
        ));
    }
    Ok(lines)
}

/// The file's channels, each checked against the structure.
fn checked_channels(
    frf: &MeasuredFrf,
    structure: &Structure,
) -> Result<Vec<::structure::channel::Channel>, CalibrateError> {
    let channels: Vec<_> = frf.channels.iter().map(|c| c.channel).collect();
    for c in &channels {
        c.check(&c.name(), structure)
            .map_err(|e| frf_error(frf, e.to_string()))?;
    }
    Ok(channels)
}

impl Block {
    /// A channel's data on `lines`, its lines weighted by their magnitude over the median.
    fn of(c: &FrfChannel, lines: &[usize]) -> Block {
        let all_db = c.values.magnitude_db();
        let magnitude_db: Vec<f64> = lines.iter().map(|&k| all_db[k]).collect();
        let phase = c
            .values
            .phase()
            .map(|p| lines.iter().map(|&k| p[k]).collect::<Vec<f64>>());
        let linear: Vec<f64> = magnitude_db.iter().map(|m| 10f64.powf(m / 20.0)).collect();
        let mut sorted = linear.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2].max(f64::MIN_POSITIVE);
        let sqrt_weight = linear
            .iter()
            .map(|m| (m / median).clamp(1.0, RESONANCE_WEIGHT_CAP).sqrt())
            .collect();
        Block {
            magnitude_db,
            phase,
            sqrt_weight,
        }
    }
}

/// The starts' outcome: the best fit, and each start's objective (None where it failed).
struct Starts {
    best: Fit,
    outcomes: Vec<Option<f64>>,
}

/// The fits from every start (the prior mean, then draws from the prior); the best one wins.
fn best_of_starts(
    problem: &mut Problem,
    unknowns: usize,
    setup: &FrfSetup,
    frf: &MeasuredFrf,
) -> Result<Starts, CalibrateError> {
    let mut rng = StdRng::seed_from_u64(setup.seed);
    let mut best: Option<Fit> = None;
    let mut outcomes = Vec::new();
    for i in 0..setup.starts.max(1) {
        let z0: Vec<f64> = (0..unknowns)
            .map(|_| {
                if i == 0 {
                    0.0
                } else {
                    rng.sample::<f64, _>(StandardNormal)
                }
            })
            .collect();
        problem.sigma = vec![(3.0, 0.3); problem.blocks.len()];
        let fit = run_start(problem, z0);
        outcomes.push(fit.as_ref().map(|f| f.objective));
        if let Some(fit) = fit {
            if best.as_ref().is_none_or(|b| fit.objective < b.objective) {
                best = Some(fit);
            }
        }
    }
    let best = best.ok_or_else(|| {
        CalibrateError::Failed(format!(
            "{} starts on {}",
            outcomes.len(),
            frf.path.display()
        ))
    })?;
    Ok(Starts { best, outcomes })
}

/// The Laplace posterior's covariance of the standardised unknowns at the MAP: the inverse of
/// the Gauss–Newton Hessian, the blocks' sds held at the MAP's.
fn posterior_covariance(problem: &mut Problem, best: &Fit) -> Result<DMatrix<f64>, CalibrateError> {
    problem.sigma = best.sigma.clone();
    let r = lm::LeastSquares::residuals(problem, &best.z)
        .ok_or_else(|| CalibrateError::Failed("the MAP's FRF cannot be evaluated".into()))?;
    let jac = lm::LeastSquares::jacobian(problem, &best.z, &r)
        .ok_or_else(|| CalibrateError::Failed("no Jacobian at the MAP".into()))?;
    (jac.transpose() * &jac).try_inverse().ok_or_else(|| {
        CalibrateError::Failed("the posterior Hessian at the optimum is singular".into())
    })
}

/// The posterior in the parameters' own units: each one's value and sd, their correlations,
/// the gain offset, and the covariance stored in the twin.
struct Posterior {
    parameters: Vec<ParameterEstimate>,
    correlation: Vec<Vec<f64>>,
    gain_offset_db: Option<Estimate>,
    covariance: ParameterCovariance,
}

impl Posterior {
    /// The posterior at the MAP `best` from the standardised unknowns' covariance `cov`.
    fn of(problem: &Problem, best: &Fit, cov: &DMatrix<f64>) -> Posterior {
        let (names, priors) = (problem.names, problem.priors);
        let p = names.len();
        let values = problem.values(&best.z);
        let parameters: Vec<ParameterEstimate> = (0..p)
            .map(|j| {
                let prior = priors[j];
                let sd_coordinate = prior.sd() * cov[(j, j)].max(0.0).sqrt();
                let sd = match prior.space {
                    Space::Linear => sd_coordinate,
                    Space::Log => values[j] * sd_coordinate,
                };
                ParameterEstimate {
                    name: names[j].clone(),
                    value: values[j],
                    prior,
                    sd_coordinate,
                    sd,
                }
            })
            .collect();
        let correlation: Vec<Vec<f64>> = (0..p)
            .map(|a| {
                (0..p)
                    .map(|b| cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt())
                    .collect()
            })
            .collect();
        let gain_offset_db = problem.gain.then(|| Estimate {
            value: problem.gain_db(&best.z),
            sd: GAIN_PRIOR_SD_DB * cov[(p, p)].max(0.0).sqrt(),
        });
        let covariance = ParameterCovariance {
            names: names.to_vec(),
            matrix: (0..p)
                .map(|a| {
                    (0..p)
                        .map(|b| {
                            let r = if a == b {
                                1.0
                            } else {
                                0.5 * (correlation[a][b] + correlation[b][a])
                            };
                            let c = r * parameters[a].sd * parameters[b].sd;
                            if c.is_finite() {
                                c
                            } else {
                                0.0
                            }
                        })
                        .collect()
                })
                .collect(),
        };
        Posterior {
            parameters,
            correlation,
            gain_offset_db,
            covariance,
        }
    }
}

/// The calibration's report: the posterior, the fit's errors and sds per channel, the
/// calibrated structure's modes beside the measured peaks, and the starts.
fn calibration_report(
    problem: &Problem,
    frf: &MeasuredFrf,
    frequency: &[f64],
    starts: Starts,
    posterior: Posterior,
    started: Instant,
) -> Result<(FrfCalibration, ParameterCovariance), CalibrateError> {
    let Starts { best, outcomes } = starts;
    let Posterior {
        parameters,
        correlation,
        gain_offset_db,
        covariance,
    } = posterior;
    let calibrated = problem
        .structure_at(&best.z)
        .ok_or_else(|| CalibrateError::Failed("the MAP is not a valid structure".into()))?;
    let (errors, _) = problem
        .errors(&best.z, &[])
        .ok_or_else(|| CalibrateError::Failed("the MAP's FRF cannot be evaluated".into()))?;
    let rms_error_db = errors
        .iter()
        .map(|(mag, _)| (mag.iter().map(|e| e * e).sum::<f64>() / mag.len() as f64).sqrt())
        .collect();
    let magnitudes: Vec<Vec<f64>> = problem
        .blocks
        .iter()
        .map(|b| b.magnitude_db.clone())
        .collect();
    let calibration = FrfCalibration {
        record: frf.path.display().to_string(),
        correlation,
        gain_offset_db,
        channels: frf.channel_names(),
        band_hz: (frequency[0], frequency[frequency.len() - 1]),
        lines: frequency.len(),
        magnitude_sd_db: best.sigma.iter().map(|s| s.0).collect(),
        phase_sd_rad: problem
            .blocks
            .iter()
            .zip(&best.sigma)
            .map(|(b, s)| b.phase.as_ref().map(|_| s.1))
            .collect(),
        rms_error_db,
        twin_modes: twin_modes(&calibrated, Some(&covariance)),
        measured_peaks: measured_peaks(frequency, &magnitudes),
        neg_log_posterior: best.objective,
        starts: outcomes,
        seconds: started.elapsed().as_secs_f64(),
        parameters,
    };
    Ok((calibration, covariance))
}

/// The calibrated twin: the MAP's values in its physics component and the posterior covariance
/// stored, its noise variances, validation and records left unset.
fn calibrated_twin(
    twin: &Twin,
    (calibration, covariance): (FrfCalibration, ParameterCovariance),
) -> Result<(Twin, FrfCalibration), CalibrateError> {
    let mut out = twin.duplicate();
    let physics = out
        .component_mut(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup("no physics component".into()))?;
    for p in &calibration.parameters {
        physics
            .parameters
            .insert(p.name.clone(), ParameterValue::Real(p.value));
    }
    out.noise_variance = None;
    out.parameter_covariance = Some(covariance);
    out.validation_nmse = None;
    out.records = Vec::new();
    Ok((out, calibration))
}
