//! Running a twin on a measurement: the system of the twin's FMUs, the measured force replayed
//! as its input, the accelerations recorded.

use std::time::{Duration, Instant};

use crate::cosim::master::{Clock, Recorder};
use crate::evaluation::compare::{compare, CompareOptions, Comparison};
use crate::evaluation::stats::variance;
use crate::twin::data::Measurement;
use crate::twin::system::{SystemBuilder, SystemError};
use crate::twin::{ParameterValue, Twin, OUTPUTS, PHYSICS};

/// A run's error is the system builder's: the twin, the master or the wiring.
pub type RunError = SystemError;

/// Predicted accelerations at every sample of the measurement.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub time: Vec<f64>,
    pub acc: [Vec<f64>; 3],
    /// The corrector's latent variance V(f) per floor, when the twin has a corrector.
    pub latent_var: Option<[Vec<f64>; 3]>,
    /// The corrector's predictive standard deviation per floor, likewise.
    pub sd: Option<[Vec<f64>; 3]>,
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

/// Run `twin` on `data`'s force (the control force, if the data has a `control` column and the
/// twin takes it, is replayed too).
pub fn run_twin(
    twin: &Twin,
    data: &Measurement,
    mut progress: impl FnMut(u64, u64),
) -> Result<Prediction, RunError> {
    let start = data.time[0];
    let mut inputs = vec![("force", data.force().to_vec())];
    if let Some(control) = data.extra.get("control") {
        inputs.push(("control_force", control.clone()));
    }
    let builder = SystemBuilder::open(twin)?;
    let mut running = builder.build(start, inputs)?;
    let system_outputs = twin.system_outputs();
    let optional = [
        "latent_var1",
        "latent_var2",
        "latent_var3",
        "sd1",
        "sd2",
        "sd3",
    ];
    let mut watched = Vec::new();
    for output in OUTPUTS.iter().chain(
        optional
            .iter()
            .filter(|o| system_outputs.iter().any(|s| s == *o)),
    ) {
        watched.push(((*output).to_owned(), running.system_output(twin, output)?));
    }
    let mut recorder = Recorder::new(watched);
    let clock = Clock::new(start, data.dt, (data.len() - 1) as u64);
    running
        .system
        .run(clock, &mut [&mut recorder], &mut progress)?;
    drop(running);
    let column = |name: &str| recorder.column(name).map(<[f64]>::to_vec);
    let triple = |prefix: &str| -> Option<[Vec<f64>; 3]> {
        Some([
            column(&format!("{prefix}1"))?,
            column(&format!("{prefix}2"))?,
            column(&format!("{prefix}3"))?,
        ])
    };
    let acc = triple("acc")
        .ok_or_else(|| RunError::Wiring("the accelerations were not recorded".into()))?;
    Ok(Prediction {
        time: recorder.time.clone(),
        acc,
        latent_var: triple("latent_var"),
        sd: triple("sd"),
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

/// A twin run on a record and compared with it.
pub struct Compared {
    pub prediction: Prediction,
    pub comparison: Comparison,
    /// The ±3σ band's noise variances: the twin's, else [`PRIOR_NOISE_FRACTION`] of the record's.
    pub noise_variance: [f64; 3],
    pub noise_source: &'static str,
    /// Per floor and sample, the prediction's variance from the twin's parameter uncertainty
    /// (`J Σ Jᵀ`), when the twin has a posterior covariance and no corrector band.
    pub parameter_variance: Option<[Vec<f64>; 3]>,
    /// NMSE per floor (%) the band explains on this record after the transient: noise alone,
    /// and the parameter uncertainty's share (`100 · mean(J Σ Jᵀ) / var ÿ`).
    pub noise_nmse: [f64; 3],
    pub band_nmse: [f64; 3],
    pub tolerance: Tolerance,
}

/// Run `twin` on `data` and compare the accelerations after `transient`: the one sequence
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
    let prediction = run_twin(twin, data, progress)?;
    let parameter_variance = match prediction.sd {
        Some(_) => None,
        None => parameter_variance(twin, data, &prediction.acc)?,
    };
    Ok(compare_with(
        twin,
        data,
        transient,
        tolerance,
        prediction,
        parameter_variance,
    ))
}

/// Compare a prediction the twin made some other way (e.g. in a closed loop) with `data`, as
/// [`run_and_compare`] does, but with the noise band alone (the parameter sensitivities are the
/// open loop's).
pub fn compare_prediction(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    prediction: Prediction,
) -> Compared {
    compare_with(twin, data, transient, None, prediction, None)
}

/// Compare `prediction` with `data`: the band's variance per sample is the noise variance plus
/// `parameter_variance` (or the corrector's predictive sd when the twin has one).
pub fn compare_with(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    tolerance: Option<f64>,
    prediction: Prediction,
    parameter_variance: Option<[Vec<f64>; 3]>,
) -> Compared {
    let (noise_variance, noise_source) = match twin.noise_variance {
        Some(v) => (v, "twin (calibrated)"),
        None => (
            [0, 1, 2].map(|f| PRIOR_NOISE_FRACTION * variance(&data.acc(f))),
            "prior: 2 % of the measured variance",
        ),
    };
    let tolerance = Tolerance::resolve(twin, tolerance);
    let options = CompareOptions {
        transient,
        tolerance: tolerance.value,
        ..CompareOptions::default()
    };
    let band_sd: Option<[Vec<f64>; 3]> = match (&prediction.sd, &parameter_variance) {
        (Some(sd), _) => Some(sd.clone()),
        (None, Some(pv)) => Some([0, 1, 2].map(|f| {
            pv[f]
                .iter()
                .map(|v| (noise_variance[f] + v.max(0.0)).sqrt())
                .collect()
        })),
        (None, None) => None,
    };
    let comparison = compare(
        &data.time,
        &data.accs().map(<[f64]>::to_vec),
        &prediction.acc,
        noise_variance,
        band_sd.as_ref(),
        options,
    );
    let first = comparison.first;
    let record_var = [0, 1, 2].map(|f| variance(&data.acc(f)[first..]));
    let noise_nmse = [0, 1, 2].map(|f| 100.0 * noise_variance[f] / record_var[f]);
    let band_nmse = [0, 1, 2].map(|f| match &parameter_variance {
        Some(pv) if pv[f].len() > first => {
            let tail = &pv[f][first..];
            100.0 * tail.iter().sum::<f64>() / tail.len() as f64 / record_var[f]
        }
        _ => 0.0,
    });
    Compared {
        prediction,
        comparison,
        noise_variance,
        noise_source,
        parameter_variance,
        noise_nmse,
        band_nmse,
        tolerance,
    }
}

/// The prediction's variance per floor and sample from the twin's parameter uncertainty,
/// `J Σ Jᵀ`: `J` by forward differences through FMI (the twin run once more per calibrated
/// parameter, the runs spread over the cores), `Σ` the twin's posterior covariance. None when the
/// twin has no covariance, or its physics does not hold a value for every parameter of it.
pub fn parameter_variance(
    twin: &Twin,
    data: &Measurement,
    acc: &[Vec<f64>; 3],
) -> Result<Option<[Vec<f64>; 3]>, RunError> {
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
    // The step: 1e-5 of the value, far inside the posterior's width for any usable calibration
    // and far above rounding, so `J` is the derivative and the band exactly linear in `Σ`.
    let steps: Vec<f64> = values.iter().map(|v| (1e-5 * v.abs()).max(1e-12)).collect();
    let sensitivity = |j: usize| -> Result<[Vec<f64>; 3], RunError> {
        let mut shifted = twin.duplicate();
        if let Some(c) = shifted.component_mut(PHYSICS) {
            c.parameters.insert(
                cov.names[j].clone(),
                ParameterValue::Real(values[j] + steps[j]),
            );
        }
        let run = run_twin(&shifted, data, |_, _| {})?;
        Ok([0, 1, 2].map(|f| {
            run.acc[f]
                .iter()
                .zip(&acc[f])
                .map(|(a, b)| (a - b) / steps[j])
                .collect()
        }))
    };
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .clamp(1, p);
    let results: Vec<Vec<(usize, Result<[Vec<f64>; 3], RunError>)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let sensitivity = &sensitivity;
                scope.spawn(move || {
                    (t..p)
                        .step_by(threads)
                        .map(|j| (j, sensitivity(j)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a sensitivity thread panicked"))
            .collect()
    });
    let mut jac: Vec<Option<[Vec<f64>; 3]>> = (0..p).map(|_| None).collect();
    for (j, r) in results.into_iter().flatten() {
        jac[j] = Some(r?);
    }
    let jac: Vec<[Vec<f64>; 3]> = jac.into_iter().map(|j| j.expect("every run")).collect();
    let n = acc[0].len();
    Ok(Some([0, 1, 2].map(|f| {
        (0..n)
            .map(|k| {
                let mut v = 0.0;
                for a in 0..p {
                    let ja = jac[a][f][k];
                    for b in 0..p {
                        v += ja * cov.matrix[a][b] * jac[b][f][k];
                    }
                }
                v.max(0.0)
            })
            .collect()
    })))
}

/// NMSE per floor of `twin` on `data` after the transient.
pub fn nmse_on(twin: &Twin, data: &Measurement, transient: f64) -> Result<[f64; 3], RunError> {
    let prediction = run_twin(twin, data, |_, _| {})?;
    Ok(compare_prediction(twin, data, transient, prediction)
        .comparison
        .nmse)
}
