//! The corrector: three GPs (one per floor) on the lag vector of the physics accelerations and
//! the force, their training sets, learning and refitting.

use std::path::{Path, PathBuf};

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
/// The GP types the floors' API hands out or takes, and what follows a floor's GP
/// ([`TrackedPoints`]), for hosts that drive the floors in process (`twin learn`).
pub use numerics::gp::{FitOptions, FitReport, GaussianProcess, Inputs, TrackedPoints, Tracking};
use numerics::gp::{GpError, Hyperparameters, PendingAppend, PointPrediction};
use serde::{Deserialize, Serialize};

use crate::lags::{input_dimension, LagBuffer, Sample};
use crate::training::{
    FloorHyperparameters, TargetForm, TrainingFile, MAX_LAGS, MAX_TRAINING_POINTS,
};
use crate::variables::*;
use crate::CorrectorError;

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

/// One floor's GP, or its prior while it has no training point (a `GaussianProcess` holds at
/// least one).
// Three of these exist, and a GP holds its data on the heap: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum FloorGp {
    Prior(Hyperparameters),
    Trained(GaussianProcess),
}

impl FloorGp {
    pub fn len(&self) -> usize {
        match self {
            FloorGp::Prior(_) => 0,
            FloorGp::Trained(gp) => gp.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn hyperparameters(&self) -> &Hyperparameters {
        match self {
            FloorGp::Prior(h) => h,
            FloorGp::Trained(gp) => gp.hyperparameters(),
        }
    }

    /// Mean, latent and predictive variance at `x`; the prior's (0, σ_f², σ_f² + σ_n²) without data.
    pub fn predict(&self, x: &[f64]) -> Result<PointPrediction, GpError> {
        match self {
            FloorGp::Prior(h) => {
                h.validate(x.len())?;
                Ok(PointPrediction {
                    mean: 0.0,
                    latent_variance: h.signal_variance(),
                    predictive_variance: h.signal_variance() + h.noise_variance(),
                })
            }
            FloorGp::Trained(gp) => gp.predict_point(x),
        }
    }

    /// Add a point (`O(n²)`); beyond [`MAX_TRAINING_POINTS`] the oldest point goes.
    pub fn learn(&mut self, x: &[f64], y: f64) -> Result<(), GpError> {
        let plan = self.plan_learn(x, y)?;
        self.commit_learn(plan, MAX_TRAINING_POINTS)
    }

    /// The fallible part of [`FloorGp::learn`], leaving the GP as it is.
    fn plan_learn(&self, x: &[f64], y: f64) -> Result<PendingLearn, GpError> {
        Ok(match self {
            FloorGp::Prior(h) => PendingLearn::First(GaussianProcess::new(
                Inputs::from_rows(&[x])?,
                vec![y],
                h.clone(),
            )?),
            FloorGp::Trained(gp) => PendingLearn::Append(gp.plan_append(x, y)?),
        })
    }

    /// Applies a plan of this GP's: the append, then (at the size limit) the removal of the
    /// oldest point, neither of which can fail on a GP left as planned.
    fn commit_learn(&mut self, plan: PendingLearn, budget: usize) -> Result<(), GpError> {
        match (plan, &mut *self) {
            (PendingLearn::First(gp), _) => *self = FloorGp::Trained(gp),
            (PendingLearn::Append(plan), FloorGp::Trained(gp)) => {
                gp.commit(plan)?;
                while gp.len() > budget.clamp(1, MAX_TRAINING_POINTS) {
                    gp.remove(0)?;
                }
            }
            (PendingLearn::Append(_), FloorGp::Prior(_)) => {
                return Err(GpError::InvalidOptions(
                    "a planned append to a GP that has no data".into(),
                ))
            }
        }
        Ok(())
    }

    /// Type-II ML refit from the current hyperparameters; nothing to fit without data.
    pub fn refit(&mut self, options: &FitOptions) -> Result<(), GpError> {
        if let FloorGp::Trained(gp) = self {
            gp.refit(options)?;
        }
        Ok(())
    }
}

/// A learning step of one floor, computed but not made.
enum PendingLearn {
    /// The first point of a GP that had none.
    First(GaussianProcess),
    Append(PendingAppend),
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
    pub fn initial_hyperparameters(&self) -> Result<Hyperparameters, GpError> {
        Hyperparameters::new(
            &vec![self.initial_length_scale; input_dimension(self.lags)],
            self.initial_signal_variance,
            self.initial_noise_variance,
        )
    }
}

/// The current values of the inputs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CorrectorInputs {
    pub physics_acc: [f64; 3],
    pub force: f64,
    pub measured_acc: [f64; 3],
    pub learn: bool,
}

impl CorrectorInputs {
    pub fn sample(&self) -> Sample {
        let [a1, a2, a3] = self.physics_acc;
        [a1, a2, a3, self.force]
    }
}

/// The three floors' GPs and the state of the schedule that refits them.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Floors {
    pub gps: [FloorGp; 3],
    /// Whether the hyperparameters came from data (a file or a fit) rather than the
    /// `initial_*` parameters. The first refit of initial ones starts from data-based values.
    pub fitted: bool,
    pub learned_since_refit: u32,
}

impl Floors {
    fn prior(hyper: Hyperparameters) -> Self {
        Floors {
            gps: [
                FloorGp::Prior(hyper.clone()),
                FloorGp::Prior(hyper.clone()),
                FloorGp::Prior(hyper),
            ],
            fitted: false,
            learned_since_refit: 0,
        }
    }

    /// The GPs of a training file, checked first, with the default settings for its lags and
    /// target form (what `twin train` and `twin learn` fit).
    pub fn fit_training(file: &TrainingFile) -> Result<Self, String> {
        file.check()?;
        let settings = Settings {
            lags: file.lags,
            target: file.target,
            ..Settings::default()
        };
        Self::from_training(file, &settings).map_err(|e| e.to_string())
    }

    /// The GPs of a checked training file: conditioned on its hyperparameters, or fitted.
    pub fn from_training(file: &TrainingFile, settings: &Settings) -> Result<Self, GpError> {
        let dimension = file.input_dimension();
        if file.inputs.is_empty() {
            let mut floors = Floors::prior(settings.initial_hyperparameters()?);
            if let Some(sets) = &file.hyperparameters {
                for (gp, set) in floors.gps.iter_mut().zip(sets) {
                    *gp = FloorGp::Prior(to_gp_hyperparameters(set)?);
                }
                floors.fitted = true;
            }
            return Ok(floors);
        }
        let inputs = Inputs::from_rows(&file.inputs)?;
        let targets = |floor: usize| file.targets.iter().map(|y| y[floor]).collect::<Vec<_>>();
        let build = |floor: usize| -> Result<FloorGp, GpError> {
            let gp = match &file.hyperparameters {
                Some(sets) => {
                    let hyper = to_gp_hyperparameters(&sets[floor])?;
                    hyper.validate(dimension)?;
                    GaussianProcess::new(inputs.clone(), targets(floor), hyper)?
                }
                None => GaussianProcess::fit(&inputs, &targets(floor), &initial_fit_options())?.0,
            };
            Ok(FloorGp::Trained(gp))
        };
        let [g1, g2, g3] = per_floor(build);
        Ok(Floors {
            gps: [g1?, g2?, g3?],
            fitted: true,
            learned_since_refit: 0,
        })
    }

    pub fn len(&self) -> usize {
        self.gps[0].len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Add one point to every floor; refit on the schedule. On an error nothing has changed.
    ///
    /// All or none without copying the GPs on every step: every floor's append is planned
    /// first (the fallible `O(n²)` work), then all are committed (beyond
    /// [`MAX_TRAINING_POINTS`] the oldest point goes after the append), which cannot fail. Only
    /// a step that ends in a scheduled refit copies the floors first, to restore them if the
    /// refit fails (a refit costs far more than the copy).
    pub fn learn(
        &mut self,
        x: &[f64],
        targets: [f64; 3],
        refit_every: u32,
        budget: usize,
    ) -> Result<(), String> {
        let parallel = self.len() >= PARALLEL_LEARNING;
        let plan = |floor: usize| self.gps[floor].plan_learn(x, targets[floor]);
        let plans = if parallel {
            per_floor(plan)
        } else {
            [plan(0), plan(1), plan(2)]
        };
        let failed =
            |floor: usize, e: GpError| format!("floor {}: cannot add the point: {e}", floor + 1);
        let [p0, p1, p2] = plans;
        let plans = [
            p0.map_err(|e| failed(0, e))?,
            p1.map_err(|e| failed(1, e))?,
            p2.map_err(|e| failed(2, e))?,
        ];
        let before = self.clone_if_refit_due(refit_every);
        let [g0, g1, g2] = &mut self.gps;
        let [p0, p1, p2] = plans;
        let committed = if parallel {
            std::thread::scope(|scope| {
                let h1 = scope.spawn(|| g1.commit_learn(p1, budget));
                let h2 = scope.spawn(|| g2.commit_learn(p2, budget));
                let r0 = g0.commit_learn(p0, budget);
                let join =
                    |h: std::thread::ScopedJoinHandle<'_, Result<(), GpError>>| match h.join() {
                        Ok(r) => r,
                        Err(payload) => std::panic::resume_unwind(payload),
                    };
                [r0, join(h1), join(h2)]
            })
        } else {
            [
                g0.commit_learn(p0, budget),
                g1.commit_learn(p1, budget),
                g2.commit_learn(p2, budget),
            ]
        };
        for (floor, r) in committed.into_iter().enumerate() {
            r.map_err(|e| failed(floor, e))?;
        }
        self.learned_since_refit += 1;
        if refit_every > 0 && self.learned_since_refit >= refit_every {
            if let Err(e) = self.refit() {
                if let Some(before) = before {
                    *self = before;
                }
                return Err(e);
            }
        }
        Ok(())
    }

    /// A copy to restore if the refit due at this learning step fails.
    fn clone_if_refit_due(&self, refit_every: u32) -> Option<Floors> {
        (refit_every > 0 && self.learned_since_refit + 1 >= refit_every).then(|| self.clone())
    }

    /// Refit every floor's hyperparameters (type-II ML, the floors in parallel threads): warm-
    /// started from the current ones with [`refit_options`] once they came from data, else a
    /// first fit from data-based starts. On an error nothing has changed.
    pub fn refit(&mut self) -> Result<(), String> {
        self.refit_with(&refit_options()).map(|_| ())
    }

    /// [`Floors::refit`] with the given options for the warm-started refits (the warm start
    /// itself is always the current hyperparameters); returns each floor's fit report (none
    /// for a floor without data).
    pub fn refit_with(&mut self, options: &FitOptions) -> Result<[Option<FitReport>; 3], String> {
        let warm = self.fitted;
        let results = per_floor(|floor| -> Result<(FloorGp, Option<FitReport>), GpError> {
            Ok(match &self.gps[floor] {
                FloorGp::Prior(h) => (FloorGp::Prior(h.clone()), None),
                FloorGp::Trained(gp) => {
                    let (model, report) = if warm {
                        let mut options = options.clone();
                        options.warm_start = Some(gp.hyperparameters().clone());
                        GaussianProcess::fit(gp.inputs(), gp.targets(), &options)?
                    } else {
                        GaussianProcess::fit(gp.inputs(), gp.targets(), &initial_fit_options())?
                    };
                    (FloorGp::Trained(model), Some(report))
                }
            })
        });
        let failed = |floor: usize, e: GpError| {
            format!(
                "floor {}: refitting the hyperparameters failed: {e}",
                floor + 1
            )
        };
        let [r1, r2, r3] = results;
        let (g1, f1) = r1.map_err(|e| failed(0, e))?;
        let (g2, f2) = r2.map_err(|e| failed(1, e))?;
        let (g3, f3) = r3.map_err(|e| failed(2, e))?;
        self.fitted = warm || !g1.is_empty();
        self.gps = [g1, g2, g3];
        self.learned_since_refit = 0;
        Ok([f1, f2, f3])
    }

    /// The training set and hyperparameters as a training file.
    pub fn to_training_file(&self, lags: usize, target: TargetForm) -> TrainingFile {
        let inputs = match &self.gps[0] {
            FloorGp::Prior(_) => Vec::new(),
            FloorGp::Trained(gp) => gp.inputs().rows().map(<[f64]>::to_vec).collect(),
        };
        let targets = (0..inputs.len())
            .map(|n| {
                let y = |floor: usize| match &self.gps[floor] {
                    FloorGp::Trained(gp) => gp.targets()[n],
                    FloorGp::Prior(_) => 0.0,
                };
                [y(0), y(1), y(2)]
            })
            .collect();
        let hyperparameters = self
            .gps
            .iter()
            .map(|g| {
                let h = g.hyperparameters();
                FloorHyperparameters {
                    length_scales: h.lengthscales(),
                    signal_variance: h.signal_variance(),
                    noise_variance: h.noise_variance(),
                }
            })
            .collect();
        TrainingFile {
            lags,
            target,
            inputs,
            targets,
            hyperparameters: Some(hyperparameters),
        }
    }
}

/// From this many training points on, [`Floors::learn`] works on the three floors in parallel
/// threads: its `O(n²)` step takes about 0.3 ms a floor at 1024 points and 40 inputs (1 ms at
/// 2048); below, starting two threads (tens of µs) would eat much of the gain. Results are the
/// same either way.
const PARALLEL_LEARNING: usize = 1024;

/// Run `work` for floors 0, 1, 2 in three threads (a panic in one is resumed in the caller).
pub fn per_floor<T: Send>(work: impl Fn(usize) -> T + Sync) -> [T; 3] {
    std::thread::scope(|scope| {
        let work = &work;
        let h1 = scope.spawn(move || work(1));
        let h2 = scope.spawn(move || work(2));
        let r0 = work(0);
        let join = |h: std::thread::ScopedJoinHandle<'_, T>| match h.join() {
            Ok(r) => r,
            Err(payload) => std::panic::resume_unwind(payload),
        };
        [r0, join(h1), join(h2)]
    })
}

pub fn to_gp_hyperparameters(set: &FloorHyperparameters) -> Result<Hyperparameters, GpError> {
    Hyperparameters::new(&set.length_scales, set.signal_variance, set.noise_variance)
}

/// The GP corrector FMU's model.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GpCorrector {
    pub settings: Settings,
    pub inputs: CorrectorInputs,
    /// The FMU's unpacked `resources/` folder, when the host named one.
    pub resource_dir: Option<PathBuf>,
    /// `resources/training.json`, read and checked at instantiation; dropped once initialized.
    pub bundled: Option<(PathBuf, TrainingFile)>,
    /// The GPs: built from the training data on first need (an output read in initialization
    /// mode, or leaving it), cleared when a parameter they depend on changes.
    pub floors: Option<Floors>,
    /// The samples before the current one.
    pub history: LagBuffer,
    /// Predictions at the current lag vector, until an input or the GPs change.
    #[serde(skip)]
    cache: Option<[PointPrediction; 3]>,
}

impl GpCorrector {
    /// A corrector without bundled training data.
    pub fn new(settings: Settings) -> Self {
        let history = LagBuffer::new(settings.lags);
        GpCorrector {
            settings,
            inputs: CorrectorInputs::default(),
            resource_dir: None,
            bundled: None,
            floors: None,
            history,
            cache: None,
        }
    }

    /// As `fmi2Instantiate` makes it: reads and checks `resources/training.json` if present.
    pub fn with_resources(resource_dir: Option<&Path>) -> Result<Self, CorrectorError> {
        let mut model = GpCorrector::new(Settings::default());
        model.resource_dir = resource_dir.map(Path::to_path_buf);
        if let Some(dir) = resource_dir {
            let path = dir.join(BUNDLED_TRAINING_FILE);
            if path.is_file() {
                let file = TrainingFile::read(&path)?;
                model.bundled = Some((path, file));
            }
        }
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
                loaded = TrainingFile::read(&path)?;
                (path, &loaded)
            }
            None => match &self.bundled {
                Some((path, file)) => (path.clone(), file),
                None => {
                    return Ok(Floors::prior(self.settings.initial_hyperparameters()?));
                }
            },
        };
        let problem = |problem: String| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem,
        };
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
        Floors::from_training(file, &self.settings)
            .map_err(|e| problem(format!("cannot build the GPs: {e}")))
    }

    /// The GP input vector of the current sample.
    pub fn input_vector(&self) -> Vec<f64> {
        self.history.input_vector(&self.inputs.sample())
    }

    /// Predictions of the three floors at the current lag vector.
    pub fn predictions(&mut self) -> Result<[PointPrediction; 3], CorrectorError> {
        if let Some(cached) = self.cache {
            return Ok(cached);
        }
        let x = self.input_vector();
        let floors = self.prepare()?;
        let mut out = [PointPrediction {
            mean: 0.0,
            latent_variance: 0.0,
            predictive_variance: 0.0,
        }; 3];
        for (p, gp) in out.iter_mut().zip(&floors.gps) {
            *p = gp.predict(&x)?;
        }
        self.cache = Some(out);
        Ok(out)
    }

    /// The training set and hyperparameters in the training file format (once built).
    pub fn training_file(&self) -> Option<TrainingFile> {
        self.floors
            .as_ref()
            .map(|f| f.to_training_file(self.settings.lags, self.settings.target))
    }

    /// A parameter the GPs depend on changed: build them again when next needed.
    fn parameters_changed(&mut self) {
        self.floors = None;
        self.cache = None;
    }

    fn floor_index(vr: u32, first: u32) -> Option<usize> {
        vr.checked_sub(first).map(|i| i as usize).filter(|&i| i < 3)
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

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError> {
        GpCorrector::with_resources(context.resource_dir.as_deref())
            .map_err(|e| ModelError::Other(e.to_string()))
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        if let Some(i) = Self::floor_index(vr, PHYSICS_ACC) {
            return Ok(self.inputs.physics_acc[i]);
        }
        if let Some(i) = Self::floor_index(vr, MEASURED_ACC) {
            return Ok(self.inputs.measured_acc[i]);
        }
        let output = [ACC, LATENT_VAR, SD]
            .iter()
            .find_map(|&first| Self::floor_index(vr, first).map(|i| (first, i)));
        if let Some((first, i)) = output {
            let p = self.predictions().map_err(refused)?[i];
            return Ok(match first {
                ACC => self
                    .settings
                    .target
                    .corrected(self.inputs.physics_acc[i], p.mean),
                LATENT_VAR => p.latent_variance,
                _ => p.predictive_variance.sqrt(),
            });
        }
        Ok(match vr {
            FORCE => self.inputs.force,
            INITIAL_SIGNAL_VARIANCE_VR => self.settings.initial_signal_variance,
            INITIAL_NOISE_VARIANCE_VR => self.settings.initial_noise_variance,
            INITIAL_LENGTH_SCALE_VR => self.settings.initial_length_scale,
            _ => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        })
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        // The prediction is kept while its inputs keep their values (a master's second
        // pass sets the same ones again).
        if let Some(i) = Self::floor_index(vr, PHYSICS_ACC) {
            if self.inputs.physics_acc[i].to_bits() != value.to_bits() {
                self.inputs.physics_acc[i] = value;
                self.cache = None;
            }
            return Ok(());
        }
        if let Some(i) = Self::floor_index(vr, MEASURED_ACC) {
            self.inputs.measured_acc[i] = value;
            return Ok(());
        }
        match vr {
            FORCE => {
                if self.inputs.force.to_bits() != value.to_bits() {
                    self.inputs.force = value;
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
            let measured = self.inputs.measured_acc;
            let physics = self.inputs.physics_acc;
            let targets = [0, 1, 2].map(|i| target.target(measured[i], physics[i]));
            let refit_every = self.settings.refit_every;
            let budget = self.settings.budget;
            let floors = self
                .prepare()
                .map_err(|e| ModelError::Other(e.to_string()))?;
            floors
                .learn(&x, targets, refit_every, budget)
                .map_err(|e| ModelError::Other(format!("learning the current sample: {e}")))?;
        }
        self.history.push(sample);
        self.cache = None;
        Ok(())
    }
}
