//! `twin train`: fit the Gaussian-process bias corrector (reference paper §4.2) on a record and
//! put it, connected behind the physics FMU, into the twin.
//!
//! The corrector FMU's own code builds the training set (`lagged_inputs`, the target form) and
//! fits the three GPs (`Floors::from_training`: type-II ML, the floors in parallel), so what is
//! trained here is exactly what the FMU computes when it runs. The fitted set, with its
//! hyperparameters, goes into a copy of the corrector FMU as `resources/training.json`.

use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;

use fmu_gp_corrector::{lagged_inputs, Floors, Sample, TargetForm, TrainingFile};

use crate::twin::data::Measurement;
use crate::twin::run::{run_twin, RunError};
use crate::twin::{
    find_fmu, Component, Connection, ParameterValue, Twin, TwinError, OUTPUTS, PHYSICS,
};

/// The corrector component's name and its FMU file in the twin.
pub const CORRECTOR: &str = "corrector";
pub const CORRECTOR_FMU: &str = "fmu_gp_corrector.fmu";

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Run(#[from] RunError),
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error("train: {0}")]
    Setup(String),
    #[error(transparent)]
    Options(#[from] crate::workflows::options::InvalidOption),
}

#[derive(Debug, Clone)]
pub struct TrainOptions {
    pub lags: usize,
    pub target: TargetForm,
    /// Seconds at the start of the record not used for training (the physics model starts at rest).
    pub transient: f64,
    /// Use every `stride`-th sample after the transient (1: all). A GP fit costs O(N³).
    pub stride: usize,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            lags: fmu_gp_corrector::DEFAULT_LAGS,
            target: TargetForm::Discrepancy,
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            stride: 1,
        }
    }
}

/// What training produced, for the report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TrainSummary {
    pub points: usize,
    pub lags: usize,
    pub inputs: usize,
    pub target: &'static str,
    /// Per floor: signal variance, noise variance, the three shortest length scales.
    pub hyperparameters: Vec<serde_json::Value>,
    pub seconds: f64,
}

/// The physics-only version of a twin (a trained twin's corrector taken out).
pub fn physics_only(twin: &Twin) -> Twin {
    let mut out = twin.duplicate();
    out.components.retain(|c| c.name != CORRECTOR);
    out.connections.retain(|c| {
        c.start_element.as_deref() != Some(CORRECTOR) && c.end_element.as_deref() != Some(CORRECTOR)
    });
    for output in OUTPUTS {
        if !out
            .connections
            .iter()
            .any(|c| c.end_element.is_none() && c.end_connector == output)
        {
            out.connections.push(Connection {
                start_element: Some(PHYSICS.into()),
                start_connector: output.into(),
                end_element: None,
                end_connector: output.into(),
            });
        }
    }
    out
}

/// The GP inputs (lags of `samples`) and targets after the transient, every `stride`-th sample,
/// and the three GPs fitted on them.
fn fit_floors(
    data: &Measurement,
    samples: &[Sample],
    physics: &[Vec<f64>; 3],
    options: &TrainOptions,
) -> Result<Floors, TrainError> {
    let inputs = lagged_inputs(samples, options.lags);
    let first = crate::evaluation::stats::first_after_transient(&data.time, options.transient)
        .max(options.lags);
    if data.len() <= first + 10 {
        return Err(TrainError::Setup(format!(
            "{}: too few samples after the {} s transient",
            data.path.display(),
            options.transient
        )));
    }
    let used: Vec<usize> = (first..data.len()).step_by(options.stride.max(1)).collect();
    let file = TrainingFile {
        lags: options.lags,
        target: options.target,
        inputs: used.iter().map(|&k| inputs[k].clone()).collect(),
        targets: used
            .iter()
            .map(|&k| [0, 1, 2].map(|f| options.target.target(data.acc(f)[k], physics[f][k])))
            .collect(),
        hyperparameters: None,
    };
    Floors::fit_training(&file)
        .map_err(|e| TrainError::Setup(format!("fitting the GPs ({} lags): {e}", options.lags)))
}

/// One candidate lag count and the fit it gave.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LagScore {
    pub lags: usize,
    /// Negative log marginal likelihood per floor at the type-II ML hyperparameters.
    pub nlml: [f64; 3],
    pub total: f64,
}

/// Choose the number of lags as the reference paper did: fit the three GPs for each candidate
/// `q` on the same samples and targets (only the inputs differ, so the marginal likelihoods are
/// comparable) and take the lowest total negative log marginal likelihood. Returns the scores,
/// best first.
pub fn select_lags(
    twin: &Twin,
    data: &Measurement,
    candidates: &[usize],
    options: &TrainOptions,
) -> Result<Vec<LagScore>, TrainError> {
    if candidates.is_empty() {
        return Err(TrainError::Setup("no lag count to choose from".into()));
    }
    let physics = physics_only(twin);
    let acc = run_twin(&physics, data, |_, _| {})?
        .accs()
        .map(<[f64]>::to_vec);
    let samples = physics_samples(data, &acc);
    // The same samples for every q: the transient cut at the largest q.
    let largest = candidates.iter().copied().max().unwrap_or(1);
    let mut scores = Vec::new();
    for &q in candidates {
        let floors = fit_floors(
            data,
            &samples,
            &acc,
            &TrainOptions {
                lags: q,
                transient: options.transient.max(largest as f64 * data.dt),
                ..options.clone()
            },
        )?;
        let nlml = [0, 1, 2].map(|f| match &floors.gps[f] {
            fmu_gp_corrector::FloorGp::Trained(gp) => gp.negative_log_marginal_likelihood(),
            fmu_gp_corrector::FloorGp::Prior(_) => f64::INFINITY,
        });
        scores.push(LagScore {
            lags: q,
            nlml,
            total: nlml.iter().sum(),
        });
    }
    scores.sort_by(|a, b| a.total.total_cmp(&b.total));
    Ok(scores)
}

fn physics_samples(data: &Measurement, acc: &[Vec<f64>; 3]) -> Vec<Sample> {
    (0..data.len())
        .map(|k| [acc[0][k], acc[1][k], acc[2][k], data.force()[k]])
        .collect()
}

/// Fit the corrector on `data` and return the twin with it.
pub fn train(
    twin: &Twin,
    data: &Measurement,
    options: &TrainOptions,
) -> Result<(Twin, TrainSummary), TrainError> {
    let started = std::time::Instant::now();
    let physics = physics_only(twin);
    let acc = run_twin(&physics, data, |_, _| {})?
        .accs()
        .map(<[f64]>::to_vec);
    let samples = physics_samples(data, &acc);
    let floors = fit_floors(data, &samples, &acc, options)?;
    let trained = floors.to_training_file(options.lags, options.target);

    let summary = TrainSummary {
        points: trained.inputs.len(),
        lags: options.lags,
        inputs: trained.input_dimension(),
        target: options.target.name(),
        hyperparameters: trained
            .hyperparameters
            .iter()
            .flatten()
            .map(|h| {
                let mut ls = h.length_scales.clone();
                ls.sort_by(f64::total_cmp);
                serde_json::json!({"signal_variance": h.signal_variance, "noise_variance": h.noise_variance, "shortest_length_scales": &ls[..ls.len().min(3)]})
            })
            .collect(),
        seconds: started.elapsed().as_secs_f64(),
    };

    Ok((with_corrector(twin, &trained)?, summary))
}

/// `twin`'s physics with a corrector behind it that carries `trained` (training set and
/// hyperparameters) in a copy of the corrector FMU: its outputs become the twin's `acc1..3`,
/// `latent_var1..3` and `sd1..3`. A corrector already in `twin` is replaced.
pub fn with_corrector(twin: &Twin, trained: &TrainingFile) -> Result<Twin, TrainError> {
    let physics = physics_only(twin);
    // A copy of the corrector FMU carrying the training set.
    let scratch = tempfile::Builder::new()
        .prefix("twin-train-")
        .tempdir()
        .map_err(|e| TrainError::Setup(format!("temporary directory: {e}")))?;
    let fmu_path = scratch.path().join(CORRECTOR_FMU);
    let json = serde_json::to_vec(&trained)
        .map_err(|e| TrainError::Setup(format!("training set: {e}")))?;
    with_resource(
        &find_fmu(CORRECTOR_FMU)?,
        &fmu_path,
        "resources/training.json",
        &json,
    )?;

    let mut out = physics.duplicate();
    out.keep_alive(Arc::new(scratch));
    let mut parameters = std::collections::BTreeMap::new();
    parameters.insert(
        "lags".to_owned(),
        ParameterValue::Integer(trained.lags as i32),
    );
    parameters.insert(
        "target".to_owned(),
        ParameterValue::Integer(trained.target.code()),
    );
    out.components.push(Component {
        name: CORRECTOR.into(),
        fmu_name: CORRECTOR_FMU.into(),
        fmu_path,
        parameters,
    });
    // The corrector's outputs replace the physics accelerations as the twin's outputs.
    out.connections
        .retain(|c| !(c.end_element.is_none() && OUTPUTS.contains(&c.end_connector.as_str())));
    let link = |from: Option<&str>, a: &str, to: Option<&str>, b: &str| Connection {
        start_element: from.map(str::to_owned),
        start_connector: a.into(),
        end_element: to.map(str::to_owned),
        end_connector: b.into(),
    };
    out.connections
        .push(link(None, "force", Some(CORRECTOR), "force"));
    for f in 1..=3 {
        out.connections.push(link(
            Some(PHYSICS),
            &format!("acc{f}"),
            Some(CORRECTOR),
            &format!("physics_acc{f}"),
        ));
        out.connections.push(link(
            Some(CORRECTOR),
            &format!("acc{f}"),
            None,
            &format!("acc{f}"),
        ));
        out.connections.push(link(
            Some(CORRECTOR),
            &format!("latent_var{f}"),
            None,
            &format!("latent_var{f}"),
        ));
        out.connections.push(link(
            Some(CORRECTOR),
            &format!("sd{f}"),
            None,
            &format!("sd{f}"),
        ));
    }
    Ok(out)
}

/// Copy the FMU at `source` to `target` with one resource file added (or replaced).
fn with_resource(source: &Path, target: &Path, name: &str, bytes: &[u8]) -> Result<(), TrainError> {
    let bad = |m: String| TrainError::Setup(format!("{}: {m}", source.display()));
    let file = std::fs::File::open(source).map_err(|e| bad(e.to_string()))?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| bad(e.to_string()))?;
    let out = std::fs::File::create(target).map_err(|e| bad(e.to_string()))?;
    let mut zip = zip::ZipWriter::new(out);
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(|e| bad(e.to_string()))?;
        if entry.name() == name || entry.is_dir() {
            continue;
        }
        let options =
            zip::write::SimpleFileOptions::default().compression_method(entry.compression());
        let entry_name = entry.name().to_owned();
        let mut content = Vec::new();
        entry
            .read_to_end(&mut content)
            .map_err(|e| bad(e.to_string()))?;
        zip.start_file(entry_name, options)
            .map_err(|e| bad(e.to_string()))?;
        zip.write_all(&content).map_err(|e| bad(e.to_string()))?;
    }
    zip.start_file(
        name,
        zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated),
    )
    .map_err(|e| bad(e.to_string()))?;
    zip.write_all(bytes).map_err(|e| bad(e.to_string()))?;
    zip.finish().map_err(|e| bad(e.to_string()))?;
    Ok(())
}

/// `--selection-stride`'s default: the lag selection's fits on every 4th sample.
pub const SELECTION_STRIDE: usize = 4;

impl TrainOptions {
    pub fn validate(&self) -> Result<(), crate::workflows::options::InvalidOption> {
        use crate::workflows::options::InvalidOption;
        if self.stride == 0 {
            return Err(InvalidOption("--stride must be at least 1".into()));
        }
        crate::workflows::options::check_transient(self.transient)
    }
}

/// `--select-lags Q,…` with `--selection-stride`: choose the lags among `candidates`.
#[derive(Debug, Clone, PartialEq)]
pub struct LagSelection {
    pub candidates: Vec<usize>,
    pub stride: usize,
}

impl LagSelection {
    pub fn validate(&self) -> Result<(), crate::workflows::options::InvalidOption> {
        use crate::workflows::options::InvalidOption;
        if self
            .candidates
            .iter()
            .any(|&q| q == 0 || q > fmu_gp_corrector::training::MAX_LAGS)
        {
            return Err(InvalidOption(format!(
                "--select-lags: each count must be in 1..={}, got {:?}",
                fmu_gp_corrector::training::MAX_LAGS,
                self.candidates
            )));
        }
        if self.stride == 0 {
            return Err(InvalidOption(
                "--selection-stride must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// What `twin train` computes: the twin with its corrector, the training's summary, the lag
/// selection's scores (best first; empty without one) and the corrected twin's NMSE % per
/// floor on the training record.
pub struct Trained {
    pub twin: Twin,
    pub summary: TrainSummary,
    pub selection: Vec<LagScore>,
    pub nmse: [f64; 3],
}

/// `twin train` as a whole: the lags chosen first when `selection` is given (overriding
/// `options.lags`), the corrector trained, the corrected twin's NMSE on the record.
pub fn train_selected(
    twin: &Twin,
    data: &Measurement,
    options: &TrainOptions,
    selection: Option<&LagSelection>,
) -> Result<Trained, TrainError> {
    options.validate()?;
    let mut options = options.clone();
    let mut scores = Vec::new();
    if let Some(s) = selection {
        s.validate()?;
        scores = select_lags(
            twin,
            data,
            &s.candidates,
            &TrainOptions {
                stride: s.stride,
                ..options.clone()
            },
        )?;
        options.lags = scores[0].lags;
    }
    let (trained, summary) = train(twin, data, &options)?;
    let nmse = crate::twin::run::nmse_on(&trained, data, options.transient)?;
    Ok(Trained {
        twin: trained,
        summary,
        selection: scores,
        nmse,
    })
}
