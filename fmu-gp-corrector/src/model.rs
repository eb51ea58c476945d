//! The corrector: one GP per measured channel (the paper's rig: three, one per floor) on lags of
//! the physics predictions and the excitation ([`crate::layout`] says which), their training
//! sets, learning and refitting.

mod floors;

use std::path::{Path, PathBuf};

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
/// The GP types the floors' API hands out or takes, and what follows a floor's GP
/// ([`TrackedPoints`]), for hosts that drive the floors in process (`twin learn`).
pub use numerics::gp::{FitOptions, FitReport, GaussianProcess, Inputs, TrackedPoints, Tracking};
use numerics::gp::{GpError, Hyperparameters, PointPrediction};
use serde::{Deserialize, Serialize};

use crate::lags::{input_dimension, LagBuffer};
use crate::layout::Layout;
use crate::training::{
    FloorHyperparameters, LayoutTraining, TargetForm, TrainingFile, MAX_LAGS, MAX_TRAINING_POINTS,
};
use crate::variables::*;
use crate::CorrectorError;
pub use floors::{per_channel, FloorGp, Floors};

/// q = 9: the paper's choice (lowest negative log marginal likelihood on its dataset one).
pub const DEFAULT_LAGS: usize = 9;

/// Refit after 25 learned points: the spacing of the paper's uniform query mode, and often
/// enough that the hyperparameters follow a changing training set while the refits (warm-started,
/// one L-BFGS run, `O(n³)` per iteration) stay a small share of the steps' cost.
pub const DEFAULT_REFIT_EVERY: u32 = 25;

/// Hyperparameters of a GP without data, scaled to the example records (accelerations of about
/// 0.1 m/s² standard deviation, forces of about 0.25 N): σ_f = 0.1 m/s², σ_n = 0.01 m/s², and a
/// length scale of 1 in every input, several of its standard deviations.
pub const INITIAL_SIGNAL_VARIANCE: f64 = 1e-2;
pub const INITIAL_NOISE_VARIANCE: f64 = 1e-4;
pub const INITIAL_LENGTH_SCALE: f64 = 1.0;

/// The file looked for in the FMU's `resources/` when `training_path` is empty.
pub const BUNDLED_TRAINING_FILE: &str = "training.json";

/// The fit of a training set that comes without hyperparameters: the numerics' defaults
/// (three seeded L-BFGS starts from data-based values).
pub fn initial_fit_options() -> FitOptions {
    FitOptions::default()
}

/// A scheduled refit: one L-BFGS run from the current hyperparameters, at most 100 iterations.
pub fn refit_options() -> FitOptions {
    FitOptions {
        starts: 1,
        max_iterations: 100,
        ..FitOptions::default()
    }
}

/// The fixed and tunable parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    pub lags: usize,
    pub target: TargetForm,
    pub refit_every: u32,
    /// The most training points a floor keeps while learning.
    #[serde(default = "default_budget")]
    pub budget: usize,
    pub training_path: String,
    pub initial_signal_variance: f64,
    pub initial_noise_variance: f64,
    pub initial_length_scale: f64,
}

fn default_budget() -> usize {
    MAX_TRAINING_POINTS
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            lags: DEFAULT_LAGS,
            target: TargetForm::Discrepancy,
            refit_every: DEFAULT_REFIT_EVERY,
            budget: MAX_TRAINING_POINTS,
            training_path: String::new(),
            initial_signal_variance: INITIAL_SIGNAL_VARIANCE,
            initial_noise_variance: INITIAL_NOISE_VARIANCE,
            initial_length_scale: INITIAL_LENGTH_SCALE,
        }
    }
}

impl Settings {
    /// The `initial_*` hyperparameters of a paper rig's GP.
    pub fn initial_hyperparameters(&self) -> Result<Hyperparameters, GpError> {
        self.initial_hyperparameters_of(input_dimension(self.lags))
    }

    /// The `initial_*` hyperparameters of a GP of `dimension` inputs.
    pub fn initial_hyperparameters_of(&self, dimension: usize) -> Result<Hyperparameters, GpError> {
        Hyperparameters::new(
            &vec![self.initial_length_scale; dimension],
            self.initial_signal_variance,
            self.initial_noise_variance,
        )
    }
}

/// The current values of the inputs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CorrectorInputs {
    /// The physics prediction of each measured channel, in the layout's order.
    pub physics: Vec<f64>,
    /// The excitation: `force` (N) or `ground_acc` (m/s²).
    pub excitation: f64,
    pub measured: Vec<f64>,
    pub learn: bool,
}

impl CorrectorInputs {
    /// Zeros for the channels of `layout`.
    pub fn for_layout(layout: &Layout) -> Self {
        let m = layout.channels.len();
        CorrectorInputs {
            physics: vec![0.0; m],
            excitation: 0.0,
            measured: vec![0.0; m],
            learn: false,
        }
    }

    /// The current sample: the physics predictions, then the excitation.
    pub fn sample(&self) -> Vec<f64> {
        let mut s = self.physics.clone();
        s.push(self.excitation);
        s
    }
}

pub fn to_gp_hyperparameters(set: &FloorHyperparameters) -> Result<Hyperparameters, GpError> {
    Hyperparameters::new(&set.length_scales, set.signal_variance, set.noise_variance)
}

/// The GP corrector FMU's model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GpCorrector {
    pub settings: Settings,
    /// The channels and excitation, fixed at instantiation.
    pub layout: Layout,
    pub inputs: CorrectorInputs,
    /// The FMU's unpacked `resources/` folder, when the host named one.
    pub resource_dir: Option<PathBuf>,
    /// `resources/training.json`, read and checked at instantiation; dropped once initialized.
    pub bundled: Option<(PathBuf, LayoutTraining)>,
    /// The GPs: built from the training data on first need (an output read in initialization
    /// mode, or leaving it), cleared when a parameter they depend on changes.
    pub floors: Option<Floors>,
    /// The samples before the current one.
    pub history: LagBuffer,
    /// Predictions at the current lag vector, until an input or the GPs change.
    #[serde(skip)]
    cache: Option<Vec<PointPrediction>>,
    /// The layout's variable table.
    #[serde(skip)]
    table: Option<&'static ModelInfo>,
}

impl GpCorrector {
    /// A corrector of the paper's rig without bundled training data.
    pub fn new(settings: Settings) -> Self {
        Self::for_layout(Layout::default(), settings)
    }

    /// A corrector of a checked `layout` without bundled training data.
    pub fn for_layout(layout: Layout, settings: Settings) -> Self {
        let history = LagBuffer::new(settings.lags);
        GpCorrector {
            settings,
            inputs: CorrectorInputs::for_layout(&layout),
            table: Some(crate::variables::table(&layout)),
            layout,
            resource_dir: None,
            bundled: None,
            floors: None,
            history,
            cache: None,
        }
    }

    /// As `fmi2Instantiate` makes it: reads and checks `resources/training.json` if present,
    /// whose channels and excitation give the layout (the paper's rig without it).
    pub fn with_resources(resource_dir: Option<&Path>) -> Result<Self, CorrectorError> {
        let mut bundled = None;
        if let Some(dir) = resource_dir {
            let path = dir.join(BUNDLED_TRAINING_FILE);
            if path.is_file() {
                let file = LayoutTraining::read(&path)?;
                bundled = Some((path, file));
            }
        }
        let layout = match &bundled {
            Some((path, file)) => {
                file.layout()
                    .map_err(|problem| CorrectorError::TrainingFile {
                        path: path.display().to_string(),
                        problem,
                    })?
            }
            None => Layout::default(),
        };
        let mut model = GpCorrector::for_layout(layout, Settings::default());
        model.resource_dir = resource_dir.map(Path::to_path_buf);
        model.bundled = bundled;
        Ok(model)
    }

    /// Where `training_path` points: absolute as given, relative from the resources folder
    /// (from the working directory when the host named none).
    pub fn training_file_path(&self) -> Option<PathBuf> {
        if self.settings.training_path.is_empty() {
            return None;
        }
        let path = PathBuf::from(&self.settings.training_path);
        Some(match &self.resource_dir {
            Some(dir) if path.is_relative() => dir.join(path),
            _ => path,
        })
    }

    /// Build the GPs from the training data the parameters select, if not built yet.
    pub fn prepare(&mut self) -> Result<&mut Floors, CorrectorError> {
        let floors = match self.floors.take() {
            Some(floors) => floors,
            None => {
                let floors = self.build_floors()?;
                self.history = LagBuffer::new(self.settings.lags);
                self.cache = None;
                floors
            }
        };
        Ok(self.floors.insert(floors))
    }

    fn build_floors(&self) -> Result<Floors, CorrectorError> {
        let loaded;
        let (path, file) = match self.training_file_path() {
            Some(path) => {
                loaded = LayoutTraining::read(&path)?;
                (path, &loaded)
            }
            None => match &self.bundled {
                Some((path, file)) => (path.clone(), file),
                None => {
                    return Ok(Floors::prior(&self.layout, &self.settings)?);
                }
            },
        };
        let problem = |problem: String| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem,
        };
        if file.channels != self.layout.names() || file.excitation != self.layout.excitation_name()
        {
            return Err(problem(format!(
                "its channels are {} under {}, but this corrector's (fixed at instantiation by \
                 resources/{BUNDLED_TRAINING_FILE}) are {} under {}",
                file.channels.join(", "),
                file.excitation,
                self.layout.names().join(", "),
                self.layout.excitation_name()
            )));
        }
        if file.lags != self.settings.lags {
            return Err(problem(format!(
                "it was made with lags = {}, but the parameter lags is {}",
                file.lags, self.settings.lags
            )));
        }
        if file.target != self.settings.target {
            return Err(problem(format!(
                "its targets are '{}' (target = {}), but the parameter target is {} ('{}')",
                file.target.name(),
                file.target.code(),
                self.settings.target.code(),
                self.settings.target.name()
            )));
        }
        Floors::from_training(file, &self.layout, &self.settings)
            .map_err(|e| problem(format!("cannot build the GPs: {e}")))
    }

    /// The whole lag vector of the current sample.
    pub fn input_vector(&self) -> Vec<f64> {
        self.history.input_vector(&self.inputs.sample())
    }

    /// Predictions of every channel at the current lag vector.
    pub fn predictions(&mut self) -> Result<Vec<PointPrediction>, CorrectorError> {
        if let Some(cached) = &self.cache {
            return Ok(cached.clone());
        }
        let x = self.input_vector();
        let floors = self.prepare()?;
        let out = floors.predict(&x)?;
        self.cache = Some(out.clone());
        Ok(out)
    }

    /// The prediction of channel `j` at the current lag vector.
    fn prediction(&mut self, j: usize) -> Result<PointPrediction, CorrectorError> {
        if self.cache.is_none() {
            self.predictions()?;
        }
        Ok(self.cache.as_ref().map_or(
            PointPrediction {
                mean: 0.0,
                latent_variance: 0.0,
                predictive_variance: 0.0,
            },
            |c| c[j],
        ))
    }

    /// The training set and hyperparameters in the paper rig's training file format (once
    /// built; `None` on another layout: see [`GpCorrector::training`]).
    pub fn training_file(&self) -> Option<TrainingFile> {
        self.training().and_then(|t| t.to_rig())
    }

    /// The training set and hyperparameters as a training file of the layout (once built).
    pub fn training(&self) -> Option<LayoutTraining> {
        self.floors
            .as_ref()
            .map(|f| f.to_training(self.settings.target))
    }

    /// A parameter the GPs depend on changed: build them again when next needed.
    fn parameters_changed(&mut self) {
        self.floors = None;
        self.cache = None;
    }
}

/// A training-data problem met while reading an output: refused, naming the parameter that
/// selects the data, so the host can fix it and read again.
fn refused(e: CorrectorError) -> ModelError {
    ModelError::InvalidValue {
        name: "training_path".into(),
        reason: e.to_string(),
    }
}

fn positive(name: &str, value: f64) -> Result<f64, ModelError> {
    if value > 0.0 && value.is_finite() {
        Ok(value)
    } else {
        Err(ModelError::InvalidValue {
            name: name.to_owned(),
            reason: format!("{value} must be > 0"),
        })
    }
}

impl CoSimModel for GpCorrector {
    fn info() -> &'static ModelInfo {
        info()
    }

    fn table(&self) -> &'static ModelInfo {
        self.table
            .unwrap_or_else(|| crate::variables::table(&self.layout))
    }

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError> {
        GpCorrector::with_resources(context.resource_dir.as_deref())
            .map_err(|e| ModelError::Other(e.to_string()))
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        if let Some((role, j)) = role_of(&self.layout, vr) {
            return Ok(match role {
                Role::Physics => self.inputs.physics[j],
                Role::Measured => self.inputs.measured[j],
                Role::Corrected | Role::LatentVar | Role::Sd => {
                    let p = self.prediction(j).map_err(refused)?;
                    match role {
                        Role::Corrected => self
                            .settings
                            .target
                            .corrected(self.inputs.physics[j], p.mean),
                        Role::LatentVar => p.latent_variance,
                        _ => p.predictive_variance.sqrt(),
                    }
                }
            });
        }
        Ok(match vr {
            vr if vr == excitation_vr(&self.layout) => self.inputs.excitation,
            INITIAL_SIGNAL_VARIANCE_VR => self.settings.initial_signal_variance,
            INITIAL_NOISE_VARIANCE_VR => self.settings.initial_noise_variance,
            INITIAL_LENGTH_SCALE_VR => self.settings.initial_length_scale,
            _ => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        })
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        // The prediction is kept while its inputs keep their values (a master's second
        // pass sets the same ones again).
        match role_of(&self.layout, vr) {
            Some((Role::Physics, j)) => {
                if self.inputs.physics[j].to_bits() != value.to_bits() {
                    self.inputs.physics[j] = value;
                    self.cache = None;
                }
                return Ok(());
            }
            Some((Role::Measured, j)) => {
                self.inputs.measured[j] = value;
                return Ok(());
            }
            Some(_) => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
            None => {}
        }
        match vr {
            vr if vr == excitation_vr(&self.layout) => {
                if self.inputs.excitation.to_bits() != value.to_bits() {
                    self.inputs.excitation = value;
                    self.cache = None;
                }
            }
            INITIAL_SIGNAL_VARIANCE_VR => {
                self.settings.initial_signal_variance = positive("initial_signal_variance", value)?;
                self.parameters_changed();
            }
            INITIAL_NOISE_VARIANCE_VR => {
                self.settings.initial_noise_variance = positive("initial_noise_variance", value)?;
                self.parameters_changed();
            }
            INITIAL_LENGTH_SCALE_VR => {
                self.settings.initial_length_scale = positive("initial_length_scale", value)?;
                self.parameters_changed();
            }
            _ => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        }
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        Ok(match vr {
            LAGS => self.settings.lags as i32,
            TARGET => self.settings.target.code(),
            REFIT_EVERY => self.settings.refit_every as i32,
            BUDGET => self.settings.budget as i32,
            TRAINING_POINTS => {
                let floors = self.prepare().map_err(refused)?;
                floors.len() as i32
            }
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Integer",
                })
            }
        })
    }

    fn set_integer(&mut self, vr: u32, value: i32) -> Result<(), ModelError> {
        let invalid = |name: &str, reason: String| ModelError::InvalidValue {
            name: name.to_owned(),
            reason,
        };
        match vr {
            LAGS => {
                let lags = usize::try_from(value)
                    .ok()
                    .filter(|&q| q <= MAX_LAGS)
                    .ok_or_else(|| {
                        invalid("lags", format!("{value} is outside [0, {MAX_LAGS}]"))
                    })?;
                if lags != self.settings.lags {
                    self.settings.lags = lags;
                    self.parameters_changed();
                }
            }
            TARGET => {
                let target = TargetForm::from_code(value).ok_or_else(|| {
                    invalid(
                        "target",
                        format!("{value} is neither 0 (discrepancy) nor 1 (measured)"),
                    )
                })?;
                if target != self.settings.target {
                    self.settings.target = target;
                    self.parameters_changed();
                }
            }
            REFIT_EVERY => {
                self.settings.refit_every = u32::try_from(value)
                    .map_err(|_| invalid("refit_every", format!("{value} must be ≥ 0")))?;
            }
            BUDGET => {
                self.settings.budget = usize::try_from(value)
                    .ok()
                    .filter(|b| (1..=MAX_TRAINING_POINTS).contains(b))
                    .ok_or_else(|| {
                        invalid(
                            "budget",
                            format!("{value} is outside [1, {MAX_TRAINING_POINTS}]"),
                        )
                    })?;
            }
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Integer",
                })
            }
        }
        Ok(())
    }

    fn get_boolean(&mut self, vr: u32) -> Result<bool, ModelError> {
        match vr {
            LEARN => Ok(self.inputs.learn),
            _ => Err(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            }),
        }
    }

    fn set_boolean(&mut self, vr: u32, value: bool) -> Result<(), ModelError> {
        match vr {
            LEARN => {
                self.inputs.learn = value;
                Ok(())
            }
            _ => Err(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            }),
        }
    }

    fn get_string(&mut self, vr: u32) -> Result<String, ModelError> {
        match vr {
            TRAINING_PATH => Ok(self.settings.training_path.clone()),
            _ => Err(ModelError::UnknownVariable { vr, kind: "String" }),
        }
    }

    fn set_string(&mut self, vr: u32, value: &str) -> Result<(), ModelError> {
        match vr {
            TRAINING_PATH => {
                if value != self.settings.training_path {
                    self.settings.training_path = value.to_owned();
                    self.parameters_changed();
                }
                Ok(())
            }
            _ => Err(ModelError::UnknownVariable { vr, kind: "String" }),
        }
    }

    fn exit_initialization(&mut self) -> Result<(), ModelError> {
        self.prepare()
            .map_err(|e| ModelError::Other(e.to_string()))?;
        // The parameters are fixed from here on: the bundled file is no longer needed.
        self.bundled = None;
        Ok(())
    }

    fn do_step(&mut self, _time: f64, _step_size: f64) -> Result<(), ModelError> {
        let sample = self.inputs.sample();
        if self.inputs.learn {
            let x = self.input_vector();
            let target = self.settings.target;
            let targets: Vec<f64> = self
                .inputs
                .measured
                .iter()
                .zip(&self.inputs.physics)
                .map(|(&m, &p)| target.target(m, p))
                .collect();
            let refit_every = self.settings.refit_every;
            let budget = self.settings.budget;
            let floors = self
                .prepare()
                .map_err(|e| ModelError::Other(e.to_string()))?;
            floors
                .learn(&x, &targets, refit_every, budget)
                .map_err(|e| ModelError::Other(format!("learning the current sample: {e}")))?;
        }
        self.history.push(&sample);
        self.cache = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests;
