//! Running a twin on a measurement: the system of the twin's FMUs, the measured excitation
//! (`force` or `ground_acc`) replayed as its input, the twin's value of every response channel
//! the record measures recorded.

use std::time::{Duration, Instant};

use ::structure::channel::{Channel, Quantity};

use crate::cosim::master::{Clock, Recorder};
use crate::evaluation::compare::{compare, CompareOptions, Comparison};
use crate::evaluation::stats::{variance, worst};
use crate::twin::data::Measurement;
use crate::twin::system::{SystemBuilder, SystemError};
use crate::twin::{ParameterValue, Twin, PHYSICS};

/// A run's error is the system builder's: the twin, the master or the wiring.
pub type RunError = SystemError;

/// The twin's prediction of one measured channel at every sample of the record.
#[derive(Debug, Clone)]
pub struct PredictedChannel {
    pub channel: Channel,
    /// In SI: m/s², m/s or m.
    pub values: Vec<f64>,
    /// The corrector's latent variance V(f) of this channel, when the twin corrects it.
    pub latent_var: Option<Vec<f64>>,
    /// The corrector's predictive standard deviation of this channel, likewise.
    pub sd: Option<Vec<f64>>,
}

/// The twin's prediction of a record: one [`PredictedChannel`] per response channel, in the
/// record's order.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub time: Vec<f64>,
    pub channels: Vec<PredictedChannel>,
}

/// Acceleration of floor `floor` (1-based).
fn acc_channel(floor: usize) -> Channel {
    Channel::Response {
        quantity: Quantity::Acceleration,
        floor,
    }
}

impl Prediction {
    /// Accelerations of floors 1, 2, … (a closed loop's prediction), without corrector.
    pub fn of_accelerations(time: Vec<f64>, acc: Vec<Vec<f64>>) -> Prediction {
        let channels = acc
            .into_iter()
            .enumerate()
            .map(|(f, values)| PredictedChannel {
                channel: acc_channel(f + 1),
                values,
                latent_var: None,
                sd: None,
            })
            .collect();
        Prediction { time, channels }
    }

    /// The prediction of `channel`, if the twin made one.
    pub fn get(&self, channel: Channel) -> Option<&PredictedChannel> {
        self.channels.iter().find(|c| c.channel == channel)
    }

    /// The predicted channels' names, in order.
    pub fn names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.channel.name()).collect()
    }

    /// Whether the twin gives a predictive sd (its corrector) for some channel.
    pub fn has_sd(&self) -> bool {
        self.channels.iter().any(|c| c.sd.is_some())
    }

    /// Floor `f`'s acceleration (`f` from 0), for the workflows written for the paper's rig
    /// (their records have acc1..acc3, [`Measurement::require_paper_rig`]). Panics when it
    /// was not predicted.
    pub fn acc(&self, f: usize) -> &[f64] {
        &self
            .get(acc_channel(f + 1))
            .unwrap_or_else(|| panic!("the prediction has no acc{}", f + 1))
            .values
    }

    /// The latent variances of `channels`, in their order, when the twin's corrector gives one
    /// for each (the paper's rig: `structure::paper::channels()`).
    pub fn latent_vars(&self, channels: &[Channel]) -> Option<Vec<&[f64]>> {
        channels
            .iter()
            .map(|&c| self.get(c)?.latent_var.as_deref())
            .collect()
    }
}

/// Calls `on_progress(done, total)`, but only once a run has lasted more than a second, so short
/// runs print nothing.
pub struct Progress<F: FnMut(u64, u64)> {
    started: Instant,
    report: F,
}

impl<F: FnMut(u64, u64)> Progress<F> {
    pub fn new(report: F) -> Self {
        Progress {
            started: Instant::now(),
            report,
        }
    }
    pub fn tick(&mut self, done: u64, total: u64) {
        if self.started.elapsed() > Duration::from_secs(1) {
            (self.report)(done, total);
        }
    }
}

/// Run `twin` on `data`'s excitation (`force` or `ground_acc`; the control force, if the data
/// has a `control` column and the twin takes it, is replayed too) and record its value of every
/// response channel the record measures: the system output of that name when the twin has one
/// (a corrector's corrected acceleration), else the physics component's variable (`acc<i>`,
/// `vel<i>`, `disp<i>`: the shear FMU has them for every floor); and the corrector's latent
/// variance and sd of each channel when the twin gives them (`latent_var<i>`, `sd<i>` for
/// `acc<i>`; `latent_var_vel2`, `sd_vel2` for another channel).
pub fn run_twin(
    twin: &Twin,
    data: &Measurement,
    mut progress: impl FnMut(u64, u64),
) -> Result<Prediction, RunError> {
    let start = data.time[0];
    let excitation = data.excitation.channel.name();
    let driven = |name: &str| {
        twin.connections
            .iter()
            .any(|c| c.start_element.is_none() && c.start_connector == name)
    };
    if !driven(&excitation) {
        return Err(RunError::Wiring(format!(
            "{}: the record is excited by '{excitation}', which {} does not take",
            data.path.display(),
            twin.describe(),
        )));
    }
    let mut inputs = vec![(excitation.as_str(), data.excitation.values.clone())];
    if let Some(control) = data.extra.get("control") {
        inputs.push(("control_force", control.clone()));
    }
    // Channels the twin gives out under their name, and those read from its physics.
    let measured: Vec<Channel> = data.responses.iter().map(|s| s.channel).collect();
    let names: Vec<String> = measured.iter().map(Channel::name).collect();
    let wired = twin.wired_for(&measured);
    let twin = wired.as_ref().unwrap_or(twin);
    let builder = SystemBuilder::open(twin)?;
    let mut running = builder.build(start, inputs)?;
    let system_outputs = twin.system_outputs();
    // The corrector's names: latent_var<i> / sd<i> for acc<i>, latent_var_<c> / sd_<c> else.
    let band_of = |name: &str, prefix: &str| -> Option<String> {
        let band = fmu_gp_corrector::layout::band_name(prefix, &Channel::parse(name)?);
        system_outputs.contains(&band).then_some(band)
    };
    let mut watched = Vec::new();
    for name in &names {
        watched.push((name.clone(), running.system_output(twin, name)?));
        for prefix in ["latent_var", "sd"] {
            if let Some(band) = band_of(name, prefix) {
                if !watched.iter().any(|(w, _)| *w == band) {
                    let port = running.system_output(twin, &band)?;
                    watched.push((band, port));
                }
            }
        }
    }
    let mut recorder = Recorder::new(watched);
    let clock = Clock::new(start, data.dt, (data.len() - 1) as u64);
    running
        .system
        .run(clock, &mut [&mut recorder], &mut progress)?;
    drop(running);
    let column = |name: &str| recorder.column(name).map(<[f64]>::to_vec);
    let channels = data
        .responses
        .iter()
        .zip(&names)
        .map(|(signal, name)| {
            let values = column(name)
                .ok_or_else(|| RunError::Wiring(format!("the twin's '{name}' was not recorded")))?;
            Ok(PredictedChannel {
                channel: signal.channel,
                values,
                latent_var: band_of(name, "latent_var").and_then(|b| column(&b)),
                sd: band_of(name, "sd").and_then(|b| column(&b)),
            })
        })
        .collect::<Result<Vec<_>, RunError>>()?;
    Ok(Prediction {
        time: recorder.time.clone(),
        channels,
    })
}

/// Noise variance when the twin has none (not calibrated): 2 % of each floor's measured
/// variance, the centre the calibration's noise prior uses.
pub const PRIOR_NOISE_FRACTION: f64 = 0.02;

/// Tolerance (NMSE %) when the twin has no validation records: a twin within it explains
/// 99.5 % of the response's variance, and the smallest changes the hidden-effect tests plant
/// (contact, friction, a stiffness change of 15 %) give 5.8 % and more.
pub const FALLBACK_TOLERANCE: f64 = 0.5;
/// The default tolerance is this × the twin's worst validation NMSE.
pub const VALIDATION_MARGIN: f64 = 2.0;
/// Validation records worse than this (worst floor, %) are not stored as evidence of fidelity
/// by `twin calibrate`: they show something the twin does not know (dataset3's contact).
pub const VALIDATION_CAP: f64 = 1.0;

/// Whether a validation record's NMSE (per floor or channel, %) counts as the twin's validation level.
pub fn accepted_for_validation(nmse: &[f64]) -> bool {
    !nmse.is_empty() && worst(nmse) <= VALIDATION_CAP
}

/// The twin's validation NMSE from its validation records (name, NMSE per floor): the worst
/// floor of the worst record under [`VALIDATION_CAP`]; records above it show something the
/// twin does not know and are no measure of its fidelity.
pub fn validation_nmse<N: AsRef<[f64]>>(validated: &[(String, N)]) -> Option<f64> {
    validated
        .iter()
        .filter(|(_, n)| accepted_for_validation(n.as_ref()))
        .map(|(_, n)| worst(n.as_ref()))
        .reduce(f64::max)
}

/// Practical significance: below this NMSE (%) nothing is reported as failing.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Tolerance {
    pub value: f64,
    pub source: String,
}

impl Tolerance {
    /// `given` (`--tolerance`), else [`VALIDATION_MARGIN`] × the twin's validation NMSE, else
    /// [`FALLBACK_TOLERANCE`].
    pub fn resolve(twin: &Twin, given: Option<f64>) -> Tolerance {
        match (given, twin.validation_nmse) {
            (Some(t), _) => Tolerance {
                value: t,
                source: "--tolerance".into(),
            },
            (None, Some(v)) => Tolerance {
                value: VALIDATION_MARGIN * v,
                source: format!(
                    "{VALIDATION_MARGIN} × the twin's worst validation NMSE ({v:.3} %)"
                ),
            },
            (None, None) => Tolerance {
                value: FALLBACK_TOLERANCE,
                source: format!(
                    "fallback {FALLBACK_TOLERANCE} % (the twin has no validation records)"
                ),
            },
        }
    }
}

/// A twin run on a record and compared with it, channel by channel in the record's order.
pub struct Compared {
    pub prediction: Prediction,
    pub comparison: Comparison,
    /// The ±3σ band's noise variance per channel: the twin's, else [`PRIOR_NOISE_FRACTION`] of
    /// the record's, in the channel's own unit squared (SI).
    pub noise_variance: Vec<f64>,
    pub noise_source: String,
    /// Per channel and sample, the prediction's variance from the twin's parameter uncertainty
    /// (`J Σ Jᵀ`), when the twin has a posterior covariance and no corrector band.
    pub parameter_variance: Option<Vec<Vec<f64>>>,
    /// NMSE per channel (%) the band explains on this record after the transient: noise alone,
    /// and the parameter uncertainty's share (`100 · mean(J Σ Jᵀ) / var y`).
    pub noise_nmse: Vec<f64>,
    pub band_nmse: Vec<f64>,
    pub tolerance: Tolerance,
}

impl Compared {
    /// NMSE per channel (%) the whole band explains: the noise's and the parameter
    /// uncertainty's shares together.
    pub fn explained_nmse(&self) -> Vec<f64> {
        self.noise_nmse
            .iter()
            .zip(&self.band_nmse)
            .map(|(noise, band)| noise + band)
            .collect()
    }
}

/// Run `twin` on `data` and compare every measured channel after `transient`: the one sequence
/// behind `twin compare`, the calibrated twin's plot and the NMSE after calibrating or training.
/// The band includes the parameter uncertainty; the tolerance is the twin's default.
pub fn run_and_compare(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    progress: impl FnMut(u64, u64),
) -> Result<Compared, RunError> {
    run_and_compare_with(twin, data, transient, None, progress)
}

/// [`run_and_compare`] with a tolerance (NMSE %; None: the twin's default, [`Tolerance::resolve`]).
pub fn run_and_compare_with(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    tolerance: Option<f64>,
    progress: impl FnMut(u64, u64),
) -> Result<Compared, RunError> {
    // The linear model's band needs no prediction: on a second core while the twin runs.
    let (prediction, linear) = std::thread::scope(|scope| {
        let band = scope.spawn(|| linear_parameter_variance(twin, data));
        let prediction = run_twin(twin, data, progress);
        let band = band
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (prediction, band)
    });
    let prediction = prediction?;
    let parameter_variance = if prediction.has_sd() {
        None
    } else if let Some(band) = linear {
        Some(band)
    } else {
        fallback_parameter_variance(twin, data, &prediction)?
    };
    compare_with(
        twin,
        data,
        transient,
        tolerance,
        prediction,
        parameter_variance,
    )
}

/// Compare a prediction the twin made some other way (e.g. in a closed loop) with `data`, as
/// [`run_and_compare`] does, but with the noise band alone (the parameter sensitivities are the
/// open loop's).
pub fn compare_prediction(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    prediction: Prediction,
) -> Result<Compared, RunError> {
    compare_with(twin, data, transient, None, prediction, None)
}

/// The noise variance of each of `data`'s response channels: the twin's where it has one
/// ([`Twin::noise_variance_of`]), else [`PRIOR_NOISE_FRACTION`] of the channel's measured
/// variance; and where they came from, in words.
pub fn noise_variances(twin: &Twin, data: &Measurement) -> (Vec<f64>, String) {
    let mut from_twin = Vec::new();
    let mut from_prior = Vec::new();
    let variances = data
        .responses
        .iter()
        .map(|s| match twin.noise_variance_of(s.channel) {
            Some(v) => {
                from_twin.push(s.channel.name());
                v
            }
            None => {
                from_prior.push(s.channel.name());
                PRIOR_NOISE_FRACTION * variance(&s.values)
            }
        })
        .collect();
    let prior = "prior: 2 % of the measured variance";
    let calibrated = "twin (calibrated)";
    let source = match (from_twin.is_empty(), from_prior.is_empty()) {
        (false, true) => calibrated.to_owned(),
        (true, _) => prior.to_owned(),
        (false, false) => format!(
            "{calibrated} for {}; {prior} for {}",
            from_twin.join(", "),
            from_prior.join(", ")
        ),
    };
    (variances, source)
}

/// Compare `prediction` with `data`, channel by channel in the record's order: the band's
/// variance per sample is the noise variance plus `parameter_variance` (or the corrector's
/// predictive sd where the twin gives one). Err when the prediction lacks a measured channel.
pub fn compare_with(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    tolerance: Option<f64>,
    prediction: Prediction,
    parameter_variance: Option<Vec<Vec<f64>>>,
) -> Result<Compared, RunError> {
    let (noise_variance, noise_source) = noise_variances(twin, data);
    let tolerance = Tolerance::resolve(twin, tolerance);
    let options = CompareOptions {
        transient,
        tolerance: tolerance.value,
        ..CompareOptions::default()
    };
    let predicted: Vec<&PredictedChannel> = data
        .responses
        .iter()
        .map(|s| {
            prediction.get(s.channel).ok_or_else(|| {
                RunError::Wiring(format!(
                    "the twin's prediction has no '{}', which {} measures",
                    s.channel.name(),
                    data.path.display()
                ))
            })
        })
        .collect::<Result<_, _>>()?;
    let n = data.len();
    // A band per sample when some channel has one: the corrector's sd, or noise and parameter
    // uncertainty; the other channels keep their noise sd.
    let band_sd: Option<Vec<Vec<f64>>> =
        if predicted.iter().any(|p| p.sd.is_some()) || parameter_variance.is_some() {
            Some(
                predicted
                    .iter()
                    .enumerate()
                    .map(|(c, p)| match (&p.sd, &parameter_variance) {
                        (Some(sd), _) => sd.clone(),
                        (None, Some(pv)) => pv[c]
                            .iter()
                            .map(|v| (noise_variance[c] + v.max(0.0)).sqrt())
                            .collect(),
                        (None, None) => vec![noise_variance[c].sqrt(); n],
                    })
                    .collect(),
            )
        } else {
            None
        };
    let channels: Vec<Channel> = data.responses.iter().map(|s| s.channel).collect();
    let measured: Vec<Vec<f64>> = data.responses.iter().map(|s| s.values.clone()).collect();
    let predicted_values: Vec<Vec<f64>> = predicted.iter().map(|p| p.values.clone()).collect();
    let comparison = compare(
        &data.time,
        &channels,
        &measured,
        &predicted_values,
        &noise_variance,
        band_sd.as_deref(),
        options,
    );
    let first = comparison.first;
    let record_var: Vec<f64> = measured.iter().map(|m| variance(&m[first..])).collect();
    let noise_nmse = (0..channels.len())
        .map(|c| 100.0 * noise_variance[c] / record_var[c])
        .collect();
    let band_nmse = (0..channels.len())
        .map(|c| match &parameter_variance {
            Some(pv) if pv[c].len() > first => {
                let tail = &pv[c][first..];
                100.0 * tail.iter().sum::<f64>() / tail.len() as f64 / record_var[c]
            }
            _ => 0.0,
        })
        .collect();
    Ok(Compared {
        prediction,
        comparison,
        noise_variance,
        noise_source,
        parameter_variance,
        noise_nmse,
        band_nmse,
        tolerance,
    })
}

/// The prediction's variance per measured channel (the record's order) and sample from the
/// twin's parameter uncertainty, `J Σ Jᵀ`: `J` by forward differences through FMI (the twin run
/// once more per calibrated parameter, the runs spread over the cores), `Σ` the twin's
/// posterior covariance. None when the twin has no covariance, or its physics does not hold a
/// value for every parameter of it.
pub fn parameter_variance(
    twin: &Twin,
    data: &Measurement,
    prediction: &Prediction,
) -> Result<Option<Vec<Vec<f64>>>, RunError> {
    if let Some(band) = linear_parameter_variance(twin, data) {
        return Ok(Some(band));
    }
    fallback_parameter_variance(twin, data, prediction)
}

/// [`parameter_variance`] of a twin that is not the linear shear model alone (the caller has
/// asked [`linear_parameter_variance`] first): from its FMU's sensitivities, else by finite
/// differences.
fn fallback_parameter_variance(
    twin: &Twin,
    data: &Measurement,
    prediction: &Prediction,
) -> Result<Option<Vec<Vec<f64>>>, RunError> {
    let Some(cov) = &twin.parameter_covariance else {
        return Ok(None);
    };
    let Some(physics) = twin.component(PHYSICS) else {
        return Ok(None);
    };
    let mut values = Vec::new();
    for name in &cov.names {
        match physics.parameters.get(name) {
            Some(ParameterValue::Real(x)) => values.push(*x),
            _ => return Ok(None),
        }
    }
    let p = values.len();
    if p == 0 {
        return Ok(None);
    }
    let sigma = nalgebra::DMatrix::from_fn(p, p, |a, b| cov.matrix[a][b]);
    // Not the linear model alone: from one run of the physics FMU with its forward
    // sensitivities where it has them, streamed; else `J` by finite differences, a run per
    // parameter.
    if let Some(band) = sensitivity_band(twin, data, &cov.names, &sigma) {
        return Ok(Some(band));
    }
    let base = measured_columns(data, prediction)?;
    let jac = finite_difference_columns(twin, data, &cov.names, &values, &base)?;
    let n = data.len();
    // Per channel, `diag(J Σ Jᵀ)` as one matrix product `(J Σ) ∘ J` summed along rows (a
    // blocked product: p² per sample, as the scalar form, at the speed of a matrix kernel).
    Ok(Some(
        (0..base.len())
            .map(|c| {
                let j = nalgebra::DMatrix::from_fn(n, p, |k, a| jac[a][c][k]);
                let js = &j * &sigma;
                (0..n)
                    .map(|k| {
                        let v: f64 = (0..p).map(|a| js[(k, a)] * j[(k, a)]).sum();
                        v.max(0.0)
                    })
                    .collect()
            })
            .collect(),
    ))
}

/// [`parameter_variance`] where the twin is the linear shear model alone, which needs no
/// prediction: computed in process over the whole record (the same step maps as its FMU's, in
/// blocks of samples). None for another twin, or one without a posterior covariance.
fn linear_parameter_variance(twin: &Twin, data: &Measurement) -> Option<Vec<Vec<f64>>> {
    let cov = twin.parameter_covariance.as_ref()?;
    if cov.names.is_empty() || twin.components.len() != 1 {
        return None;
    }
    let physics = twin.component(PHYSICS)?;
    let real =
        |name: &String| matches!(physics.parameters.get(name), Some(ParameterValue::Real(_)));
    if !cov.names.iter().all(real) {
        return None;
    }
    let sigma =
        nalgebra::DMatrix::from_fn(cov.names.len(), cov.names.len(), |a, b| cov.matrix[a][b]);
    super::linear::acceleration_band(twin, data, &cov.names, &covariance_root(&sigma))
}

/// A square root `R` of the covariance, `Σ = Rᵀ R`: the Cholesky factor's transpose, or for a
/// covariance that is only semi-definite (a parameter the record does not inform), `√Λ Vᵀ` of
/// its eigenvectors with the negative rounding clipped.
fn covariance_root(sigma: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    match sigma.clone().cholesky() {
        Some(c) => c.l().transpose(),
        None => {
            let eig = sigma.clone().symmetric_eigen();
            let mut root = eig.eigenvectors.transpose();
            for (i, l) in eig.eigenvalues.iter().enumerate() {
                let scale = l.max(0.0).sqrt();
                root.row_mut(i).scale_mut(scale);
            }
            root
        }
    }
}

/// The band's variance `diag(J Σ Jᵀ)` per measured channel (the record's order) and sample,
/// from the physics' forward sensitivities streamed out of one run: each sample's rows of `J`
/// (one per channel, `p` long) are gathered in blocks of samples, multiplied by the covariance's
/// root `R` (`Σ = Rᵀ R`, so the variance is `|R jᵀ|²`) as one matrix product a block, and
/// dropped. Memory is a block, not `J`: samples × channels × parameters (160 MB for 20
/// channels of 20 storeys on 16,384 samples, 3.5 GB on an hour at 100 Hz). None where
/// [`stream_sensitivities`] has none.
fn sensitivity_band(
    twin: &Twin,
    data: &Measurement,
    names: &[String],
    sigma: &nalgebra::DMatrix<f64>,
) -> Option<Vec<Vec<f64>>> {
    const BLOCK: usize = 256;
    let p = names.len();
    let channels = data.responses.len();
    let root = covariance_root(sigma);
    let mut band: Vec<Vec<f64>> = vec![Vec::with_capacity(data.len()); channels];
    // Column (sample · channels + channel) of the block holds that sample's row of J.
    let mut block = nalgebra::DMatrix::<f64>::zeros(p, BLOCK * channels);
    let mut product = nalgebra::DMatrix::<f64>::zeros(p, BLOCK * channels);
    let mut filled = 0;
    let flush = |block: &nalgebra::DMatrix<f64>,
                 product: &mut nalgebra::DMatrix<f64>,
                 filled: usize,
                 band: &mut Vec<Vec<f64>>| {
        product.gemm(1.0, &root, block, 0.0);
        for k in 0..filled {
            for (c, b) in band.iter_mut().enumerate() {
                b.push(product.column(k * channels + c).norm_squared());
            }
        }
    };
    stream_sensitivities(twin, data, names, |values| {
        // `values[c · p + j]`: channel c, parameter j.
        block.as_mut_slice()[filled * channels * p..(filled + 1) * channels * p]
            .copy_from_slice(values);
        filled += 1;
        if filled == BLOCK {
            flush(&block, &mut product, filled, &mut band);
            filled = 0;
        }
    })?;
    if filled > 0 {
        flush(&block, &mut product, filled, &mut band);
    }
    Some(band)
}

/// The prediction's values of each of `data`'s measured channels, in the record's order.
fn measured_columns<'p>(
    data: &Measurement,
    prediction: &'p Prediction,
) -> Result<Vec<&'p [f64]>, RunError> {
    data.responses
        .iter()
        .map(|s| {
            prediction
                .get(s.channel)
                .map(|c| c.values.as_slice())
                .ok_or_else(|| {
                    RunError::Wiring(format!("the prediction has no '{}'", s.channel.name()))
                })
        })
        .collect()
}

/// `∂y/∂θ` (`[parameter][channel][sample]`) by forward differences of the whole twin, one run
/// per parameter (in parallel), around the prediction `base` (per channel, the record's order).
fn finite_difference_columns(
    twin: &Twin,
    data: &Measurement,
    names: &[String],
    values: &[f64],
    base: &[&[f64]],
) -> Result<Vec<Vec<Vec<f64>>>, RunError> {
    let p = values.len();
    // The step: 1e-5 of the value, far inside the posterior's width for any usable calibration
    // and far above rounding, so `J` is the derivative and the band exactly linear in `Σ`.
    let steps: Vec<f64> = values.iter().map(|v| (1e-5 * v.abs()).max(1e-12)).collect();
    let sensitivity = |j: usize| -> Result<Vec<Vec<f64>>, RunError> {
        let mut shifted = twin.duplicate();
        if let Some(c) = shifted.component_mut(PHYSICS) {
            c.parameters
                .insert(names[j].clone(), ParameterValue::Real(values[j] + steps[j]));
        }
        let run = run_twin(&shifted, data, |_, _| {})?;
        Ok(run
            .channels
            .iter()
            .zip(base)
            .map(|(c, b)| {
                c.values
                    .iter()
                    .zip(b.iter())
                    .map(|(a, b)| (a - b) / steps[j])
                    .collect()
            })
            .collect())
    };
    let threads = crate::parallel::cores();
    let parameters: Vec<usize> = (0..p).collect();
    crate::parallel::on_threads(&parameters, threads, |&j| sensitivity(j))
        .into_iter()
        .collect()
}

/// The physics component's `∂y/∂θ` at each sample, from one run of its FMU with the forward
/// sensitivities on: the exact derivatives of its own step map (`fmu_shear::sensitivity`), in
/// one run where finite differences take one per parameter. `each` gets a sample's values,
/// `[channel · p + parameter]` (the record's channels in order). None where that cannot stand
/// for the twin's own derivatives: the twin's outputs not its physics' alone (a corrector), a
/// record with a control column (a closed loop), an FMU without the switch or without
/// `d_{channel}_d_{p}` for a channel and parameter, or non-finite values (an effect on: the FMU
/// gives NaN) — then what `each` was given is to be dropped.
fn stream_sensitivities(
    twin: &Twin,
    data: &Measurement,
    names: &[String],
    mut each: impl FnMut(&[f64]),
) -> Option<()> {
    use crate::cosim::import::Fmu;
    use crate::twin::simulator::{channel_sensitivities, sensitivity_switch, Simulator};
    if data.extra.contains_key("control") || twin.components.len() != 1 {
        return None;
    }
    let physics = twin.component(PHYSICS)?;
    let fmu = Fmu::open(&physics.fmu_path).ok()?;
    let switch = sensitivity_switch(&fmu)?;
    let mut outputs = Vec::new();
    for s in &data.responses {
        outputs.extend(channel_sensitivities(&fmu, &s.channel.name(), names)?);
    }
    let mut sim = Simulator::for_record(&fmu, physics.parameters.clone(), data, "band").ok()?;
    let mut finite = true;
    sim.stream_switched(&[], &[], switch, &outputs, |values| {
        finite &= values.iter().all(|v| v.is_finite());
        each(values);
    })
    .ok()?;
    finite.then_some(())
}

/// NMSE % of `twin` on `data` after the transient, per measured channel in the record's order.
pub fn nmse_on(twin: &Twin, data: &Measurement, transient: f64) -> Result<Vec<f64>, RunError> {
    let prediction = run_twin(twin, data, |_, _| {})?;
    Ok(compare_prediction(twin, data, transient, prediction)?
        .comparison
        .nmse)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{synth_record, Scenario};
    use ::structure::{Excitation, Structure};

    /// The band's `J` from the FMU's forward sensitivities (one run) is the finite differences'
    /// (a run per parameter), on four storeys under a force at floor 2 and under ground motion,
    /// every floor measured: the two agree to the differences' own error (forward, step 1e-5
    /// of the value). Measured worst 1.4e-4 of the channel's largest |J| (force) and 8.7e-5
    /// (ground); the bar is 1e-3.
    #[test]
    fn sensitivities_give_the_finite_differences_jacobian() {
        for excitation in [Excitation::Force { floor: 2 }, Excitation::Base] {
            let structure = Structure {
                mass: vec![5.1, 4.8, 5.4, 4.5],
                damping: vec![3.2, 2.4, 1.9, 2.8],
                stiffness: vec![4100.0, 3900.0, 4300.0, 3600.0],
                excitation,
            };
            let mut twin = Twin::for_structure(&structure).expect("twin");
            let names: Vec<String> = structure.parameter_names();
            let values: Vec<f64> = [&structure.mass, &structure.damping, &structure.stiffness]
                .into_iter()
                .flatten()
                .copied()
                .collect();
            // As a calibrated twin holds them: every parameter set in the SSP.
            let physics = twin.component_mut(PHYSICS).expect("physics");
            for (name, v) in names.iter().zip(&values) {
                physics
                    .parameters
                    .insert(name.clone(), ParameterValue::Real(*v));
            }
            let scenario = Scenario {
                mass: structure.mass.clone(),
                damping: structure.damping.clone(),
                stiffness: structure.stiffness.clone(),
                excitation,
                duration: 10.0,
                ..Scenario::default()
            };
            let data = synth_record(&scenario).expect("record").0.measurement;
            let prediction = run_twin(&twin, &data, |_, _| {}).expect("run");
            let base = measured_columns(&data, &prediction).expect("every channel");
            let exact = sensitivity_columns(&twin, &data, &names).expect("sensitivities");
            let fd = finite_difference_columns(&twin, &data, &names, &values, &base).expect("fd");
            let mut worst: f64 = 0.0;
            for (j, name) in names.iter().enumerate() {
                for c in 0..data.responses.len() {
                    let scale = fd[j][c].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                    let err = exact[j][c]
                        .iter()
                        .zip(&fd[j][c])
                        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
                    assert!(scale > 0.0, "{name}: no sensitivity");
                    worst = worst.max(err / scale);
                }
            }
            assert!(worst < 1e-3, "{excitation:?}: worst {worst:e}");

            // A calibration's in process (`LinearFit`, the calibrated values set on the base):
            // the same predictions and sensitivities as the FMU's run, to rounding (bar 1e-9
            // of the channel's largest value).
            let mut fixed = twin.component(PHYSICS).expect("physics").parameters.clone();
            for name in &names {
                fixed.remove(name);
            }
            let fit = crate::twin::linear::LinearFit::new(
                &twin.component(PHYSICS).expect("physics").fmu_path,
                &fixed,
                &names,
            )
            .expect("the linear shear model");
            let channel_names: Vec<String> =
                data.responses.iter().map(|s| s.channel.name()).collect();
            let floors = fit
                .floors(&channel_names.iter().map(String::as_str).collect::<Vec<_>>())
                .expect("accelerometers");
            let (mut peak, mut peak_d, mut err, mut err_d) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            let p = names.len();
            fit.run(&values, &data, &floors, |k, v, dv| {
                for c in 0..floors.len() {
                    peak = peak.max(base[c][k].abs());
                    err = err.max((v[c] - base[c][k]).abs());
                    for j in 0..p {
                        peak_d = peak_d.max(exact[j][c][k].abs());
                        err_d = err_d.max((dv[c * p + j] - exact[j][c][k]).abs());
                    }
                }
            })
            .expect("valid values");
            assert!(
                err <= 1e-9 * peak,
                "{excitation:?}: predictions {err:e} of {peak:e}"
            );
            assert!(
                err_d <= 1e-9 * peak_d,
                "{excitation:?}: sensitivities {err_d:e} of {peak_d:e}"
            );

            // The streamed band (blocks of samples, the covariance's root) is `diag(J Σ Jᵀ)`
            // of these sensitivities, for a positive definite Σ (Cholesky) and for one of rank
            // 2 (eigenvectors), on 513 samples (two blocks and a part), streamed through FMI
            // and in process. Rounding only: the bar is 1e-9 of the channel's largest variance.
            let p = names.len();
            let scaled: Vec<f64> = values.iter().map(|v| 1e-2 * v).collect();
            let full = nalgebra::DMatrix::from_fn(p, p, |a, b| {
                let r = if a == b {
                    1.0
                } else {
                    0.3f64.powi(a.abs_diff(b) as i32)
                };
                r * scaled[a] * scaled[b]
            });
            let low = nalgebra::DMatrix::from_fn(p, p, |a, b| {
                let u = |i: usize| scaled[i] * ((i as f64) * 0.7).sin();
                let w = |i: usize| scaled[i] * ((i as f64) * 1.3).cos();
                u(a) * u(b) + 0.5 * w(a) * w(b)
            });
            for sigma in [full, low] {
                let band = sensitivity_band(&twin, &data, &names, &sigma).expect("band");
                // The same from the linear model in process (blocks of 256 samples).
                let in_process = crate::twin::linear::acceleration_band(
                    &twin,
                    &data,
                    &names,
                    &covariance_root(&sigma),
                )
                .expect("the twin is the linear shear model");
                for c in 0..data.responses.len() {
                    let want: Vec<f64> = (0..data.len())
                        .map(|k| {
                            let mut v = 0.0;
                            for a in 0..p {
                                for b in 0..p {
                                    v += exact[a][c][k] * sigma[(a, b)] * exact[b][c][k];
                                }
                            }
                            v
                        })
                        .collect();
                    let top = want.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                    assert_eq!(band[c].len(), want.len());
                    assert!(top > 0.0);
                    assert_eq!(in_process[c].len(), want.len());
                    for ((got, linear), want) in band[c].iter().zip(&in_process[c]).zip(&want) {
                        assert!((got - want).abs() <= 1e-9 * top, "{got} vs {want}");
                        assert!((linear - want).abs() <= 1e-9 * top, "{linear} vs {want}");
                    }
                }
            }
        }
    }

    /// `∂y/∂θ` as `[parameter][channel][sample]` from the streamed sensitivities.
    fn sensitivity_columns(
        twin: &Twin,
        data: &Measurement,
        names: &[String],
    ) -> Option<Vec<Vec<Vec<f64>>>> {
        let (p, channels) = (names.len(), data.responses.len());
        let mut jac = vec![vec![Vec::new(); channels]; p];
        stream_sensitivities(twin, data, names, |values| {
            for c in 0..channels {
                for (j, column) in jac.iter_mut().enumerate() {
                    column[c].push(values[c * p + j]);
                }
            }
        })?;
        Some(jac)
    }
}
