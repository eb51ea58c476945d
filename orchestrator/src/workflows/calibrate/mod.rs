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

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::{DMatrix, DVector};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::StandardNormal;
use serde::Serialize;

use ::structure::channel::Channel;
use ::structure::Structure;

use crate::cosim::import::{Causality, Fmu, ScalarType};
use crate::twin::data::Measurement;
use crate::twin::linear::LinearFit;
use crate::twin::noise::NoiseVariances;
use crate::twin::simulator::{channel_sensitivities, sensitivity_switch, Simulator};
use crate::twin::{Component, ParameterValue, Twin, TwinError, PHYSICS};
pub use prior::{
    default_prior, priors_from_json, read_priors, structure_prior, Prior, PriorSpec, Space,
};
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
            threads: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
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

/// One measured response of one record: its values, the FMU output predicting it and its own
/// noise prior.
struct ChannelTarget<'a> {
    name: String,
    values: &'a [f64],
    /// The FMU's output of the same name (`acc2`, `vel1`, `disp3`).
    output: u32,
    /// `d_{name}_d_{p}` for the calibrated parameters, when the FMU has them all.
    sensitivities: Option<Vec<u32>>,
    /// Prior mean of log σ² for this channel of this record: from its own measured variance.
    noise_mean: f64,
}

/// One record of a calibration: its excitation, its measured channels, the samples the
/// likelihood uses.
struct RecordTarget<'a> {
    data: &'a Measurement,
    /// The FMU input the excitation drives (`force` or `ground_acc`).
    input: String,
    /// Sample indices the likelihood uses.
    used: Vec<usize>,
    channels: Vec<ChannelTarget<'a>>,
}

impl RecordTarget<'_> {
    fn outputs(&self) -> Vec<u32> {
        self.channels.iter().map(|c| c.output).collect()
    }
}

/// What one calibration works on, shared by the threads: one or more records, one parameter
/// vector. The residuals are the records' in turn, each channel-major (record r, channel c is
/// one block with its own noise variance).
struct Target<'a> {
    fmu: &'a Fmu,
    base: BTreeMap<String, ParameterValue>,
    records: Vec<RecordTarget<'a>>,
    vrs: Vec<u32>,
    priors: Vec<Prior>,
    noise_var: f64,
    budget: usize,
    /// The FMU's forward sensitivities of the measured outputs to the calibrated parameters,
    /// when it offers them for all of them.
    sensitivity: Option<Sensitivity>,
    /// The same in process, when the twin is the linear shear model and the calibrated
    /// parameters its `m`, `c`, `k` ([`LinearFit`]).
    linear: Option<LinearFit>,
    /// Threads one start's finite-difference columns may use: the cores the starts leave idle
    /// (a single start on two cores: two).
    columns_threads: usize,
}

/// Where an FMU gives `∂y/∂p` along a run: the Boolean parameter that switches them on (the
/// outputs `d_{channel}_d_{p}` are each channel's). The shear FMU carries them for its linear
/// model (`fmu_shear::sensitivity`); with an effect on they are NaN, and the calibration falls
/// back to finite differences.
struct Sensitivity {
    switch: u32,
    /// Set once a sensitivity run gave non-finite values: finite differences from then on.
    failed: AtomicBool,
}

impl Sensitivity {
    fn find(fmu: &Fmu) -> Option<Self> {
        Some(Sensitivity {
            switch: sensitivity_switch(fmu)?,
            failed: AtomicBool::new(false),
        })
    }
}

impl Target<'_> {
    fn values(&self, z: &[f64]) -> Vec<f64> {
        z.iter()
            .zip(&self.priors)
            .map(|(z, p)| p.value(p.mean + p.sd() * z))
            .collect()
    }
    /// The residual blocks (record, channel) as (first row, rows).
    fn blocks(&self) -> Vec<(usize, usize)> {
        let mut at = 0;
        let mut out = Vec::new();
        for r in &self.records {
            for _ in &r.channels {
                out.push((at, r.used.len()));
                at += r.used.len();
            }
        }
        out
    }
    fn rows(&self) -> usize {
        self.records
            .iter()
            .map(|r| r.channels.len() * r.used.len())
            .sum()
    }
    /// Every block's prior mean of log σ², in block order.
    fn noise_means(&self) -> Vec<f64> {
        self.records
            .iter()
            .flat_map(|r| r.channels.iter().map(|c| c.noise_mean))
            .collect()
    }
    /// Whether every channel of every record has its sensitivities.
    fn sensitive(&self) -> bool {
        self.records
            .iter()
            .all(|r| r.channels.iter().all(|c| c.sensitivities.is_some()))
    }
}

/// One simulator per record (its excitation), for one thread.
fn simulators<'a>(target: &Target<'a>, name: &str) -> Result<Vec<Simulator<'a>>, TwinError> {
    target
        .records
        .iter()
        .map(|r| {
            Simulator::driven(
                target.fmu,
                target.base.clone(),
                &r.input,
                &r.data.excitation.values,
                r.data.time[0],
                r.data.dt,
                name,
            )
        })
        .collect()
}

/// Residuals `y − ŷ` after the transient for parameters `z`, every record in turn, or None if
/// the FMU refused them (out of range, or the simulation diverged).
fn raw_residuals(
    sims: &mut [Simulator],
    target: &Target,
    z: &[f64],
    buf: &mut Vec<Vec<f64>>,
) -> Option<Vec<f64>> {
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut r = Vec::with_capacity(target.rows());
    for (sim, record) in sims.iter_mut().zip(&target.records) {
        buf.resize(record.channels.len(), Vec::new());
        sim.record(&target.vrs, &values, &record.outputs(), buf)
            .ok()?;
        for (c, predicted) in record.channels.iter().zip(buf.iter()) {
            for &k in &record.used {
                r.push(c.values[k] - predicted[k]);
            }
        }
    }
    Some(r)
}

/// The residuals `y − ŷ` for parameters `z` and their Jacobian `∂(y − ŷ)/∂z` (rows as the
/// residuals), from one run per record with the FMU's sensitivities; None when the FMU has none
/// for these parameters, refused them, or gave non-finite ones (an FMU's: then never again for
/// this calibration).
fn sensitivity_jacobian(
    sims: &mut [Simulator],
    target: &Target,
    z: &[f64],
) -> Option<(Vec<f64>, DMatrix<f64>)> {
    let sensitivity = target.sensitivity.as_ref()?;
    if sensitivity.failed.load(Ordering::Relaxed) {
        return None;
    }
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let p = z.len();
    let rows = target.rows();
    let mut r = Vec::with_capacity(rows);
    let mut jac = DMatrix::zeros(rows, p);
    let scale = prior_scales(target, &values);
    let mut row0 = 0;
    let mut through_fmi = false;
    for (sim, record) in sims.iter_mut().zip(&target.records) {
        let q = record.channels.len();
        // The linear shear model in process where the twin is it (the FMU's own maps, a pass
        // over the record), else the FMU's run with its sensitivities through FMI: the
        // predictions, then each channel's derivatives.
        let out = match target
            .linear
            .as_ref()
            .and_then(|fit| linear_outputs(fit, record, &values))
        {
            Some(out) => out,
            None => {
                through_fmi = true;
                let mut outputs = record.outputs();
                for c in &record.channels {
                    outputs.extend(c.sensitivities.as_ref()?);
                }
                let mut out: Vec<Vec<f64>> = vec![Vec::new(); outputs.len()];
                sim.record_switched(&target.vrs, &values, sensitivity.switch, &outputs, &mut out)
                    .ok()?;
                out
            }
        };
        let per = record.used.len();
        for (f, c) in record.channels.iter().enumerate() {
            r.extend(record.used.iter().map(|&k| c.values[k] - out[f][k]));
            for (j, scale) in scale.iter().enumerate() {
                let d = &out[q + f * p + j];
                let mut column = jac.column_mut(j);
                for (i, &k) in record.used.iter().enumerate() {
                    column[row0 + f * per + i] = -d[k] * scale;
                }
            }
        }
        row0 += q * per;
    }
    if jac.iter().any(|d| !d.is_finite()) {
        // An FMU whose sensitivities are not finite (NaN with an effect on) is asked no more;
        // the linear model in process gives non-finite ones only where the parameters blow
        // the run up (a start's wide draw), which says nothing of the other trials: before,
        // one such trial sent every start of a 10-storey calibration to finite differences
        // through FMI (5,235 of its runs, 6.2 s).
        if through_fmi {
            sensitivity.failed.store(true, Ordering::Relaxed);
        }
        return None;
    }
    Some((r, jac))
}

/// What the FMU's sensitivity run records for `record` (each channel's predictions, then its
/// derivatives along the calibrated parameters), from the linear model in process; None when
/// a channel is not an accelerometer or the FMU would refuse `values`.
fn linear_outputs(fit: &LinearFit, record: &RecordTarget, values: &[f64]) -> Option<Vec<Vec<f64>>> {
    let names: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
    let floors = fit.floors(&names)?;
    let (q, p) = (floors.len(), values.len());
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(record.data.len()); q * (p + 1)];
    fit.run(
        values,
        record.data,
        &floors,
        |_, predictions, derivatives| {
            for c in 0..q {
                out[c].push(predictions[c]);
                for j in 0..p {
                    out[q + c * p + j].push(derivatives[c * p + j]);
                }
            }
        },
    )?;
    Some(out)
}

/// The model's normal equations at a point: the residuals `y − ŷ` (every block in turn) and,
/// per block (record, channel), `J_bᵀ J_b` and `J_bᵀ r_b` with `J_b = ∂(y − ŷ)/∂z` of its rows.
struct ModelNormals {
    r: Vec<f64>,
    blocks: Vec<(DMatrix<f64>, DVector<f64>)>,
}

impl ModelNormals {
    fn from_jacobian(r: Vec<f64>, jac: &DMatrix<f64>, blocks: &[(usize, usize)]) -> Self {
        let blocks = blocks
            .iter()
            .map(|&(start, per)| {
                let jf = jac.rows(start, per);
                let rf = DVector::from_column_slice(&r[start..start + per]);
                (jf.transpose() * jf, jf.transpose() * rf)
            })
            .collect();
        ModelNormals { r, blocks }
    }

    /// The normal equations of the weighted residuals and the prior's rows (`[w ∘ r; z]`):
    /// `Σ_b w_b² J_bᵀ J_b + I` and `Σ_b w_b² J_bᵀ r_b + z`, `w_b` block b's weight.
    fn weighted(&self, block_weights: &[f64], z: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
        let p = z.len();
        let mut a = DMatrix::identity(p, p);
        let mut g = DVector::from_column_slice(z);
        for ((jtj, jtr), w) in self.blocks.iter().zip(block_weights) {
            let w2 = w * w;
            a += jtj * w2;
            g += jtr * w2;
        }
        (a, g)
    }
}

/// [`ModelNormals`] at `z`: through the linear model's modes in process where the twin is that
/// model ([`LinearFit::normals`]: a Gram matrix of the modes' responses, no Jacobian formed),
/// else from [`sensitivity_jacobian`]. None where that is.
fn sensitivity_normals(sims: &mut [Simulator], target: &Target, z: &[f64]) -> Option<ModelNormals> {
    if let Some(normals) = target
        .linear
        .as_ref()
        .and_then(|fit| linear_normals(fit, target, z))
    {
        return Some(normals);
    }
    let (r, jac) = sensitivity_jacobian(sims, target, z)?;
    Some(ModelNormals::from_jacobian(r, &jac, &target.blocks()))
}

/// [`ModelNormals`] from the linear model's modes in process (`J = −∂ŷ/∂θ · ∂θ/∂z`); None when
/// a record's channel is not an accelerometer, the FMU would refuse the values, or the modes are
/// not distinct.
fn linear_normals(fit: &LinearFit, target: &Target, z: &[f64]) -> Option<ModelNormals> {
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let scale = prior_scales(target, &values);
    let mut r = Vec::with_capacity(target.rows());
    let mut blocks = Vec::new();
    for record in &target.records {
        let names: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
        let floors = fit.floors(&names)?;
        let measured: Vec<&[f64]> = record.channels.iter().map(|c| c.values).collect();
        let normals = fit.normals(&values, record.data, &floors, &measured, &record.used)?;
        for ((c, predicted), (m, v)) in record
            .channels
            .iter()
            .zip(&normals.predictions)
            .zip(normals.blocks)
        {
            r.extend(record.used.iter().map(|&k| c.values[k] - predicted[k]));
            let jtj =
                DMatrix::from_fn(m.nrows(), m.ncols(), |a, b| scale[a] * m[(a, b)] * scale[b]);
            let jtr = DVector::from_fn(v.len(), |a, _| -scale[a] * v[a]);
            blocks.push((jtj, jtr));
        }
    }
    Some(ModelNormals { r, blocks })
}

/// `∂u_j/∂z_j` at the values `u`: the prior's scale, times the value where the prior is on the
/// log.
fn prior_scales(target: &Target, values: &[f64]) -> Vec<f64> {
    target
        .priors
        .iter()
        .zip(values)
        .map(|(prior, value)| match prior.space {
            Space::Linear => prior.sd(),
            Space::Log => prior.sd() * value,
        })
        .collect()
}

/// The sum of squares of every block (record, floor) of `r`.
fn sse_per_block(r: &[f64], blocks: &[(usize, usize)]) -> Vec<f64> {
    blocks
        .iter()
        .map(|&(a, n)| r[a..a + n].iter().map(|x| x * x).sum())
        .collect()
}

/// The least-squares problem in `z` for fixed noise variances.
struct Problem<'s, 'a> {
    sims: RefCell<&'s mut [Simulator<'a>]>,
    target: &'s Target<'a>,
    /// Each residual's weight `e^{−s/2}`, by the noise variance of its block.
    weights: Vec<f64>,
    buf: RefCell<Vec<Vec<f64>>>,
    /// Simulations used, a Jacobian from sensitivities counted as the p runs it replaces: what
    /// the budget bounds.
    evaluations: RefCell<usize>,
    /// FMU runs made.
    runs: RefCell<usize>,
    /// The model's normal equations from the last trial's sensitivities, and where they were
    /// taken.
    at_hand: RefCell<Option<(Vec<f64>, ModelNormals)>>,
    /// The last trial and its residuals `y − ŷ`: where the fit ended, the noise's next estimate
    /// needs no run of its own.
    last: RefCell<Option<(Vec<f64>, Vec<f64>)>>,
    /// Simulations this least-squares solve may use.
    budget: usize,
}

impl Problem<'_, '_> {
    fn weighted(&self, z: &[f64]) -> Option<DVector<f64>> {
        *self.evaluations.borrow_mut() += 1;
        *self.runs.borrow_mut() += self.target.records.len();
        let mut sims = self.sims.borrow_mut();
        // With sensitivities, every trial runs with them: an accepted trial's Jacobian is then
        // at hand, for less than a run of its own.
        let r = match sensitivity_normals(&mut sims, self.target, z) {
            Some(model) => {
                let r = model.r.clone();
                *self.at_hand.borrow_mut() = Some((z.to_vec(), model));
                r
            }
            None => raw_residuals(&mut sims, self.target, z, &mut self.buf.borrow_mut())?,
        };
        let weighted = with_prior_rows(&r, &self.weights, z);
        *self.last.borrow_mut() = Some((z.to_vec(), r));
        Some(weighted)
    }

    /// The forward-difference Jacobian at `z` (`base` its residuals), one run per parameter:
    /// through [`Problem::weighted`] while the FMU's sensitivities are on, else as plain runs
    /// by [`over_columns`] (over the cores the starts leave idle, when worth it). The same
    /// columns either way.
    fn forward_differences(&self, z: &[f64], base: &DVector<f64>) -> Option<DMatrix<f64>> {
        let plain = self
            .target
            .sensitivity
            .as_ref()
            .is_none_or(|s| s.failed.load(Ordering::Relaxed));
        let mut jac = DMatrix::zeros(base.len(), z.len());
        if !plain {
            for j in 0..z.len() {
                let h = 1e-6 * z[j].abs().max(1.0);
                let mut shifted = z.to_vec();
                shifted[j] += h;
                jac.set_column(j, &((self.weighted(&shifted)? - base) / h));
            }
            return Some(jac);
        }
        *self.evaluations.borrow_mut() += z.len();
        *self.runs.borrow_mut() += z.len() * self.target.records.len();
        let (target, weights) = (self.target, &self.weights);
        let columns = over_columns(
            &mut self.sims.borrow_mut(),
            &mut self.buf.borrow_mut(),
            target,
            z.len(),
            |sims, buf, j| {
                let h = 1e-6 * z[j].abs().max(1.0);
                let mut shifted = z.to_vec();
                shifted[j] += h;
                let r = raw_residuals(sims, target, &shifted, buf)?;
                Some((with_prior_rows(&r, weights, &shifted) - base) / h)
            },
        )?;
        for (j, c) in columns.iter().enumerate() {
            jac.set_column(j, c);
        }
        Some(jac)
    }
}

/// Below this much work left after the first column (its time × the columns left), the rest
/// run on this thread: another thread's simulators (an FMU instance per record) and its start
/// cost a few milliseconds, more than a three-storey record's few columns take.
const COLUMNS_WORTH_THREADS: Duration = Duration::from_millis(40);

/// `column(sims, buf, j)` for every `j` in `0..count`, in order. Column 0 on this thread,
/// timed; when the rest is worth it ([`COLUMNS_WORTH_THREADS`]), column j on thread
/// `(j − 1) mod t`, `t` the target's [`Target::columns_threads`], thread 0 this one with `sims`,
/// each other with simulators of its own; else the rest here too. The same columns either way.
/// None when any column is.
fn over_columns<'a, T: Send>(
    sims: &mut [Simulator<'a>],
    buf: &mut Vec<Vec<f64>>,
    target: &Target<'a>,
    count: usize,
    column: impl Fn(&mut [Simulator<'a>], &mut Vec<Vec<f64>>, usize) -> Option<T> + Sync,
) -> Option<Vec<T>> {
    if count == 0 {
        return Some(Vec::new());
    }
    let timed = Instant::now();
    let first = column(sims, buf, 0)?;
    let rest = timed.elapsed() * (count - 1) as u32;
    let threads = target.columns_threads.min(count - 1).max(1);
    if threads == 1 || rest < COLUMNS_WORTH_THREADS {
        return std::iter::once(Some(first))
            .chain((1..count).map(|j| column(sims, buf, j)))
            .collect();
    }
    let column = &column;
    let parts: Vec<Option<Vec<(usize, T)>>> = std::thread::scope(|scope| {
        let others: Vec<_> = (1..threads)
            .map(|t| {
                scope.spawn(move || {
                    let mut sims = simulators(target, "differences").ok()?;
                    let mut buf = Vec::new();
                    (1 + t..count)
                        .step_by(threads)
                        .map(|j| Some((j, column(&mut sims, &mut buf, j)?)))
                        .collect()
                })
            })
            .collect();
        let mine = (1..count)
            .step_by(threads)
            .map(|j| Some((j, column(sims, buf, j)?)))
            .collect();
        std::iter::once(mine)
            .chain(others.into_iter().map(|h| h.join().ok().flatten()))
            .collect()
    });
    let mut out: Vec<Option<T>> = std::iter::once(Some(first))
        .chain((1..count).map(|_| None))
        .collect();
    for part in parts {
        for (j, c) in part? {
            out[j] = Some(c);
        }
    }
    out.into_iter().collect()
}

/// The weighted residuals `r ∘ w` followed by the prior's rows `z` (the standardised
/// parameters): the least-squares vector of a trial.
fn with_prior_rows(r: &[f64], weights: &[f64], z: &[f64]) -> DVector<f64> {
    let mut out = DVector::zeros(r.len() + z.len());
    for (i, (x, w)) in r.iter().zip(weights).enumerate() {
        out[i] = x * w;
    }
    for (j, zj) in z.iter().enumerate() {
        out[r.len() + j] = *zj;
    }
    out
}

/// Simulations one start may use by default. Starts that reach the optimum need 350–800 on the examples
/// (9 parameters); starts that wander in a flat region used up to 15,000 without improving.
pub const SIMULATIONS_PER_START: usize = 1500;

impl lm::LeastSquares for Problem<'_, '_> {
    fn residuals(&mut self, z: &[f64]) -> Option<DVector<f64>> {
        self.weighted(z)
    }

    fn jacobian(&mut self, z: &[f64], base: &DVector<f64>) -> Option<DMatrix<f64>> {
        self.forward_differences(z, base)
    }

    fn normal(&mut self, z: &[f64], base: &DVector<f64>) -> Option<(DMatrix<f64>, DVector<f64>)> {
        // A start that has not settled within its budget is abandoned.
        if *self.evaluations.borrow() > self.budget {
            return None;
        }
        let at_hand = self
            .at_hand
            .borrow_mut()
            .take()
            .filter(|(at, _)| at.as_slice() == z)
            .map(|(_, model)| model);
        let sensitive = at_hand.or_else(|| {
            let mut sims = self.sims.borrow_mut();
            let model = sensitivity_normals(&mut sims, self.target, z)?;
            *self.runs.borrow_mut() += self.target.records.len();
            Some(model)
        });
        if let Some(model) = sensitive {
            // Counted as the p runs it replaces, so a start's budget buys the same iterations.
            *self.evaluations.borrow_mut() += z.len();
            let block_weights: Vec<f64> = self
                .target
                .blocks()
                .iter()
                .map(|&(start, _)| self.weights.get(start).copied().unwrap_or(0.0))
                .collect();
            return Some(model.weighted(&block_weights, z));
        }
        let jac = self.forward_differences(z, base)?;
        let jt = jac.transpose();
        Some((&jt * &jac, &jt * base))
    }
}

/// A fit under noise weights still on their way stops when its next step is predicted to gain
/// less than this (nats of the negative log posterior): about 0.14 posterior sd along the step.
pub const COARSE_GAIN: f64 = 1e-2;
/// The fit under settled noise weights stops below this gain: about 0.004 posterior sd, far
/// below anything a report shows (the steps it saves each moved the estimates by less).
pub const FINE_GAIN: f64 = 1e-5;
/// The noise estimates (log variances) have all but settled when no block's moved by more
/// than this in an outer iteration.
const NOISE_NEARLY_SETTLED: f64 = 0.1;

/// Newton on `N s/2 + SSE e^{−s}/2 + (s − μ)²/(2v)`, convex in s.
fn optimal_log_noise(n: f64, sse: f64, mean: f64, var: f64, start: f64) -> f64 {
    let mut s = start;
    for _ in 0..50 {
        let g = n / 2.0 - sse * (-s).exp() / 2.0 + (s - mean) / var;
        let h = sse * (-s).exp() / 2.0 + 1.0 / var;
        let step = g / h;
        s -= step.clamp(-5.0, 5.0);
        if step.abs() < 1e-12 {
            break;
        }
    }
    s
}

fn neg_log_posterior(target: &Target, sse: &[f64], s: &[f64], z: &[f64]) -> f64 {
    let mut j = 0.5 * z.iter().map(|x| x * x).sum::<f64>();
    for (((&(_, n), sse), s), mean) in target
        .blocks()
        .iter()
        .zip(sse)
        .zip(s)
        .zip(target.noise_means())
    {
        j += n as f64 * s / 2.0
            + sse * (-s).exp() / 2.0
            + (s - mean).powi(2) / (2.0 * target.noise_var);
    }
    j
}

struct StartResult {
    z: Vec<f64>,
    /// log σ² of every block (record, floor).
    s: Vec<f64>,
    objective: f64,
    /// FMU runs made.
    runs: usize,
}

/// A start on its way: the parameters and noise after its outer iterations so far.
struct Running {
    z: Vec<f64>,
    /// log σ² of every block (record, floor).
    s: Vec<f64>,
    /// The next fit is a fine one (the noise has all but settled).
    fine: bool,
    /// The noise has settled after a fine fit: the start is done.
    done: bool,
    outer: usize,
    evaluations: usize,
    runs: usize,
    /// The negative log posterior at (z, s).
    objective: f64,
}

/// Outer iterations a start makes at most: a fit of the parameters under fixed noise weights,
/// then the noise's own optimum for those parameters.
const OUTER_ITERATIONS: usize = 6;

/// A start from `z0`, the noise at its priors' means, before any iteration.
fn new_start(target: &Target, z0: Vec<f64>) -> Running {
    Running {
        z: z0,
        s: target.noise_means(),
        fine: false,
        done: false,
        outer: 0,
        evaluations: 0,
        runs: 0,
        objective: f64::INFINITY,
    }
}

/// One outer iteration of `start` within `budget` evaluations in all: the parameters fitted
/// under the current noise weights, then the noise's optimum for them. None when the FMU
/// refused the parameters.
fn outer_iteration<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    start: &mut Running,
    budget: usize,
) -> Option<()> {
    let blocks = target.blocks();
    let means = target.noise_means();
    let records = target.records.len();
    let mut buf: Vec<Vec<f64>> = Vec::new();
    // The noise starts at its prior's mean, usually far from the record's: the fit under those
    // weights is only a way to the next noise estimate, and stops at a coarse gain
    // ([`COARSE_GAIN`]); once the noise has all but settled the fit goes on to [`FINE_GAIN`].
    // The last fit is always a fine one.
    let settings = lm::Settings {
        min_predicted: if start.fine { FINE_GAIN } else { COARSE_GAIN },
        ..lm::Settings::default()
    };
    let mut weights = Vec::with_capacity(target.rows());
    for (&(_, n), sb) in blocks.iter().zip(&start.s) {
        weights.extend(std::iter::repeat((-sb / 2.0).exp()).take(n));
    }
    let mut problem = Problem {
        sims: RefCell::new(&mut *sims),
        target,
        weights,
        buf: RefCell::new(Default::default()),
        evaluations: RefCell::new(0),
        runs: RefCell::new(0),
        at_hand: RefCell::new(None),
        last: RefCell::new(None),
        budget: budget.saturating_sub(start.evaluations),
    };
    let z = std::mem::take(&mut start.z);
    start.z = match problem.weighted(&z) {
        Some(r0) => lm::minimize(&mut problem, z, r0, settings).0,
        None => z,
    };
    start.evaluations += *problem.evaluations.borrow();
    start.runs += *problem.runs.borrow();
    // The fit's last trial is usually where it ended (a fit stops on the step it would take
    // next, untried): its residuals are at hand.
    let r = match problem.last.take() {
        Some((at, r)) if at == start.z => r,
        _ => {
            start.evaluations += 1;
            start.runs += records;
            raw_residuals(sims, target, &start.z, &mut buf)?
        }
    };
    let sse = sse_per_block(&r, &blocks);
    let s_new: Vec<f64> = (0..blocks.len())
        .map(|b| {
            optimal_log_noise(
                blocks[b].1 as f64,
                sse[b],
                means[b],
                target.noise_var,
                start.s[b],
            )
        })
        .collect();
    let moved = s_new
        .iter()
        .zip(&start.s)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    start.s = s_new;
    start.objective = neg_log_posterior(target, &sse, &start.s, &start.z);
    start.outer += 1;
    start.done = (moved < 1e-3 && start.fine) || start.outer >= OUTER_ITERATIONS;
    start.fine = moved < NOISE_NEARLY_SETTLED;
    Some(())
}

/// Run `start` on to its end within `budget` evaluations in all.
fn finish_start<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    mut start: Running,
    budget: usize,
) -> Option<StartResult> {
    // The last outer iteration leaves the objective at the start's final (z, s): no run more.
    while !start.done {
        outer_iteration(sims, target, &mut start, budget)?;
    }
    start.objective.is_finite().then_some(StartResult {
        z: start.z,
        s: start.s,
        objective: start.objective,
        runs: start.runs,
    })
}

/// One start from `z0` (the noise from its priors' means), within `budget` evaluations.
fn run_start<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z0: Vec<f64>,
    budget: usize,
) -> Option<StartResult> {
    finish_start(sims, target, new_start(target, z0), budget)
}

/// Starts whose negative log posterior after their first outer iteration is more than this
/// above the best start's stop there (nats). Measured on dataset3's diagnosis (58 starts of 16
/// fits): a start near its fit's best gained at most 14 nats after its first outer iteration
/// (a start far behind, up to 183 — still thousands of nats behind).
pub const RACE_MARGIN: f64 = 50.0;
/// Two starts whose parameters (in prior standard deviations) after their first outer
/// iteration differ by less than this in every coordinate have reached the same optimum (the
/// same fit's starts there differed by at most 0.012; distinct optima by 0.2 or more): only
/// the better goes on.
pub const SAME_OPTIMUM: f64 = 0.05;

/// The race after the first outer iteration: the starts (index, state) that go on — the best,
/// and every other within [`RACE_MARGIN`] of it at an optimum of its own — and those that stop.
fn race(mut first: Vec<(usize, Running)>) -> (Vec<(usize, Running)>, Vec<(usize, Running)>) {
    first.sort_by(|a, b| a.1.objective.total_cmp(&b.1.objective));
    let best = first.first().map_or(f64::INFINITY, |b| b.1.objective);
    let (mut going, mut stopped) = (Vec::new(), Vec::new());
    for (i, start) in first {
        let behind = start.objective > best + RACE_MARGIN;
        let same = going.iter().any(|(_, kept): &(usize, Running)| {
            kept.z
                .iter()
                .zip(&start.z)
                .all(|(a, b)| (a - b).abs() < SAME_OPTIMUM)
        });
        if behind || same {
            stopped.push((i, start));
        } else {
            going.push((i, start));
        }
    }
    (going, stopped)
}

/// Every start for a few iterations, then the best [`SCREEN_KEEP`] on (the screen: more starts
/// than that, and a budget above the screen's); then every start still going for its first
/// outer iteration, and the [`race`]'s on to their end. Every start's outcome, the simulations
/// spent, and the best start.
fn screened_starts(
    target: &Target,
    starts: &[Vec<f64>],
    p: usize,
    threads: usize,
) -> Result<(Vec<StartOutcome>, usize, Option<StartResult>), TwinError> {
    let screen_budget = SCREEN_EVALUATIONS_PER_PARAMETER * (p + 1);
    let screening = starts.len() > SCREEN_KEEP && target.budget > screen_budget;
    let mut jobs: Vec<StartJob> = starts.iter().cloned().enumerate().collect();
    let mut outcomes = Vec::new();
    let mut simulations = 0;
    let mut stop = |i: usize, objective: f64, runs: usize| {
        simulations += runs;
        outcomes.push(StartOutcome {
            start: i,
            neg_log_posterior: objective,
            evaluations: runs,
            screened_out: true,
        });
    };
    let mut spent = BTreeMap::new();
    let mut budget = target.budget;
    if screening {
        let mut first = run_starts(target, jobs, screen_budget, threads)?;
        first.sort_by(|a, b| match (&a.1, &b.1) {
            (Some(x), Some(y)) => x.objective.total_cmp(&y.objective),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => a.0.cmp(&b.0),
        });
        let rest = first.split_off(SCREEN_KEEP.min(first.len()));
        for (i, res) in rest.into_iter() {
            if let Some(res) = res {
                stop(i, res.objective, res.runs);
            }
        }
        jobs = first
            .into_iter()
            .filter_map(|(i, res)| {
                let res = res?;
                spent.insert(i, res.runs);
                // The noise starts again from its prior mean, as every start does: from the
                // screen's (a poor fit's) larger noise the prior outweighs the data and the
                // outer iterations end before the fit is done.
                Some((i, res.z))
            })
            .collect();
        budget = target.budget.saturating_sub(screen_budget);
    }
    // The first outer iteration of every start still going, the race, the rest to the end: a
    // start the screen kept can still be far behind (on two long roving runs one of the three
    // kept wandered for its whole budget, ten times the winner's simulations).
    let first = on_threads(target, jobs, threads, |sims, (i, z0)| {
        let mut start = new_start(target, z0);
        (
            i,
            outer_iteration(sims, target, &mut start, budget).map(|()| start),
        )
    })?;
    let (going, stopped) = race(
        first
            .into_iter()
            .filter_map(|(i, s)| Some((i, s?)))
            .collect(),
    );
    let before = |i: usize| spent.get(&i).copied().unwrap_or(0);
    for (i, start) in stopped {
        stop(i, start.objective, start.runs + before(i));
    }
    let finished = on_threads(target, going, threads, |sims, (i, start)| {
        (i, finish_start(sims, target, start, budget))
    })?;
    let mut best: Option<StartResult> = None;
    for (i, res) in finished {
        let Some(mut res) = res else { continue };
        res.runs += before(i);
        simulations += res.runs;
        outcomes.push(StartOutcome {
            start: i,
            neg_log_posterior: res.objective,
            evaluations: res.runs,
            screened_out: false,
        });
        if best.as_ref().map_or(true, |b| res.objective < b.objective) {
            best = Some(res);
        }
    }
    outcomes.sort_by_key(|o| o.start);
    Ok((outcomes, simulations, best))
}

/// A start: its index and parameters.
type StartJob = (usize, Vec<f64>);

/// The starts `jobs` within `budget` evaluations each, over `threads` threads (one FMU instance
/// each), in no particular order.
fn run_starts(
    target: &Target,
    jobs: Vec<StartJob>,
    budget: usize,
    threads: usize,
) -> Result<Vec<(usize, Option<StartResult>)>, TwinError> {
    on_threads(target, jobs, threads, |sims, (i, z0)| {
        (i, run_start(sims, target, z0, budget))
    })
}

/// `work` on every job over `threads` threads, each with simulators of its own (one FMU
/// instance per record), results in no particular order.
fn on_threads<'a, J: Send, T: Send>(
    target: &Target<'a>,
    jobs: Vec<J>,
    threads: usize,
    work: impl Fn(&mut [Simulator<'a>], J) -> T + Sync,
) -> Result<Vec<T>, TwinError> {
    let threads = threads.clamp(1, jobs.len().max(1));
    if threads == 1 {
        // One thread's work on this one: no thread to start and schedule, no fresh heap.
        let mut sims = simulators(target, "calibration")?;
        return Ok(jobs.into_iter().map(|job| work(&mut sims, job)).collect());
    }
    let mut chunks: Vec<Vec<J>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, job) in jobs.into_iter().enumerate() {
        chunks[k % threads].push(job);
    }
    let work = &work;
    let results: Vec<Result<Vec<T>, TwinError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|chunk| {
                scope.spawn(move || -> Result<Vec<T>, TwinError> {
                    let mut sims = simulators(target, "calibration")?;
                    Ok(chunk.into_iter().map(|job| work(&mut sims, job)).collect())
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(TwinError::Invalid {
                        path: "calibration".into(),
                        message: "a worker thread panicked".into(),
                    })
                })
            })
            .collect()
    });
    let mut out = Vec::new();
    for r in results {
        out.extend(r?);
    }
    Ok(out)
}

/// The residuals at `z` and their Jacobian by central differences (2p runs per record).
fn central_differences<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z: &[f64],
) -> Option<(Vec<f64>, DMatrix<f64>)> {
    let mut buf: Vec<Vec<f64>> = Vec::new();
    let r0 = raw_residuals(sims, target, z, &mut buf)?;
    let mut jac = DMatrix::zeros(r0.len(), z.len());
    let columns = over_columns(sims, &mut buf, target, z.len(), |sims, buf, j| {
        let h = 1e-4 * z[j].abs().max(1.0);
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        zp[j] += h;
        zm[j] -= h;
        let rp = raw_residuals(sims, target, &zp, buf)?;
        let rm = raw_residuals(sims, target, &zm, buf)?;
        Some(
            rp.iter()
                .zip(&rm)
                .map(|(p, m)| (p - m) / (2.0 * h))
                .collect::<Vec<f64>>(),
        )
    })?;
    for (j, c) in columns.iter().enumerate() {
        jac.column_mut(j).copy_from_slice(c);
    }
    Some((r0, jac))
}

/// The Laplace approximation at (z, s): covariance of (z, s), `s` every block's log σ² after
/// the parameters. Also the FMU runs it made.
fn laplace<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z: &[f64],
    s: &[f64],
) -> Option<(DMatrix<f64>, usize)> {
    let p = z.len();
    let records = target.records.len();
    let blocks = target.blocks();
    let (model, runs) = match sensitivity_normals(sims, target, z) {
        Some(exact) => (exact, records),
        None => {
            let (r0, jac) = central_differences(sims, target, z)?;
            let model = ModelNormals::from_jacobian(r0, &jac, &blocks);
            (model, (2 * p + 1) * records)
        }
    };
    let sse = sse_per_block(&model.r, &blocks);
    let q = blocks.len();
    let mut hess = DMatrix::zeros(p + q, p + q);
    for (b, (jtj, jtr)) in model.blocks.iter().enumerate() {
        let w = (-s[b]).exp();
        for a in 0..p {
            for c in 0..p {
                hess[(a, c)] += w * jtj[(a, c)];
            }
            hess[(a, p + b)] = -w * jtr[a];
            hess[(p + b, a)] = -w * jtr[a];
        }
        hess[(p + b, p + b)] = sse[b] * w / 2.0 + 1.0 / target.noise_var;
    }
    for a in 0..p {
        hess[(a, a)] += 1.0;
    }
    Some((hess.try_inverse()?, runs))
}

/// The samples the likelihood uses: after the transient, where the mask (if any) is set.
/// Also the first sample after the transient.
fn used_samples(
    data: &Measurement,
    mask: Option<&[bool]>,
    transient: f64,
) -> Result<(usize, Vec<usize>), CalibrateError> {
    let first = crate::evaluation::stats::first_after_transient(&data.time, transient);
    if let Some(mask) = mask {
        if mask.len() != data.len() {
            return Err(CalibrateError::Setup(format!(
                "{}: the sample mask has {} entries for a record of {} samples",
                data.path.display(),
                mask.len(),
                data.len()
            )));
        }
    }
    let used: Vec<usize> = (first..data.len())
        .filter(|&k| mask.map_or(true, |m| m[k]))
        .collect();
    if used.len() < 10 {
        return Err(CalibrateError::Setup(format!(
            "{}: the transient cut-off of {} s and the sample mask leave {} samples",
            data.path.display(),
            transient,
            used.len()
        )));
    }
    Ok((first, used))
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

impl<'a> Target<'a> {
    /// The calibration's target: the records, the calibrated parameters (`vrs`, with their
    /// `priors`), the component's other parameters as they are, and the FMU's sensitivities when
    /// every channel has them.
    fn new(
        fmu: &'a Fmu,
        component: &Component,
        setup: &CalibrationSetup,
        records: Vec<RecordTarget<'a>>,
        vrs: Vec<u32>,
        priors: Vec<Prior>,
    ) -> Self {
        let mut base = component.parameters.clone();
        for name in &setup.parameters {
            base.remove(name);
        }
        let linear = LinearFit::new(&fmu.path, &base, &setup.parameters);
        let mut target = Target {
            fmu,
            base,
            records,
            vrs,
            priors,
            noise_var: setup.noise_log_variance,
            budget: setup.simulations_per_start.max(1),
            sensitivity: Sensitivity::find(fmu),
            linear,
            columns_threads: 1,
        };
        if !target.sensitive() {
            target.sensitivity = None;
        }
        target
    }
}

/// The starts, in the priors' standardised coordinates: the prior mean (or `setup.initial`),
/// then the values `setup.starts_at`, then draws from the prior widened ×3.
fn starts(setup: &CalibrationSetup, priors: &[Prior]) -> Vec<Vec<f64>> {
    let mut rng = StdRng::seed_from_u64(setup.seed);
    let p = setup.parameters.len();
    let at = |given: &BTreeMap<String, f64>| -> Vec<f64> {
        setup
            .parameters
            .iter()
            .zip(priors)
            .map(|(name, prior)| match given.get(name) {
                Some(&v) if prior.space == Space::Linear || v > 0.0 => {
                    (prior.coordinate(v) - prior.mean) / prior.sd()
                }
                _ => 0.0,
            })
            .collect()
    };
    (0..setup.starts.max(1))
        .map(|i| {
            if i == 0 {
                at(&setup.initial)
            } else if let Some(given) = setup.starts_at.get(i - 1) {
                at(given)
            } else {
                (0..p)
                    .map(|_| 3.0 * rng.sample::<f64, _>(StandardNormal))
                    .collect()
            }
        })
        .collect()
}

/// The Laplace posterior of the calibrated parameters.
struct Posterior {
    parameters: Vec<ParameterEstimate>,
    correlation: Vec<Vec<f64>>,
    log_evidence: f64,
}

impl Posterior {
    /// The posterior at the optimum `values` (negative log posterior `objective` there), from
    /// the covariance `cov` of the standardised parameters and the log noise variances: each
    /// parameter's estimate and sd, their correlations, and the log evidence.
    fn at(
        target: &Target,
        setup: &CalibrationSetup,
        values: &[f64],
        cov: &DMatrix<f64>,
        objective: f64,
    ) -> Posterior {
        let p = setup.parameters.len();
        let parameters = (0..p)
            .map(|j| {
                let prior = target.priors[j];
                let sd_coordinate = prior.sd() * cov[(j, j)].max(0.0).sqrt();
                let sd = match prior.space {
                    Space::Linear => sd_coordinate,
                    Space::Log => values[j] * sd_coordinate,
                };
                ParameterEstimate {
                    name: setup.parameters[j].clone(),
                    value: values[j],
                    prior,
                    sd_coordinate,
                    sd,
                }
            })
            .collect();
        let correlation = (0..p)
            .map(|a| {
                (0..p)
                    .map(|b| cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt())
                    .collect()
            })
            .collect();
        let log_evidence = match cov.clone().cholesky() {
            Some(chol) => {
                let log_det: f64 = chol.l().diagonal().iter().map(|d| 2.0 * d.ln()).sum();
                -objective + 0.5 * log_det
            }
            None => f64::NEG_INFINITY,
        };
        Posterior {
            parameters,
            correlation,
            log_evidence,
        }
    }
}

/// What the calibration found on each record at the optimum (`values`, the log noise
/// variances `s`, covariance `cov`): its noise variances with their posterior sd, and the fit's
/// NMSE per channel after the record's transient (`firsts`), one run per record.
fn record_fits(
    sims: &mut [Simulator],
    target: &Target,
    firsts: &[usize],
    values: &[f64],
    s: &[f64],
    cov: &DMatrix<f64>,
) -> Result<Vec<RecordCalibration>, CalibrateError> {
    let p = target.priors.len();
    let mut buf: Vec<Vec<f64>> = Vec::new();
    let mut fitted = Vec::with_capacity(target.records.len());
    let mut block = 0;
    for ((sim, record), &first) in sims.iter_mut().zip(&target.records).zip(firsts) {
        buf.resize(record.channels.len(), Vec::new());
        sim.record(&target.vrs, values, &record.outputs(), &mut buf)?;
        let q = record.channels.len();
        let blocks = block..block + q;
        block += q;
        fitted.push(RecordCalibration {
            record: record.data.path.display().to_string(),
            channels: record.channels.iter().map(|c| c.name.clone()).collect(),
            noise_variance: blocks.clone().map(|b| s[b].exp()).collect(),
            noise_log_sd: blocks
                .map(|b| cov[(p + b, p + b)].max(0.0).sqrt())
                .collect(),
            samples_used: record.used.len(),
            nmse: record
                .channels
                .iter()
                .zip(&buf)
                .map(|(c, predicted)| {
                    crate::evaluation::compare::nmse(&c.values[first..], &predicted[first..])
                })
                .collect(),
        });
    }
    Ok(fitted)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn at(objective: f64, z: &[f64]) -> Running {
        Running {
            z: z.to_vec(),
            s: Vec::new(),
            fine: false,
            done: false,
            outer: 1,
            evaluations: 10,
            runs: 10,
            objective,
        }
    }

    /// The race keeps the best start and every start within the margin at an optimum of its
    /// own; a start behind by more than the margin, or at the best's optimum, stops.
    #[test]
    fn the_race_keeps_the_best_and_the_distinct_near_it() {
        let first = vec![
            (0, at(-1000.0, &[0.5, 0.2])),
            (1, at(-2000.0, &[0.9, 0.0])),
            // The best's optimum, a little behind it.
            (
                2,
                at(-1999.0, &[0.9 + 0.4 * SAME_OPTIMUM, -0.4 * SAME_OPTIMUM]),
            ),
            // Another optimum, within the margin.
            (3, at(-2000.0 + 0.9 * RACE_MARGIN, &[-0.3, 0.0])),
            // Another optimum, beyond the margin.
            (4, at(-2000.0 + 1.1 * RACE_MARGIN, &[2.0, 1.0])),
        ];
        let (going, stopped) = race(first);
        let going: Vec<usize> = going.iter().map(|g| g.0).collect();
        let mut stopped: Vec<usize> = stopped.iter().map(|s| s.0).collect();
        stopped.sort();
        assert_eq!(
            going,
            vec![1, 3],
            "the best first, then the distinct one near it"
        );
        assert_eq!(stopped, vec![0, 2, 4]);
    }
}
