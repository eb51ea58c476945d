//! The corrector: one GP per measured channel (the paper's rig: three, one per floor) on lags of
//! the physics predictions and the excitation ([`crate::layout`] says which), their training
//! sets, learning and refitting.

use std::path::{Path, PathBuf};

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
/// The GP types the floors' API hands out or takes, and what follows a floor's GP
/// ([`TrackedPoints`]), for hosts that drive the floors in process (`twin learn`).
pub use numerics::gp::{FitOptions, FitReport, GaussianProcess, Inputs, TrackedPoints, Tracking};
use numerics::gp::{GpError, Hyperparameters, PendingAppend, PointPrediction};
use serde::{Deserialize, Serialize};

use crate::lags::{input_dimension, LagBuffer};
use crate::layout::{select, Layout};
use crate::training::{
    FloorHyperparameters, LayoutTraining, TargetForm, TrainingFile, MAX_LAGS, MAX_TRAINING_POINTS,
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

/// One GP per measured channel, the columns of the lag vector each takes, and the state of the
/// schedule that refits them. (The name is the paper rig's, whose channels are its floors.)
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Floors {
    /// Channel j's GP, in the layout's order.
    pub gps: Vec<FloorGp>,
    pub layout: Layout,
    pub lags: usize,
    /// Channel j's columns of the sample ([`Layout::columns_of`]).
    pub columns: Vec<Vec<usize>>,
    /// Whether the hyperparameters came from data (a file or a fit) rather than the
    /// `initial_*` parameters. The first refit of initial ones starts from data-based values.
    pub fitted: bool,
    pub learned_since_refit: u32,
}

impl Floors {
    /// Every channel's GP at its prior, with the `initial_*` hyperparameters.
    pub fn prior(layout: &Layout, settings: &Settings) -> Result<Self, GpError> {
        let columns: Vec<Vec<usize>> = (0..layout.channels.len())
            .map(|j| layout.columns_of(j))
            .collect();
        let gps = columns
            .iter()
            .map(|c| {
                settings
                    .initial_hyperparameters_of(c.len() * (settings.lags + 1))
                    .map(FloorGp::Prior)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Floors {
            gps,
            layout: layout.clone(),
            lags: settings.lags,
            columns,
            fitted: false,
            learned_since_refit: 0,
        })
    }

    /// The GPs of a training file (of any layout: a paper rig's [`TrainingFile`] converts with
    /// `into()`), checked first, with the default settings for its lags and target form (what
    /// `twin train` and `twin learn` fit).
    pub fn fit_training(file: &LayoutTraining) -> Result<Self, String> {
        let layout = file.check()?;
        let settings = Settings {
            lags: file.lags,
            target: file.target,
            ..Settings::default()
        };
        Self::from_training(file, &layout, &settings).map_err(|e| e.to_string())
    }

    /// The GPs of a checked training file of `layout`: conditioned on its hyperparameters, or
    /// fitted (the channels in parallel threads).
    pub fn from_training(
        file: &LayoutTraining,
        layout: &Layout,
        settings: &Settings,
    ) -> Result<Self, GpError> {
        let mut floors = Floors::prior(layout, settings)?;
        if file.inputs.is_empty() {
            if let Some(sets) = &file.hyperparameters {
                for (gp, set) in floors.gps.iter_mut().zip(sets) {
                    *gp = FloorGp::Prior(to_gp_hyperparameters(set)?);
                }
                floors.fitted = true;
            }
            return Ok(floors);
        }
        let lags = settings.lags;
        let columns = &floors.columns;
        let build = |j: usize| -> Result<FloorGp, GpError> {
            let rows: Vec<Vec<f64>> = file
                .inputs
                .iter()
                .map(|x| select(x, &columns[j], lags))
                .collect();
            let inputs = Inputs::from_rows(&rows)?;
            let targets: Vec<f64> = file.targets.iter().map(|y| y[j]).collect();
            let gp = match &file.hyperparameters {
                Some(sets) => {
                    let hyper = to_gp_hyperparameters(&sets[j])?;
                    hyper.validate(rows[0].len())?;
                    GaussianProcess::new(inputs, targets, hyper)?
                }
                None => GaussianProcess::fit(&inputs, &targets, &initial_fit_options())?.0,
            };
            Ok(FloorGp::Trained(gp))
        };
        floors.gps = per_channel(layout.channels.len(), build)
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?;
        floors.fitted = true;
        Ok(floors)
    }

    pub fn len(&self) -> usize {
        self.gps.first().map_or(0, FloorGp::len)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Channel j's GP input from the whole lag vector `x`.
    pub fn input_of(&self, j: usize, x: &[f64]) -> Vec<f64> {
        select(x, &self.columns[j], self.lags)
    }

    /// Channel j in messages: "floor i" on the paper's rig (its channels are its floors), else
    /// the channel's name.
    pub fn who(&self, j: usize) -> String {
        if self.layout.is_paper() {
            format!("floor {}", j + 1)
        } else {
            format!("channel {}", self.layout.channels[j].name())
        }
    }

    /// Every channel's prediction at the whole lag vector `x`.
    pub fn predict(&self, x: &[f64]) -> Result<Vec<PointPrediction>, GpError> {
        self.gps
            .iter()
            .enumerate()
            .map(|(j, gp)| {
                if self.columns[j].len() * (self.lags + 1) == x.len() {
                    gp.predict(x)
                } else {
                    gp.predict(&self.input_of(j, x))
                }
            })
            .collect()
    }

    /// Add one point (the whole lag vector `x`, one target per channel) to every channel;
    /// refit on the schedule. On an error nothing has changed.
    ///
    /// All or none without copying the GPs on every step: every channel's append is planned
    /// first (the fallible `O(n²)` work), then all are committed (beyond
    /// [`MAX_TRAINING_POINTS`] the oldest point goes after the append), which cannot fail. Only
    /// a step that ends in a scheduled refit copies the GPs first, to restore them if the
    /// refit fails (a refit costs far more than the copy).
    pub fn learn(
        &mut self,
        x: &[f64],
        targets: &[f64],
        refit_every: u32,
        budget: usize,
    ) -> Result<(), String> {
        let m = self.gps.len();
        if targets.len() != m {
            return Err(format!(
                "{} targets for {m} channel(s) ({})",
                targets.len(),
                self.layout.names().join(", ")
            ));
        }
        let parallel = self.len() >= PARALLEL_LEARNING;
        let plan = |j: usize| self.gps[j].plan_learn(&self.input_of(j, x), targets[j]);
        let plans = if parallel {
            per_channel(m, plan)
        } else {
            (0..m).map(plan).collect()
        };
        let plans = plans
            .into_iter()
            .enumerate()
            .map(|(j, p)| p.map_err(|e| format!("{}: cannot add the point: {e}", self.who(j))))
            .collect::<Result<Vec<_>, _>>()?;
        let before = self.clone_if_refit_due(refit_every);
        let committed: Vec<Result<(), GpError>> = if parallel {
            std::thread::scope(|scope| {
                let handles: Vec<_> = self
                    .gps
                    .iter_mut()
                    .zip(plans)
                    .map(|(g, p)| scope.spawn(move || g.commit_learn(p, budget)))
                    .collect();
                handles
                    .into_iter()
                    .map(|h| match h.join() {
                        Ok(r) => r,
                        Err(payload) => std::panic::resume_unwind(payload),
                    })
                    .collect()
            })
        } else {
            self.gps
                .iter_mut()
                .zip(plans)
                .map(|(g, p)| g.commit_learn(p, budget))
                .collect()
        };
        for (j, r) in committed.into_iter().enumerate() {
            r.map_err(|e| format!("{}: cannot add the point: {e}", self.who(j)))?;
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

    /// Refit every channel's hyperparameters (type-II ML, the channels in parallel threads):
    /// warm-started from the current ones with [`refit_options`] once they came from data, else
    /// a first fit from data-based starts. On an error nothing has changed.
    pub fn refit(&mut self) -> Result<(), String> {
        self.refit_with(&refit_options()).map(|_| ())
    }

    /// [`Floors::refit`] with the given options for the warm-started refits (the warm start
    /// itself is always the current hyperparameters); returns each channel's fit report (none
    /// for a channel without data).
    pub fn refit_with(&mut self, options: &FitOptions) -> Result<Vec<Option<FitReport>>, String> {
        let warm = self.fitted;
        let results = per_channel(
            self.gps.len(),
            |j| -> Result<(FloorGp, Option<FitReport>), GpError> {
                Ok(match &self.gps[j] {
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
            },
        );
        let mut gps = Vec::with_capacity(results.len());
        let mut reports = Vec::with_capacity(results.len());
        for (j, r) in results.into_iter().enumerate() {
            let (g, f) = r.map_err(|e| {
                format!("{}: refitting the hyperparameters failed: {e}", self.who(j))
            })?;
            gps.push(g);
            reports.push(f);
        }
        self.fitted = warm || gps.first().is_some_and(|g| !g.is_empty());
        self.gps = gps;
        self.learned_since_refit = 0;
        Ok(reports)
    }

    /// The training set and hyperparameters as a training file of the layout: each point's
    /// whole lag vector put back together from the channels' GPs (every column is in its own
    /// channel's inputs, the excitation in all).
    pub fn to_training(&self, target: TargetForm) -> LayoutTraining {
        let m = self.gps.len();
        let block = self.lags + 1;
        let points = self.len();
        let position = |j: usize, column: usize| {
            self.columns[j]
                .iter()
                .position(|&c| c == column)
                .unwrap_or(0)
        };
        let inputs = (0..points)
            .map(|n| {
                let mut x = vec![0.0; (m + 1) * block];
                for column in 0..=m {
                    let j = if column == m { 0 } else { column };
                    if let FloorGp::Trained(gp) = &self.gps[j] {
                        let p = position(j, column);
                        let row = gp.inputs().row(n);
                        x[column * block..(column + 1) * block]
                            .copy_from_slice(&row[p * block..(p + 1) * block]);
                    }
                }
                x
            })
            .collect();
        let targets = (0..points)
            .map(|n| {
                self.gps
                    .iter()
                    .map(|g| match g {
                        FloorGp::Trained(gp) => gp.targets()[n],
                        FloorGp::Prior(_) => 0.0,
                    })
                    .collect()
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
        LayoutTraining {
            channels: self.layout.names(),
            excitation: self.layout.excitation_name(),
            lags: self.lags,
            target,
            inputs,
            targets,
            hyperparameters: Some(hyperparameters),
        }
    }

    /// The paper rig's training file (see [`Floors::to_training`]); `None` on another layout.
    pub fn to_training_file(&self, target: TargetForm) -> Option<TrainingFile> {
        self.to_training(target).to_rig()
    }
}

/// From this many training points on, [`Floors::learn`] works on the channels in parallel
/// threads: its `O(n²)` step takes about 0.3 ms a floor at 1024 points and 40 inputs (1 ms at
/// 2048); below, starting threads (tens of µs) would eat much of the gain. Results are the
/// same either way.
const PARALLEL_LEARNING: usize = 1024;

/// Run `work` for channels `0..n` in threads (as many as the machine runs at once, at least 3,
/// at most `n`; channel j on thread j mod threads), results in channel order (a panic in one
/// is resumed in the caller).
pub fn per_channel<T: Send>(n: usize, work: impl Fn(usize) -> T + Sync) -> Vec<T> {
    if n <= 1 {
        return (0..n).map(work).collect();
    }
    let threads = std::thread::available_parallelism()
        .map_or(1, |p| p.get())
        .max(3)
        .min(n);
    let work = &work;
    let mut out: Vec<(usize, T)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (1..threads)
            .map(|t| {
                scope.spawn(move || {
                    (t..n)
                        .step_by(threads)
                        .map(|j| (j, work(j)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let mut all: Vec<(usize, T)> = (0..n).step_by(threads).map(|j| (j, work(j))).collect();
        for h in handles {
            match h.join() {
                Ok(r) => all.extend(r),
                Err(payload) => std::panic::resume_unwind(payload),
            }
        }
        all
    });
    out.sort_by_key(|(j, _)| *j);
    out.into_iter().map(|(_, t)| t).collect()
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
mod tests {
    use fmi2::{CoSimModel, InstantiateContext};

    use super::*;
    use crate::lags::lagged_inputs;

    /// A layout of four channels under ground motion, trained on a small record with given
    /// hyperparameters, instantiated from its bundled training file: its table is the layout's,
    /// each channel's outputs are its GP's on the columns the layout chooses, learning through
    /// `do_step` adds the sample to every channel, and the training file written back holds the
    /// whole lag vectors the corrector saw.
    #[test]
    fn a_corrector_of_another_layout_predicts_each_channel_from_its_own_inputs() {
        let layout = Layout::from_names(&["acc1", "acc3", "acc5", "vel2"], "ground_acc")
            .expect("test value");
        let (m, lags) = (layout.channels.len(), 1);
        let samples: Vec<Vec<f64>> = (0..30)
            .map(|k| {
                (0..=m)
                    .map(|c| (0.3 * k as f64 + c as f64).sin() * (1.0 + c as f64 * 0.1))
                    .collect()
            })
            .collect();
        let inputs = lagged_inputs(&samples, lags);
        let targets: Vec<Vec<f64>> = samples
            .iter()
            .map(|s| (0..m).map(|j| 0.1 * s[j] * s[m]).collect())
            .collect();
        let hyperparameters: Vec<FloorHyperparameters> = (0..m)
            .map(|j| FloorHyperparameters {
                length_scales: vec![0.8 + 0.1 * j as f64; layout.input_dimension_of(j, lags)],
                signal_variance: 0.01,
                noise_variance: 1e-4,
            })
            .collect();
        let file = LayoutTraining {
            channels: layout.names(),
            excitation: layout.excitation_name(),
            lags,
            target: TargetForm::Discrepancy,
            inputs: inputs[..20].to_vec(),
            targets: targets[..20].to_vec(),
            hyperparameters: Some(hyperparameters.clone()),
        };
        let dir = tempfile::tempdir().expect("temp dir");
        file.write(&dir.path().join(BUNDLED_TRAINING_FILE))
            .expect("written");
        let context = InstantiateContext {
            instance_name: "layout".into(),
            resource_dir: Some(dir.path().to_path_buf()),
        };
        let mut model = GpCorrector::instantiate(&context).expect("instantiate");
        assert_eq!(model.layout, layout);
        let table = model.table();
        assert_eq!(table.guid, crate::variables::table(&layout).guid);
        assert!(table.by_name("sd_vel2").is_some() && table.by_name("force").is_none());
        model.set_integer(LAGS, lags as i32).expect("lags");
        model.set_integer(REFIT_EVERY, 0).expect("refit_every");
        model.exit_initialization().expect("initialize");
        let gp = |j: usize, points: usize| {
            let rows: Vec<Vec<f64>> = inputs[..points]
                .iter()
                .map(|x| select(x, &layout.columns_of(j), lags))
                .collect();
            let h = &hyperparameters[j];
            GaussianProcess::new(
                Inputs::from_rows(&rows).expect("test value"),
                targets[..points].iter().map(|y| y[j]).collect(),
                Hyperparameters::new(&h.length_scales, h.signal_variance, h.noise_variance)
                    .expect("test value"),
            )
            .expect("test value")
        };
        for (k, sample) in samples.iter().enumerate().take(25) {
            for (j, &value) in sample.iter().enumerate().take(m) {
                model
                    .set_real(vr_of(&layout, Role::Physics, j), value)
                    .expect("test value");
                model
                    .set_real(vr_of(&layout, Role::Measured, j), sample[j] + targets[k][j])
                    .expect("test value");
            }
            model.set_real(GROUND_ACC, sample[m]).expect("test value");
            // From sample 20 on the corrector learns each sample after reading it.
            model.set_boolean(LEARN, k >= 20).expect("test value");
            let known = if k <= 20 { 20 } else { k };
            for (j, &physics) in sample.iter().enumerate().take(m) {
                let x = select(&inputs[k], &layout.columns_of(j), lags);
                let p = gp(j, known).predict_point(&x).expect("test value");
                let corrected = model
                    .get_real(vr_of(&layout, Role::Corrected, j))
                    .expect("test value");
                let latent = model
                    .get_real(vr_of(&layout, Role::LatentVar, j))
                    .expect("test value");
                let expected = physics + p.mean;
                assert!(
                    (corrected - expected).abs() <= 1e-9 * expected.abs().max(1e-6),
                    "sample {k}, {}: {corrected} vs {expected}",
                    layout.channels[j].name()
                );
                assert!(
                    (latent - p.latent_variance).abs() <= 1e-9 * p.latent_variance.max(1e-9),
                    "sample {k}, {}: {latent} vs {}",
                    layout.channels[j].name(),
                    p.latent_variance
                );
            }
            model.do_step(k as f64, 1.0).expect("test value");
        }
        let learned = model.training().expect("built");
        assert_eq!(learned.inputs, inputs[..25].to_vec());
        assert_eq!(learned.channels, layout.names());
        for (a, b) in learned.targets.iter().zip(&targets[..25]) {
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= 1e-12, "{x} vs {y}");
            }
        }
        assert!(model.training_file().is_none(), "not the rig's format");
    }
}
