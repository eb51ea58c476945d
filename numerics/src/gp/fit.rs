//! Type-II maximum likelihood: L-BFGS in log-hyperparameter space with the hyperparameters
//! held in a box (lbfgs.rs: two-metric projection, the stopping tests of L-BFGS-B), from several
//! seeded starts.
//!
//! The objective is the NLML divided by the number of points, so that its gradient is O(1)
//! whatever N is (a first step along the steepest descent has a sensible length, and the
//! tolerances mean the same at N = 75 and N = 1000).
//!
//! The box. Each log-hyperparameter has a range set from the data (`sd_d` the d-th input's
//! standard deviation, `v` the targets' variance):
//!
//! | parameter  | lower                     | upper              |
//! | ---------- | ------------------------- | ------------------ |
//! | log l_d    | log(1e-3 sd_d)            | log(1e3 sd_d √d)   |
//! | log σ_f²   | log(1e-6 v)               | log(1e3 v)         |
//! | log σ_n²   | log(noise_floor · v)      | log(10 v)          |
//!
//! with `noise_floor = 1e-8` by default, so that the noise cannot go to 0. The bounds are hard
//! (iterates are projected onto the box, "clamping"), chosen over a soft prior because a prior
//! moves the optimum inside the box and over soft walls because an irrelevant input's
//! lengthscale ends on its upper bound, where the projection fixes it and a wall makes the
//! optimiser bounce (lbfgs.rs says what that cost). The NLML is therefore only ever computed at
//! sensible hyperparameters (no overflow of `σ_f²`, no `l → 0`).

use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::lbfgs::{self, Settings};
use super::likelihood::Workspace;
use super::model::GaussianProcess;
use super::{check_training, target_scale, GpError, Hyperparameters, Inputs};

/// How [`GaussianProcess::fit`] searches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// L-BFGS runs, at least 1. The first starts from `warm_start` when given, else from the
    /// data-based values (lengthscales `sd_d √d`, `σ_f² = var(y)`, `σ_n² = 1e-2 var(y)`); the
    /// others from those data-based values moved by independent N(0, 1) steps in every log
    /// coordinate, drawn from `seed`.
    pub starts: usize,
    pub seed: u64,
    /// L-BFGS iterations per start.
    pub max_iterations: u64,
    /// Stop when the projected gradient of NLML/N, `P(θ − g) − θ`, has a max-norm below this
    /// (L-BFGS-B's `pgtol`).
    pub gradient_tolerance: f64,
    /// Stop when an iteration lowers NLML/N by less than this relative to
    /// `max(|f_k|, |f_{k+1}|, 1)` (L-BFGS-B's `factr · ε`, scipy's `ftol`).
    pub cost_tolerance: f64,
    /// L-BFGS memory (pairs kept).
    pub history: usize,
    /// The smallest noise variance allowed, as a fraction of var(y).
    pub noise_floor: f64,
    /// Hyperparameters to start the first run from (a refit in active learning).
    pub warm_start: Option<Hyperparameters>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            starts: 3,
            seed: 0,
            max_iterations: 200,
            gradient_tolerance: 1e-5,
            cost_tolerance: 1e-9,
            history: 10,
            noise_floor: 1e-8,
            warm_start: None,
        }
    }
}

/// The box the fit keeps the log-hyperparameters in (see the module doc), in the order of
/// [`Hyperparameters::to_log_vector`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
}

impl Bounds {
    /// The box for a training set; `noise_floor` is the lowest `σ_n² / var(y)`.
    pub fn from_data(inputs: &Inputs, targets: &[f64], noise_floor: f64) -> Result<Self, GpError> {
        check_training(inputs, targets)?;
        if !(noise_floor > 0.0 && noise_floor < 10.0) {
            return Err(GpError::InvalidOptions(format!(
                "noise_floor {noise_floor} must lie in (0, 10)"
            )));
        }
        let scales = inputs.feature_scales();
        let sqrt_dim = (inputs.dim() as f64).sqrt();
        let v = target_scale(targets);
        let mut lower: Vec<f64> = scales.iter().map(|s| (1e-3 * s).ln()).collect();
        let mut upper: Vec<f64> = scales.iter().map(|s| (1e3 * s * sqrt_dim).ln()).collect();
        lower.extend([(1e-6 * v).ln(), (noise_floor * v).ln()]);
        upper.extend([(1e3 * v).ln(), (10.0 * v).ln()]);
        Ok(Self { lower, upper })
    }

    /// The nearest point of the box.
    pub fn clamp(&self, theta: &[f64]) -> Vec<f64> {
        theta
            .iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(t, (lo, hi))| t.clamp(*lo, *hi))
            .collect()
    }
}

/// One L-BFGS run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartOutcome {
    pub start: Hyperparameters,
    /// Where the run stopped.
    pub end: Hyperparameters,
    /// NLML at `end` (not divided by N).
    pub nlml: f64,
    pub iterations: u64,
    /// Evaluations of the NLML and its gradient (line-search trials included).
    pub evaluations: usize,
    /// Why the run stopped.
    pub termination: String,
}

/// What a fit did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// NLML of the returned model.
    pub nlml: f64,
    /// Jitter the returned model's factorisation needed (0 normally).
    pub jitter: f64,
    /// Index into `starts` of the run the model comes from.
    pub best_start: usize,
    pub starts: Vec<StartOutcome>,
    pub bounds: Bounds,
}

impl FitOptions {
    fn validate(&self, dim: usize) -> Result<(), GpError> {
        let bad = |what: String| Err(GpError::InvalidOptions(what));
        if self.starts == 0 {
            return bad("starts must be at least 1".into());
        }
        if self.history == 0 {
            return bad("history must be at least 1".into());
        }
        if !(self.gradient_tolerance >= 0.0 && self.cost_tolerance >= 0.0) {
            return bad("tolerances must be non-negative numbers".into());
        }
        if let Some(warm) = &self.warm_start {
            warm.validate(dim)?;
        }
        Ok(())
    }

    /// The hyperparameters every run starts from (see [`FitOptions::starts`]), clamped into the
    /// box.
    pub fn start_points(
        &self,
        inputs: &Inputs,
        targets: &[f64],
    ) -> Result<Vec<Hyperparameters>, GpError> {
        check_training(inputs, targets)?;
        self.validate(inputs.dim())?;
        let bounds = Bounds::from_data(inputs, targets, self.noise_floor)?;
        let dim = inputs.dim();
        let v = target_scale(targets);
        let sqrt_dim = (dim as f64).sqrt();
        // With d inputs r² sums d terms; lengthscales of sd·√d keep r = O(1) between typical
        // points. Lengthscales of one sd would put r near √(2d) ≈ 9 at d = 40, k ≈ 1e-7:
        // every point uncorrelated, a flat start from which the noise-only solution attracts.
        let mut base: Vec<f64> = inputs
            .feature_scales()
            .iter()
            .map(|s| (s * sqrt_dim).ln())
            .collect();
        base.extend([v.ln(), (1e-2 * v).ln()]);
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut starts = Vec::with_capacity(self.starts);
        for k in 0..self.starts {
            let theta = match (&self.warm_start, k) {
                (Some(warm), 0) => warm.to_log_vector(),
                (None, 0) => base.clone(),
                _ => base
                    .iter()
                    .map(|b| {
                        let step: f64 = StandardNormal.sample(&mut rng);
                        b + step
                    })
                    .collect(),
            };
            starts.push(Hyperparameters::from_log_vector(
                dim,
                &bounds.clamp(&theta),
            )?);
        }
        Ok(starts)
    }
}

/// One output's search: its start points, its box and the L-BFGS settings.
struct Search {
    starts: Vec<Hyperparameters>,
    bounds: Bounds,
    settings: Settings,
}

impl Search {
    fn new(inputs: &Inputs, targets: &[f64], options: &FitOptions) -> Result<Self, GpError> {
        Ok(Self {
            starts: options.start_points(inputs, targets)?,
            bounds: Bounds::from_data(inputs, targets, options.noise_floor)?,
            settings: Settings {
                max_iterations: options.max_iterations,
                history: options.history,
                gradient_tolerance: options.gradient_tolerance,
                cost_tolerance: options.cost_tolerance,
            },
        })
    }

    /// The L-BFGS run from start `k`, on the caller's buffers (every evaluation overwrites
    /// what it reads, so a run does not depend on what the buffers held before).
    fn run(
        &self,
        k: usize,
        work: &mut Workspace,
        inputs: &Inputs,
        targets: &[f64],
    ) -> Result<StartOutcome, GpError> {
        let dim = inputs.dim();
        let n = inputs.len() as f64;
        let start = &self.starts[k];
        let objective = |theta: &[f64]| -> Result<(f64, Vec<f64>), GpError> {
            let hyper = Hyperparameters::from_log_vector(dim, theta)?;
            let at = work.evaluate(inputs, targets, &hyper, true)?;
            Ok((at.nlml / n, at.gradient.iter().map(|g| g / n).collect()))
        };
        let r = lbfgs::minimise(
            objective,
            &start.to_log_vector(),
            &self.bounds.lower,
            &self.bounds.upper,
            &self.settings,
        )?;
        Ok(StartOutcome {
            start: start.clone(),
            end: Hyperparameters::from_log_vector(dim, &r.x)?,
            nlml: r.value * n,
            iterations: r.iterations,
            evaluations: r.evaluations,
            termination: r.termination.to_string(),
        })
    }

    /// The model at the best start's end, with the report; `runs` in the order of the starts.
    fn finish(
        self,
        inputs: &Inputs,
        targets: &[f64],
        runs: Vec<Result<StartOutcome, GpError>>,
    ) -> Result<(GaussianProcess, FitReport), GpError> {
        let mut outcomes = Vec::with_capacity(runs.len());
        let mut errors = Vec::new();
        for run in runs {
            match run {
                Ok(outcome) => outcomes.push(outcome),
                Err(e) => errors.push(e.to_string()),
            }
        }
        let best_start = outcomes
            .iter()
            .enumerate()
            .filter(|(_, o)| o.nlml.is_finite())
            .min_by(|a, b| a.1.nlml.total_cmp(&b.1.nlml))
            .map(|(i, _)| i)
            .ok_or_else(|| GpError::FitFailed(errors.join("; ")))?;
        let hyper = outcomes[best_start].end.clone();
        let model = GaussianProcess::new(inputs.clone(), targets.to_vec(), hyper)?;
        let report = FitReport {
            nlml: model.negative_log_marginal_likelihood(),
            jitter: model.jitter(),
            best_start,
            starts: outcomes,
            bounds: self.bounds,
        };
        Ok((model, report))
    }
}

impl GaussianProcess {
    /// Type-II ML hyperparameters for one output (see the module doc for the search), then the
    /// model at them. Single-threaded: [`GaussianProcess::fit_many`] fits several outputs in
    /// parallel threads.
    pub fn fit(
        inputs: &Inputs,
        targets: &[f64],
        options: &FitOptions,
    ) -> Result<(Self, FitReport), GpError> {
        let search = Search::new(inputs, targets, options)?;
        // One set of N × N buffers for every evaluation of every start.
        let mut work = Workspace::new(inputs.len());
        let runs = (0..search.starts.len())
            .map(|k| search.run(k, &mut work, inputs, targets))
            .collect();
        search.finish(inputs, targets, runs)
    }

    /// [`GaussianProcess::fit`] for several outputs on the same inputs (the corrector's floors),
    /// on `threads` threads: every (output, start) run is one task, taken from a shared queue
    /// by the next free thread (longest first is not known in advance, so in order), each
    /// thread with its own `N × N` buffers. Each run is the same computation as in `fit`, so
    /// the results are those of `fit` on each output, bit for bit, whatever `threads` is.
    pub fn fit_many(
        inputs: &Inputs,
        targets: &[&[f64]],
        options: &FitOptions,
        threads: usize,
    ) -> Vec<Result<(Self, FitReport), GpError>> {
        let searches: Vec<Result<Search, GpError>> = targets
            .iter()
            .map(|y| Search::new(inputs, y, options))
            .collect();
        let tasks: Vec<(usize, usize)> = searches
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.as_ref().ok().map(|s| (i, s.starts.len())))
            .flat_map(|(i, starts)| (0..starts).map(move |k| (i, k)))
            .collect();
        let next = AtomicUsize::new(0);
        let threads = threads.clamp(1, tasks.len().max(1));
        let work = || {
            let mut buffers = Workspace::new(inputs.len());
            let mut done = Vec::new();
            loop {
                let t = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(i, k)) = tasks.get(t) else {
                    return done;
                };
                if let Ok(search) = &searches[i] {
                    done.push((t, search.run(k, &mut buffers, inputs, targets[i])));
                }
            }
        };
        let mut finished: Vec<(usize, Result<StartOutcome, GpError>)> = if threads == 1 {
            work()
        } else {
            std::thread::scope(|scope| {
                let handles: Vec<_> = (1..threads).map(|_| scope.spawn(work)).collect();
                let mut all = work();
                for h in handles {
                    match h.join() {
                        Ok(done) => all.extend(done),
                        Err(payload) => std::panic::resume_unwind(payload),
                    }
                }
                all
            })
        };
        finished.sort_by_key(|(t, _)| *t);
        let mut runs: Vec<Vec<Result<StartOutcome, GpError>>> =
            targets.iter().map(|_| Vec::new()).collect();
        for (t, run) in finished {
            runs[tasks[t].0].push(run);
        }
        searches
            .into_iter()
            .zip(runs)
            .zip(targets)
            .map(|((search, runs), y)| search?.finish(inputs, y, runs))
            .collect()
    }

    /// Fits again on the model's current training set, the first run warm-started from its
    /// current hyperparameters (unless `options.warm_start` names others); replaces the model
    /// only when the fit succeeds.
    pub fn refit(&mut self, options: &FitOptions) -> Result<FitReport, GpError> {
        let mut options = options.clone();
        if options.warm_start.is_none() {
            options.warm_start = Some(self.hyperparameters().clone());
        }
        let (model, report) = Self::fit(self.inputs(), self.targets(), &options)?;
        *self = model;
        Ok(report)
    }
}
