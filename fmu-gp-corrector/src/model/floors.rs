//! The channels' GPs: each one's prior or posterior, the columns of the lag vector it takes, the
//! schedule that refits them, and the threads that learn them in parallel.

use super::{initial_fit_options, refit_options, to_gp_hyperparameters, Settings};
use crate::layout::{select, Layout};
use crate::training::{
    FloorHyperparameters, LayoutTraining, TargetForm, TrainingFile, MAX_TRAINING_POINTS,
};
use numerics::gp::{FitOptions, FitReport, GaussianProcess, Inputs};
use numerics::gp::{GpError, Hyperparameters, PendingAppend, PointPrediction};
use serde::{Deserialize, Serialize};

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
    pub(super) fn plan_learn(&self, x: &[f64], y: f64) -> Result<PendingLearn, GpError> {
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
    pub(super) fn commit_learn(
        &mut self,
        plan: PendingLearn,
        budget: usize,
    ) -> Result<(), GpError> {
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
pub(super) enum PendingLearn {
    /// The first point of a GP that had none.
    First(GaussianProcess),
    Append(PendingAppend),
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
    pub(super) fn clone_if_refit_due(&self, refit_every: u32) -> Option<Floors> {
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
pub(super) const PARALLEL_LEARNING: usize = 1024;

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
