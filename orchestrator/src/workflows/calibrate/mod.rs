//! MAP calibration of FMU parameters and per-floor noise variances (eqs. (2)–(3) of the reference
//! paper), through the FMI interface, with a Laplace approximation of the posterior.
//!
//! The negative log posterior, up to a constant, with `s_f = log σ²_f` and `z` the calibrated
//! parameters standardised by their priors (`u = μ + σ_prior·z`, `u` the value or its log):
//!
//! `J(z, s) = Σ_f [ N s_f / 2 + SSE_f(z) e^{−s_f} / 2 + (s_f − μ_s,f)² / (2 v_s) ] + ‖z‖² / 2`
//!
//! Optimiser: for fixed noise variances `J` is a least-squares problem in `z` (weighted
//! residuals plus the prior as residuals), solved by Levenberg–Marquardt (`levenberg-marquardt`
//! crate) with a forward-difference Jacobian (one extra simulation per parameter); the noise
//! variances then have a 1-D Newton update each, and the two alternate until both settle.
//! Multi-start: the prior mean (or [`CalibrationSetup::initial`]) plus starts drawn from the
//! prior widened ×3 (seeded), run in parallel, one FMU instance per thread; the best posterior
//! wins. The damping's prior mean
//! (c ≈ 0.01 N s/m) is far from a structure's real damping, and from there the optimiser can
//! stop with the damping stuck near zero; the widened starts reach past it.
//!
//! Uncertainty: the Hessian of `J` at the optimum (Gauss–Newton for the model part, from a
//! central-difference Jacobian; exact for the noise part and the cross terms), inverted.

pub mod frf;
pub mod ladder;
pub mod lm;
pub mod prior;
pub mod validated;

mod posterior;
mod problem;
mod starts;
mod target;

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use ::structure::channel::Channel;
use ::structure::Structure;

use crate::cosim::import::{Causality, Fmu, ScalarType};
use crate::twin::data::Measurement;
use crate::twin::noise::NoiseVariances;
use crate::twin::simulator::{channel_sensitivities, Simulator};
use crate::twin::{Component, ParameterValue, Twin, TwinError, PHYSICS};
use posterior::{laplace, record_fits, used_samples, Posterior};
pub use prior::{
    default_prior, priors_from_json, read_priors, structure_prior, Prior, PriorSpec, Space,
};
pub use problem::SIMULATIONS_PER_START;
use starts::{optimal_log_noise, starts};
pub use starts::{COARSE_GAIN, FINE_GAIN, RACE_MARGIN, SAME_OPTIMUM};
use target::{simulators, ChannelTarget, RecordTarget, Target};
pub use validated::{calibrate_validated, CalibrateRunError, Validated};

/// The default set of calibrated parameters.
pub const DEFAULT_PARAMETERS: [&str; 9] = ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"];

#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error("calibrate: {0}")]
    Setup(String),
    #[error("calibrate: no start converged to a finite posterior ({0})")]
    Failed(String),
}

#[derive(Debug, Clone)]
pub struct CalibrationSetup {
    pub parameters: Vec<String>,
    /// Overrides of the default priors, by parameter name (first).
    pub priors: BTreeMap<String, Prior>,
    /// A priors file (`--priors P.json`), over the twin's own (`twin init --priors`), over the
    /// structure's defaults ([`structure_prior`]).
    pub prior_spec: Option<PriorSpec>,
    /// Seconds at the start of the record left out of the likelihood.
    pub transient: f64,
    pub starts: usize,
    pub seed: u64,
    /// Prior on log σ²_f: centred on this fraction of floor f's measured variance…
    pub noise_fraction: f64,
    /// …with this variance (of the log).
    pub noise_log_variance: f64,
    pub threads: usize,
    /// Samples the likelihood uses (after the transient): all when `None`; otherwise
    /// `mask[k]` says whether sample k counts (the rest is held out, e.g. for validation).
    pub mask: Option<Vec<bool>>,
    /// Simulations one start may use before it is abandoned.
    pub simulations_per_start: usize,
    /// Where the first start begins, by parameter name (the prior mean for a name not given):
    /// a refinement from a model already fitted starts there.
    pub initial: BTreeMap<String, f64>,
    /// Further starts by value (a parameter not named at its prior mean), after the first and
    /// before the random draws, within `starts` in all.
    pub starts_at: Vec<BTreeMap<String, f64>>,
    /// Long records fitted along a ladder of their heads ([`ladder`]; default): the starts
    /// screened on the first [`ladder::STRETCH`] samples, the best refined up to every sample.
    /// Off, every start runs on every sample.
    pub climb: bool,
}

impl Default for CalibrationSetup {
    fn default() -> Self {
        CalibrationSetup {
            parameters: DEFAULT_PARAMETERS.iter().map(|s| s.to_string()).collect(),
            priors: BTreeMap::new(),
            prior_spec: None,
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            starts: 12,
            seed: 1,
            noise_fraction: 0.02,
            noise_log_variance: 1.0,
            threads: crate::parallel::cores(),
            mask: None,
            simulations_per_start: SIMULATIONS_PER_START,
            initial: BTreeMap::new(),
            starts_at: Vec::new(),
            climb: true,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct ParameterEstimate {
    pub name: String,
    pub value: f64,
    pub prior: Prior,
    /// Posterior sd in the prior's coordinate (of the value, or of its log for log-space priors).
    pub sd_coordinate: f64,
    /// Posterior sd of the value itself (delta method for log-space priors).
    pub sd: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct StartOutcome {
    pub start: usize,
    pub neg_log_posterior: f64,
    pub evaluations: usize,
    /// Left after the screening ([`SCREEN_EVALUATIONS`]): its posterior there was not among
    /// the best [`SCREEN_KEEP`] starts', so it was not run to the end.
    pub screened_out: bool,
}

/// Evaluations (a sensitivity run counts as the p finite-difference runs it replaces) every
/// start gets before the starts are compared: a few Levenberg–Marquardt iterations, by then a
/// start in a poor basin is far behind (measured on 3–20 storeys: the starts that end best are
/// among the best three after the screen). Only the best [`SCREEN_KEEP`] run on to their end.
pub const SCREEN_EVALUATIONS_PER_PARAMETER: usize = 6;

/// Starts run to the end after the screen.
pub const SCREEN_KEEP: usize = 3;

#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    pub parameters: Vec<ParameterEstimate>,
    /// Correlation matrix of the calibrated parameters (in their prior coordinates).
    pub correlation: Vec<Vec<f64>>,
    /// The first record's noise variance per measured channel, in [`Calibration::channels`]'
    /// order (on the paper's rig floors 1 to 3), in the channel's SI unit squared.
    pub noise_variance: Vec<f64>,
    /// Posterior sd of log σ² per channel.
    pub noise_log_sd: Vec<f64>,
    /// The first record's measured channels (`acc1`, `vel2`, …).
    pub channels: Vec<String>,
    pub neg_log_posterior: f64,
    /// Laplace approximation of the log evidence `log p(D)` of the model with these calibrated
    /// parameters, up to a constant that depends only on the record and the noise prior (so
    /// differences between calibrations of one record with different parameter sets are
    /// log Bayes factors): `−J(MAP) + ½ log det Σ`, with `Σ` the posterior covariance of the
    /// standardised parameters and the log noise variances.
    pub log_evidence: f64,
    /// Samples the likelihood used.
    pub samples_used: usize,
    /// NMSE (%) per channel on the first record, after the transient.
    pub nmse: Vec<f64>,
    /// Every record's noise variances and NMSE per channel, in the order given (one for a
    /// single-record calibration, the same as the fields above).
    pub records: Vec<RecordCalibration>,
    pub starts: Vec<StartOutcome>,
    /// The heads (samples of every record) the starts were screened on and the best refined
    /// on before every sample, shortest first ([`ladder`]); empty when they ran on every sample.
    pub heads: Vec<usize>,
    pub simulations: usize,
    pub seconds: f64,
    /// The storeys of the calibrated twin's structure.
    #[serde(skip)]
    pub storeys: usize,
}

impl Calibration {
    /// The noise variances the calibrated twin keeps, per measured channel: each channel's
    /// from the first run that measured it (the paper's rig: its one record's acc1..acc3; runs
    /// of a roving sensor: each floor's from its own run).
    pub fn noise_variances(&self) -> NoiseVariances {
        NoiseVariances::new(self.records.iter().flat_map(|r| {
            r.channels
                .iter()
                .zip(&r.noise_variance)
                .filter_map(|(name, v)| Some((Channel::parse(name)?, *v)))
        }))
    }

    /// The Laplace posterior covariance of the calibrated parameters in their own units (for
    /// log-space priors by the delta method, as `sd`): `corr[a][b] · sd[a] · sd[b]`.
    pub fn covariance(&self) -> crate::twin::ParameterCovariance {
        let p = &self.parameters;
        let matrix = (0..p.len())
            .map(|a| {
                (0..p.len())
                    .map(|b| {
                        // Symmetric to the bit: the inverse Hessian's two halves differ by rounding.
                        let r = if a == b {
                            1.0
                        } else {
                            0.5 * (self.correlation[a][b] + self.correlation[b][a])
                        };
                        let c = r * (p[a].sd * p[b].sd);
                        if c.is_finite() {
                            c
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        crate::twin::ParameterCovariance {
            names: p.iter().map(|e| e.name.clone()).collect(),
            matrix,
        }
    }
}

/// One record of a multi-record calibration, with the samples its likelihood uses (`mask`,
/// after the transient; all when None).
#[derive(Clone, Copy)]
pub struct RecordInput<'a> {
    pub data: &'a Measurement,
    pub mask: Option<&'a [bool]>,
}

/// What a calibration found on one of its records: that record's own noise variances (which
/// also hold what the model still misses there) and the fit's NMSE on it, per measured channel.
#[derive(Debug, Clone, Serialize)]
pub struct RecordCalibration {
    pub record: String,
    /// Its measured channels, in the record's order (`acc1`, `vel2`, …).
    pub channels: Vec<String>,
    /// Per channel, in its SI unit squared.
    pub noise_variance: Vec<f64>,
    /// Posterior sd of log σ² per channel.
    pub noise_log_sd: Vec<f64>,
    pub samples_used: usize,
    /// NMSE (%) per channel on the record, after the transient.
    pub nmse: Vec<f64>,
}

/// Calibrate the physics component of `twin` on `data` (the one record of
/// [`calibrate_records`], its mask `setup.mask`).
pub fn calibrate(
    twin: &Twin,
    data: &Measurement,
    setup: &CalibrationSetup,
) -> Result<Calibration, CalibrateError> {
    calibrate_records(
        twin,
        &[RecordInput {
            data,
            mask: setup.mask.as_deref(),
        }],
        setup,
    )
}

/// Calibrate the physics component of `twin` on several records at once: one parameter vector,
/// each record with its own per-floor noise variances (their priors centred on that record's
/// measured variance), the Laplace posterior over all of it. `setup.mask` is not used (each
/// record brings its own). The calibration's `noise_variance`, `noise_log_sd`, `samples_used`
/// and `nmse` are the first record's; `records` has every record's.
pub fn calibrate_records(
    twin: &Twin,
    inputs: &[RecordInput],
    setup: &CalibrationSetup,
) -> Result<Calibration, CalibrateError> {
    let started = Instant::now();
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let fmu = Fmu::open(&component.fmu_path).map_err(TwinError::from)?;
    if inputs.is_empty() {
        return Err(CalibrateError::Setup("no record to calibrate on".into()));
    }
    let structure = physics_structure(&component.fmu_path)?;
    let twin_priors = twin_priors(twin)?;
    check_setup(setup, &structure)?;
    // Every record's channels checked against the structure before any work.
    for input in inputs {
        check_record(input.data, &structure, &fmu)?;
    }
    let (records, firsts) = record_targets(&fmu, inputs, setup)?;
    let (vrs, priors) = parameter_priors(&fmu, component, &structure, setup, twin_priors.as_ref())?;
    let mut target = Target::new(&fmu, component, setup, records, vrs, priors);

    // The starts, screened or raced (on the records' heads when they are long), and the best
    // on to its end on every sample.
    let starts = starts(setup, &target.priors);
    let threads = setup.threads.clamp(1, starts.len());
    target.columns_threads = (setup.threads / threads).max(1);
    let ladder::Climb {
        mut outcomes,
        simulations,
        best,
        heads,
    } = ladder::climb(&fmu, component, setup, inputs, &target, &starts, threads)?;
    outcomes.sort_by_key(|o| o.start);
    let best = best.ok_or_else(|| CalibrateError::Failed(format!("{} starts", starts.len())))?;

    // The Laplace posterior at the best start's optimum, and every record's fit there.
    // The starts are done: the Laplace approximation's differences have every thread.
    target.columns_threads = setup.threads.max(1);
    let mut sims = simulators(&target, "laplace")?;
    let (cov, laplace_runs) = laplace(&mut sims, &target, &best.z, &best.s).ok_or_else(|| {
        CalibrateError::Failed("the posterior Hessian at the optimum is singular".into())
    })?;
    let values = target.values(&best.z);
    let posterior = Posterior::at(&target, setup, &values, &cov, best.objective);
    let fitted = record_fits(&mut sims, &target, &firsts, &values, &best.s, &cov)?;
    let own = fitted[0].clone();
    Ok(Calibration {
        parameters: posterior.parameters,
        correlation: posterior.correlation,
        noise_variance: own.noise_variance,
        noise_log_sd: own.noise_log_sd,
        channels: own.channels,
        neg_log_posterior: best.objective,
        log_evidence: posterior.log_evidence,
        samples_used: own.samples_used,
        nmse: own.nmse,
        records: fitted,
        starts: outcomes,
        heads,
        simulations: simulations + laplace_runs + target.records.len(),
        seconds: started.elapsed().as_secs_f64(),
        storeys: structure.storeys(),
    })
}

/// The priors the twin carries (`twin init --priors`), if any.
fn twin_priors(twin: &Twin) -> Result<Option<PriorSpec>, CalibrateError> {
    Ok(match &twin.priors {
        Some(text) => Some(
            priors_from_json(text, &format!("{} (its priors)", twin.describe()))
                .map_err(CalibrateError::Setup)?,
        ),
        None => None,
    })
}

/// Whether `setup` can calibrate a twin of `structure`: its priors file fits the structure, and
/// it names a parameter.
fn check_setup(setup: &CalibrationSetup, structure: &Structure) -> Result<(), CalibrateError> {
    if let Some(spec) = &setup.prior_spec {
        spec.check(structure, false)
            .map_err(CalibrateError::Setup)?;
    }
    if setup.parameters.is_empty() {
        return Err(CalibrateError::Setup("no parameter to calibrate".into()));
    }
    Ok(())
}

/// Every record as the likelihood reads it: the samples it uses, and each measured channel with
/// the FMU output predicting it, its sensitivities and its noise prior. Also each record's first
/// sample after the transient.
fn record_targets<'a>(
    fmu: &Fmu,
    inputs: &[RecordInput<'a>],
    setup: &CalibrationSetup,
) -> Result<(Vec<RecordTarget<'a>>, Vec<usize>), CalibrateError> {
    let mut records = Vec::with_capacity(inputs.len());
    let mut firsts = Vec::with_capacity(inputs.len());
    for input in inputs {
        let (first, used) = used_samples(input.data, input.mask, setup.transient)?;
        let channels = input
            .data
            .responses
            .iter()
            .map(|signal| {
                let name = signal.channel.name();
                let y: Vec<f64> = used.iter().map(|&k| signal.values[k]).collect();
                Ok(ChannelTarget {
                    output: fmu.value_reference(&name).map_err(TwinError::from)?,
                    sensitivities: channel_sensitivities(fmu, &name, &setup.parameters),
                    noise_mean: (setup.noise_fraction * crate::evaluation::stats::variance(&y))
                        .ln(),
                    values: &signal.values,
                    name,
                })
            })
            .collect::<Result<Vec<_>, CalibrateError>>()?;
        firsts.push(first);
        records.push(RecordTarget {
            data: input.data,
            input: input.data.excitation.channel.name(),
            used,
            channels,
        });
    }
    Ok((records, firsts))
}

/// Each calibrated parameter's value reference and prior: the setup's own, else the setup's
/// priors file's or the twin's (`twin_priors`), else the structure's default or one around the
/// parameter's current value. Err names a parameter the FMU has not as a real parameter.
fn parameter_priors(
    fmu: &Fmu,
    component: &Component,
    structure: &Structure,
    setup: &CalibrationSetup,
    twin_priors: Option<&PriorSpec>,
) -> Result<(Vec<u32>, Vec<Prior>), CalibrateError> {
    let mut vrs = Vec::new();
    let mut priors = Vec::new();
    for name in &setup.parameters {
        let var = fmu.model_description.variable(name).ok_or_else(|| {
            CalibrateError::Setup(format!("{} has no parameter '{name}'", component.fmu_name))
        })?;
        if var.scalar_type != ScalarType::Real
            || var.causality != crate::cosim::import::Causality::Parameter
        {
            return Err(CalibrateError::Setup(format!(
                "'{name}' is not a real parameter"
            )));
        }
        let current = match component.parameters.get(name) {
            Some(ParameterValue::Real(x)) => *x,
            _ => var
                .start
                .as_deref()
                .and_then(|s| s.parse().ok())
                .unwrap_or(0.0),
        };
        let fallback =
            structure_prior(structure, name).unwrap_or_else(|| default_prior(name, current));
        let from_files = setup
            .prior_spec
            .iter()
            .chain(twin_priors)
            .find_map(|spec| spec.prior_for(name, fallback))
            .transpose()
            .map_err(CalibrateError::Setup)?;
        let prior = setup
            .priors
            .get(name)
            .copied()
            .or(from_files)
            .unwrap_or(fallback);
        vrs.push(var.value_reference);
        priors.push(prior);
    }
    Ok((vrs, priors))
}

/// The structure the twin's physics FMU was made for: its `resources/structure.json`
/// (`twin init --storeys/--excitation/--nominal`), or the paper's rig when it has none.
pub fn physics_structure(fmu_path: &std::path::Path) -> Result<Structure, CalibrateError> {
    Ok(crate::twin::structure::structure_of_fmu(fmu_path)?
        .map(|r| r.structure)
        .unwrap_or_default())
}

/// Whether calibration can use `data` on a twin of `structure`: its excitation is the one the
/// structure has, every response is of a floor it has and an output of the FMU. Err names the
/// record and the column.
fn check_record(
    data: &Measurement,
    structure: &Structure,
    fmu: &Fmu,
) -> Result<(), CalibrateError> {
    let bad =
        |message: String| CalibrateError::Setup(format!("{}: {message}", data.path.display()));
    for signal in data.channels() {
        let name = signal.channel.name();
        signal
            .channel
            .check(&name, structure)
            .map_err(|e| bad(e.to_string()))?;
        let output = fmu.model_description.variable(&name);
        let ok = match signal.channel {
            Channel::Excitation(_) => output.is_some_and(|v| v.causality == Causality::Input),
            _ => output.is_some_and(|v| v.causality == Causality::Output),
        };
        if !ok {
            return Err(bad(format!(
                "column '{name}': the twin's physics FMU has no such {}",
                if matches!(signal.channel, Channel::Excitation(_)) {
                    "input"
                } else {
                    "output"
                }
            )));
        }
    }
    Ok(())
}

/// The parameters calibrated by default: every floor's mass and every storey's damping and
/// stiffness of the twin's structure (`m1..mN, c1..cN, k1..kN`; on the paper's rig
/// [`DEFAULT_PARAMETERS`]).
pub fn default_parameters(twin: &Twin) -> Result<Vec<String>, CalibrateError> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    Ok(physics_structure(&component.fmu_path)?.parameter_names())
}

/// A copy of `twin` with the calibrated values, noise variances and posterior covariance (a
/// validation NMSE the input twin had no longer applies).
pub fn calibrated_twin(twin: &Twin, calibration: &Calibration) -> Result<Twin, CalibrateError> {
    let mut out = twin.duplicate();
    let physics = out
        .component_mut(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup("no physics component".into()))?;
    for p in &calibration.parameters {
        physics
            .parameters
            .insert(p.name.clone(), ParameterValue::Real(p.value));
    }
    out.noise_variance = Some(calibration.noise_variances());
    out.parameter_covariance = Some(calibration.covariance());
    out.validation_nmse = None;
    // The records the input twin was fitted on are not this one's (the caller adds them).
    out.records = Vec::new();
    Ok(out)
}

/// The log evidence of the twin's physics as it is (no parameter calibrated), on the same
/// footing as [`Calibration::log_evidence`] for the same record, mask and noise prior: the noise
/// variances at their MAP and integrated out by Laplace. Differences with a calibration's
/// `log_evidence` are log Bayes factors of "re-estimate these parameters" against "keep them".
pub fn fixed_log_evidence(
    twin: &Twin,
    data: &Measurement,
    setup: &CalibrationSetup,
) -> Result<f64, CalibrateError> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let fmu = Fmu::open(&component.fmu_path).map_err(TwinError::from)?;
    let (_, used) = used_samples(data, setup.mask.as_deref(), setup.transient)?;
    let mut sim = Simulator::for_record(&fmu, component.parameters.clone(), data, "evidence")?;
    // Every measured channel, the FMU's output of the same name.
    let outputs = data
        .responses
        .iter()
        .map(|s| fmu.value_reference(&s.channel.name()))
        .collect::<Result<Vec<u32>, _>>()
        .map_err(TwinError::from)?;
    let mut buf: Vec<Vec<f64>> = vec![Vec::new(); outputs.len()];
    sim.record(&[], &[], &outputs, &mut buf)?;
    let n = used.len() as f64;
    let mut log_evidence = 0.0;
    for (signal, predicted) in data.responses.iter().zip(&buf) {
        let y: Vec<f64> = used.iter().map(|&k| signal.values[k]).collect();
        let var = crate::evaluation::stats::variance(&y);
        let noise_mean = (setup.noise_fraction * var).ln();
        let sse: f64 = used
            .iter()
            .map(|&k| (signal.values[k] - predicted[k]).powi(2))
            .sum();
        let v = setup.noise_log_variance;
        let s = optimal_log_noise(n, sse, noise_mean, v, noise_mean);
        let j = n * s / 2.0 + sse * (-s).exp() / 2.0 + (s - noise_mean).powi(2) / (2.0 * v);
        let curvature = sse * (-s).exp() / 2.0 + 1.0 / v;
        log_evidence += -j - 0.5 * curvature.ln();
    }
    Ok(log_evidence)
}
