//! The GPs' initial fit on the first points, and their refits as the training set grows.

use super::results::RefitRecord;
use super::stream::{trained, Stream};
use super::{refit_iterations, LearnError, LearnOptions, Result};
use fmu_gp_corrector::model::FitOptions;
use fmu_gp_corrector::{Floors, Layout, LayoutTraining};

/// Fit the initial GPs on the first `initial` points after the first record's transient.
pub fn initial_floors(streams: &[Stream], options: &LearnOptions) -> Result<Floors> {
    let Some(first) = streams.first() else {
        return Err(LearnError::Setup("no record to learn from".into()));
    };
    let end = first.first + options.initial;
    if options.initial == 0 || end >= first.len() {
        return Err(LearnError::Setup(format!(
            "{}: needs more than {} samples after the transient",
            first.name, options.initial
        )));
    }
    fit_floors(
        &first.layout,
        first.inputs[first.first..end].to_vec(),
        first.targets[first.first..end].to_vec(),
        options,
    )
    .map_err(|e| LearnError::In {
        context: "the initial GPs",
        source: Box::new(e),
    })
}

/// The channels' GPs fitted (type-II ML, the corrector's initial fit) on a training set.
pub(super) fn fit_floors(
    layout: &Layout,
    inputs: Vec<Vec<f64>>,
    targets: Vec<Vec<f64>>,
    options: &LearnOptions,
) -> Result<Floors> {
    Floors::fit_training(&LayoutTraining {
        channels: layout.names(),
        excitation: layout.excitation_name(),
        lags: options.lags,
        target: options.target,
        inputs,
        targets,
        hyperparameters: None,
    })
    .map_err(|e| LearnError::Gp(e.to_string()))
}

/// When the hyperparameters are refitted (see the module doc).
#[derive(Clone, Debug)]
pub struct RefitSchedule {
    pub min_queries: u32,
    pub growth: f64,
    /// Training points at the last fit.
    pub points_at_fit: usize,
    /// Queries since then.
    pub since: usize,
}

impl RefitSchedule {
    pub fn new(options: &LearnOptions, points_at_fit: usize) -> Self {
        RefitSchedule {
            min_queries: options.refit_every,
            growth: options.refit_growth,
            points_at_fit,
            since: 0,
        }
    }

    /// One more query; whether a refit is now due.
    pub fn query(&mut self) -> bool {
        self.since += 1;
        self.min_queries > 0
            && self.since >= self.min_queries as usize
            && self.since as f64 >= self.growth * self.points_at_fit as f64
    }

    /// A refit was done on `points` training points.
    pub fn refitted(&mut self, points: usize) {
        self.points_at_fit = points;
        self.since = 0;
    }
}

/// A warm-started refit of the three floors' hyperparameters (in parallel threads), at most
/// [`refit_iterations`] L-BFGS iterations, recorded.
pub(super) fn refit_floors(
    floors: &mut Floors,
    options: &LearnOptions,
    record: usize,
    query: usize,
    end_of_record: bool,
) -> Result<RefitRecord> {
    let clock = std::time::Instant::now();
    let m = floors.gps.len();
    let nlml_before: Vec<f64> = (0..m)
        .map(|f| {
            trained(&floors.gps[f])
                .map(|gp| gp.negative_log_marginal_likelihood())
                .unwrap_or(f64::NAN)
        })
        .collect();
    let fit = FitOptions {
        max_iterations: refit_iterations(options.refit_iterations, floors.len()),
        ..fmu_gp_corrector::model::refit_options()
    };
    let reports = floors
        .refit_with(&fit)
        .map_err(|e| LearnError::Gp(e.to_string()))?;
    let best = |f: usize| {
        reports[f]
            .as_ref()
            .map(|r| (r.nlml, r.starts[r.best_start].clone()))
    };
    let hyper = |f: usize| trained(&floors.gps[f]).map(|gp| gp.hyperparameters());
    Ok(RefitRecord {
        record,
        query,
        end_of_record,
        training_points: floors.len(),
        seconds: clock.elapsed().as_secs_f64(),
        iterations: (0..m)
            .map(|f| best(f).map_or(0, |b| b.1.iterations))
            .collect(),
        nlml_before,
        nlml_after: (0..m).map(|f| best(f).map_or(f64::NAN, |b| b.0)).collect(),
        termination: (0..m)
            .map(|f| best(f).map_or_else(String::new, |b| b.1.termination))
            .collect(),
        signal_variance: (0..m)
            .map(|f| hyper(f).map_or(f64::NAN, |h| h.signal_variance()))
            .collect(),
        noise_variance: (0..m)
            .map(|f| hyper(f).map_or(f64::NAN, |h| h.noise_variance()))
            .collect(),
    })
}
