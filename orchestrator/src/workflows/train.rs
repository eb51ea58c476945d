//! `twin train`: fit the Gaussian-process bias corrector (reference paper §4.2) on a record and
//! put it, connected behind the physics FMU, into the twin.
//!
//! Any building and any measured channels: the corrector's layout is the record's response
//! channels (`acc<i>`, `vel<i>`, `disp<i>`) and its excitation (`force` or `ground_acc`), one GP
//! per channel whose target is that channel's discrepancy (or measured value) in its own
//! quantity, its inputs lags of the physics predictions of the channel and its nearest measured
//! neighbours and of the excitation (`fmu_gp_corrector::layout`: at most 4 (q + 1) inputs). On
//! the paper's rig (force, acc1..3) that is the three GPs on all four columns, as always.
//!
//! The corrector FMU's own code builds the training set (`lagged_inputs`, the target form) and
//! fits the GPs (`Floors::from_training`: type-II ML, the channels in parallel), so what is
//! trained here is exactly what the FMU computes when it runs. The fitted set, with its
//! hyperparameters and layout, goes into a copy of the corrector FMU as
//! `resources/training.json`, from which the FMU takes its variables at instantiation.

use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;

use ::structure::channel::{Channel, ExcitationKind};
use fmu_gp_corrector::layout::band_name;
use fmu_gp_corrector::{lagged_inputs, Floors, Layout, LayoutTraining, TargetForm};

use crate::twin::data::Measurement;
use crate::twin::run::{compare_prediction, run_twin, Prediction, RunError};
use crate::twin::{find_fmu, Component, Connection, ParameterValue, Twin, TwinError, PHYSICS};

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
    /// The largest input dimension of a channel's GP.
    pub inputs: usize,
    pub target: &'static str,
    /// Per channel (the layout's order): signal variance, noise variance, the three shortest
    /// length scales.
    pub hyperparameters: Vec<serde_json::Value>,
    pub seconds: f64,
}

/// The physics-only version of a twin (a trained twin's corrector taken out): the channels the
/// corrector gave out are the physics component's again.
pub fn physics_only(twin: &Twin) -> Twin {
    let mut out = twin.duplicate();
    let corrected: Vec<String> = out
        .connections
        .iter()
        .filter(|c| {
            c.start_element.as_deref() == Some(CORRECTOR)
                && c.end_element.is_none()
                && matches!(
                    Channel::parse(&c.end_connector),
                    Some(Channel::Response { .. })
                )
        })
        .map(|c| c.end_connector.clone())
        .collect();
    out.components.retain(|c| c.name != CORRECTOR);
    out.connections.retain(|c| {
        c.start_element.as_deref() != Some(CORRECTOR) && c.end_element.as_deref() != Some(CORRECTOR)
    });
    for output in corrected {
        if !out
            .connections
            .iter()
            .any(|c| c.end_element.is_none() && c.end_connector == output)
        {
            out.connections.push(Connection {
                start_element: Some(PHYSICS.into()),
                start_connector: output.clone(),
                end_element: None,
                end_connector: output,
            });
        }
    }
    out
}

/// The corrector's layout for a record: its response channels and its excitation.
pub fn layout_of(data: &Measurement) -> Result<Layout, TrainError> {
    let excitation = match data.excitation.channel {
        Channel::Excitation(kind) => kind,
        _ => ExcitationKind::Force,
    };
    Layout {
        channels: data.responses.iter().map(|s| s.channel).collect(),
        excitation,
    }
    .checked()
    .map_err(|e| TrainError::Setup(format!("{}: {e}", data.path.display())))
}

/// A record's channels as the corrector sees them: per channel in the layout's order, the
/// physics prediction and the measured values (SI), and per sample the physics predictions
/// followed by the excitation.
pub struct Channels {
    pub layout: Layout,
    pub physics: Vec<Vec<f64>>,
    pub measured: Vec<Vec<f64>>,
    pub samples: Vec<Vec<f64>>,
}

impl Channels {
    /// From a physics-only prediction of `data`.
    pub fn of(data: &Measurement, prediction: &Prediction) -> Result<Channels, TrainError> {
        let layout = layout_of(data)?;
        let mut physics = Vec::new();
        let mut measured = Vec::new();
        for &c in &layout.channels {
            let p = prediction.get(c).ok_or_else(|| {
                TrainError::Setup(format!("the physics run did not predict {}", c.name()))
            })?;
            physics.push(p.values.clone());
            measured.push(data.channel(c).map(<[f64]>::to_vec).ok_or_else(|| {
                TrainError::Setup(format!("{}: no column {}", data.path.display(), c.name()))
            })?);
        }
        let samples = (0..data.len())
            .map(|k| {
                physics
                    .iter()
                    .map(|p| p[k])
                    .chain(std::iter::once(data.excitation.values[k]))
                    .collect()
            })
            .collect();
        Ok(Channels {
            layout,
            physics,
            measured,
            samples,
        })
    }

    /// The GP targets of sample `k`, one per channel.
    pub fn targets(&self, k: usize, target: TargetForm) -> Vec<f64> {
        self.measured
            .iter()
            .zip(&self.physics)
            .map(|(m, p)| target.target(m[k], p[k]))
            .collect()
    }
}

/// The GP inputs (lags of the samples) and targets after the transient, every `stride`-th
/// sample, and the channels' GPs fitted on them.
fn fit_floors(
    data: &Measurement,
    channels: &Channels,
    options: &TrainOptions,
) -> Result<Floors, TrainError> {
    let inputs = lagged_inputs(&channels.samples, options.lags);
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
    let file = LayoutTraining {
        channels: channels.layout.names(),
        excitation: channels.layout.excitation_name(),
        lags: options.lags,
        target: options.target,
        inputs: used.iter().map(|&k| inputs[k].clone()).collect(),
        targets: used
            .iter()
            .map(|&k| channels.targets(k, options.target))
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
    /// Negative log marginal likelihood per channel (the layout's order) at the type-II ML
    /// hyperparameters.
    pub nlml: Vec<f64>,
    pub total: f64,
}

/// Choose the number of lags as the reference paper did: fit the channels' GPs for each candidate
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
    let prediction = run_twin(&physics, data, |_, _| {})?;
    let channels = Channels::of(data, &prediction)?;
    // The same samples for every q: the transient cut at the largest q.
    let largest = candidates.iter().copied().max().unwrap_or(1);
    let mut scores = Vec::new();
    for &q in candidates {
        let floors = fit_floors(
            data,
            &channels,
            &TrainOptions {
                lags: q,
                transient: options.transient.max(largest as f64 * data.dt),
                ..options.clone()
            },
        )?;
        let nlml: Vec<f64> = floors
            .gps
            .iter()
            .map(|g| match g {
                fmu_gp_corrector::FloorGp::Trained(gp) => gp.negative_log_marginal_likelihood(),
                fmu_gp_corrector::FloorGp::Prior(_) => f64::INFINITY,
            })
            .collect();
        scores.push(LagScore {
            lags: q,
            total: nlml.iter().sum(),
            nlml,
        });
    }
    scores.sort_by(|a, b| a.total.total_cmp(&b.total));
    Ok(scores)
}

/// Fit the corrector on `data` and return the twin with it.
pub fn train(
    twin: &Twin,
    data: &Measurement,
    options: &TrainOptions,
) -> Result<(Twin, TrainSummary), TrainError> {
    train_with_physics(twin, data, options).map(|(t, s, _)| (t, s))
}

/// [`train`], also giving the physics-only prediction of `data` it trained on.
fn train_with_physics(
    twin: &Twin,
    data: &Measurement,
    options: &TrainOptions,
) -> Result<(Twin, TrainSummary, Prediction), TrainError> {
    let started = std::time::Instant::now();
    let physics = physics_only(twin);
    let prediction = run_twin(&physics, data, |_, _| {})?;
    let channels = Channels::of(data, &prediction)?;
    let floors = fit_floors(data, &channels, options)?;
    let trained = floors.to_training(options.target);
    let layout = &channels.layout;

    let summary = TrainSummary {
        points: trained.inputs.len(),
        lags: options.lags,
        inputs: (0..layout.channels.len())
            .map(|j| layout.input_dimension_of(j, options.lags))
            .max()
            .unwrap_or(0),
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

    Ok((with_corrector(twin, &trained)?, summary, prediction))
}

/// `twin`'s physics with a corrector behind it that carries `trained` (training set,
/// hyperparameters and layout) in a copy of the corrector FMU: the excitation goes in, each
/// channel's physics prediction goes in, and its corrected value, latent variance and
/// predictive sd (`acc<i>`, `latent_var<i>`, `sd<i>`; `vel2`, `latent_var_vel2`, `sd_vel2`)
/// become the twin's outputs. A corrector already in `twin` is replaced.
pub fn with_corrector(twin: &Twin, trained: &LayoutTraining) -> Result<Twin, TrainError> {
    let layout = trained
        .layout()
        .map_err(|e| TrainError::Setup(format!("training set: {e}")))?;
    let physics = physics_only(twin);
    // A copy of the corrector FMU carrying the training set.
    let scratch = tempfile::Builder::new()
        .prefix("twin-train-")
        .tempdir()
        .map_err(|e| TrainError::Setup(format!("temporary directory: {e}")))?;
    let fmu_path = scratch.path().join(CORRECTOR_FMU);
    // The paper rig's file in its own format (no channels, no excitation).
    let rig = trained.to_rig();
    let json = match &rig {
        Some(rig) => serde_json::to_vec(rig),
        None => serde_json::to_vec(&trained),
    }
    .map_err(|e| TrainError::Setup(format!("training set: {e}")))?;
    // Another layout than the rig's: the modelDescription of its variable table, the one the
    // library serves when it reads the training file at instantiation.
    let xml = rig.is_none().then(|| {
        fmu_gp_corrector::variables::table(&layout)
            .to_model_description_xml()
            .into_bytes()
    });
    let mut entries = vec![("resources/training.json", json.as_slice())];
    if let Some(xml) = &xml {
        entries.push(("modelDescription.xml", xml.as_slice()));
    }
    with_resources(&find_fmu(CORRECTOR_FMU)?, &fmu_path, &entries)?;

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
    // The corrector's outputs replace the physics predictions as the twin's outputs.
    let names = layout.names();
    out.connections
        .retain(|c| !(c.end_element.is_none() && names.contains(&c.end_connector)));
    let link = |from: Option<&str>, a: &str, to: Option<&str>, b: &str| Connection {
        start_element: from.map(str::to_owned),
        start_connector: a.into(),
        end_element: to.map(str::to_owned),
        end_connector: b.into(),
    };
    let excitation = layout.excitation_name();
    out.connections
        .push(link(None, &excitation, Some(CORRECTOR), &excitation));
    for c in &layout.channels {
        let name = c.name();
        out.connections.push(link(
            Some(PHYSICS),
            &name,
            Some(CORRECTOR),
            &format!("physics_{name}"),
        ));
        out.connections
            .push(link(Some(CORRECTOR), &name, None, &name));
        for prefix in ["latent_var", "sd"] {
            let band = band_name(prefix, c);
            out.connections
                .push(link(Some(CORRECTOR), &band, None, &band));
        }
    }
    Ok(out)
}

/// Copy the FMU at `source` to `target` with the files `entries` (name, bytes) added or
/// replaced.
fn with_resources(
    source: &Path,
    target: &Path,
    entries: &[(&str, &[u8])],
) -> Result<(), TrainError> {
    let bad = |m: String| TrainError::Setup(format!("{}: {m}", source.display()));
    let file = std::fs::File::open(source).map_err(|e| bad(e.to_string()))?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| bad(e.to_string()))?;
    let out = std::fs::File::create(target).map_err(|e| bad(e.to_string()))?;
    let mut zip = zip::ZipWriter::new(out);
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).map_err(|e| bad(e.to_string()))?;
        if entries.iter().any(|(name, _)| entry.name() == *name) || entry.is_dir() {
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
    for (name, bytes) in entries {
        zip.start_file(
            *name,
            zip::write::SimpleFileOptions::default()
                .compression_method(zip::CompressionMethod::Deflated),
        )
        .map_err(|e| bad(e.to_string()))?;
        zip.write_all(bytes).map_err(|e| bad(e.to_string()))?;
    }
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
/// selection's scores (best first; empty without one), the corrected twin's NMSE % per
/// channel on the training record and the physics alone's.
pub struct Trained {
    pub twin: Twin,
    pub summary: TrainSummary,
    pub selection: Vec<LagScore>,
    /// The corrector's channels, in its order (that of `nmse` and the per-channel lists).
    pub channels: Vec<String>,
    pub nmse: Vec<f64>,
    pub nmse_physics: Vec<f64>,
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
    let (trained, summary, physics) = train_with_physics(twin, data, &options)?;
    let layout = layout_of(data)?;
    let nmse_per_channel = |twin: &Twin, prediction: Prediction| -> Result<Vec<f64>, TrainError> {
        let compared = compare_prediction(twin, data, options.transient, prediction)?;
        Ok(layout
            .channels
            .iter()
            .map(|&c| compared.comparison.nmse_of(c).unwrap_or(f64::NAN))
            .collect())
    };
    let nmse_physics = nmse_per_channel(&physics_only(twin), physics)?;
    let corrected = run_twin(&trained, data, |_, _| {})?;
    let nmse = nmse_per_channel(&trained, corrected)?;
    Ok(Trained {
        twin: trained,
        summary,
        selection: scores,
        channels: layout.names(),
        nmse,
        nmse_physics,
    })
}
