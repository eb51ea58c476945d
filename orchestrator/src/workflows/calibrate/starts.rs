//! The multi-start search: each start's outer iterations (the fit, then the noise's optimum),
//! the race after the first, and the starts on threads.

use super::lm;
use super::prior::{Prior, Space};
use super::problem::Problem;
use super::target::{raw_residuals, simulators, sse_per_block, ModelNormals, Target};
use super::{CalibrationSetup, StartOutcome, SCREEN_EVALUATIONS_PER_PARAMETER, SCREEN_KEEP};
use crate::twin::simulator::Simulator;
use crate::twin::TwinError;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::StandardNormal;
use std::cell::RefCell;
use std::collections::BTreeMap;

/// A fit under noise weights still on their way stops when its next step is predicted to gain
/// less than this (nats of the negative log posterior): about 0.14 posterior sd along the step.
pub const COARSE_GAIN: f64 = 1e-2;
/// The fit under settled noise weights stops below this gain: about 0.004 posterior sd, far
/// below anything a report shows (the steps it saves each moved the estimates by less).
pub const FINE_GAIN: f64 = 1e-5;
/// The noise estimates (log variances) have all but settled when no block's moved by more
/// than this in an outer iteration.
pub(super) const NOISE_NEARLY_SETTLED: f64 = 0.1;

/// Newton on `N s/2 + SSE e^{−s}/2 + (s − μ)²/(2v)`, convex in s.
pub(super) fn optimal_log_noise(n: f64, sse: f64, mean: f64, var: f64, start: f64) -> f64 {
    let mut s = start;
    for _ in 0..50 {
        let g = n / 2.0 - sse * (-s).exp() / 2.0 + (s - mean) / var;
        let h = sse * (-s).exp() / 2.0 + 1.0 / var;
        let step = g / h;
        s -= step.clamp(-5.0, 5.0);
        if step.abs() < 1e-12 {
            break;
        }
    }
    s
}

pub(super) fn neg_log_posterior(target: &Target, sse: &[f64], s: &[f64], z: &[f64]) -> f64 {
    let mut j = 0.5 * z.iter().map(|x| x * x).sum::<f64>();
    for (((&(_, n), sse), s), mean) in target
        .blocks()
        .iter()
        .zip(sse)
        .zip(s)
        .zip(target.noise_means())
    {
        j += n as f64 * s / 2.0
            + sse * (-s).exp() / 2.0
            + (s - mean).powi(2) / (2.0 * target.noise_var);
    }
    j
}

pub(super) struct StartResult {
    pub(super) z: Vec<f64>,
    /// log σ² of every block (record, floor).
    pub(super) s: Vec<f64>,
    pub(super) objective: f64,
    /// FMU runs made.
    pub(super) runs: usize,
}

/// A start on its way: the parameters and noise after its outer iterations so far.
pub(super) struct Running {
    pub(super) z: Vec<f64>,
    /// log σ² of every block (record, floor).
    pub(super) s: Vec<f64>,
    /// The next fit is a fine one (the noise has all but settled).
    pub(super) fine: bool,
    /// The noise has settled after a fine fit: the start is done.
    pub(super) done: bool,
    pub(super) outer: usize,
    pub(super) evaluations: usize,
    pub(super) runs: usize,
    /// The negative log posterior at (z, s).
    pub(super) objective: f64,
    /// The model's normal equations at `z`, from the last trial of the fit before: the next
    /// outer iteration's fit starts there without running it again.
    pub(super) at_hand: Option<(Vec<f64>, ModelNormals)>,
}

/// Outer iterations a start makes at most: a fit of the parameters under fixed noise weights,
/// then the noise's own optimum for those parameters.
pub(super) const OUTER_ITERATIONS: usize = 6;

/// A start from `z0`, the noise at its priors' means, before any iteration.
pub(super) fn new_start(target: &Target, z0: Vec<f64>) -> Running {
    Running {
        z: z0,
        s: target.noise_means(),
        fine: false,
        done: false,
        outer: 0,
        evaluations: 0,
        runs: 0,
        objective: f64::INFINITY,
        at_hand: None,
    }
}

/// One outer iteration of `start` within `budget` evaluations in all: the parameters fitted
/// under the current noise weights, then the noise's optimum for them. None when the FMU
/// refused the parameters.
pub(super) fn outer_iteration<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    start: &mut Running,
    budget: usize,
) -> Option<()> {
    let blocks = target.blocks();
    let means = target.noise_means();
    let records = target.records.len();
    let mut buf: Vec<Vec<f64>> = Vec::new();
    // The noise starts at its prior's mean, usually far from the record's: the fit under those
    // weights is only a way to the next noise estimate, and stops at a coarse gain
    // ([`COARSE_GAIN`]); once the noise has all but settled the fit goes on to [`FINE_GAIN`].
    // The last fit is always a fine one.
    let settings = lm::Settings {
        min_predicted: if start.fine { FINE_GAIN } else { COARSE_GAIN },
        ..lm::Settings::default()
    };
    let mut weights = Vec::with_capacity(target.rows());
    for (&(_, n), sb) in blocks.iter().zip(&start.s) {
        weights.extend(std::iter::repeat((-sb / 2.0).exp()).take(n));
    }
    let mut problem = Problem {
        sims: RefCell::new(&mut *sims),
        target,
        weights,
        buf: RefCell::new(Default::default()),
        evaluations: RefCell::new(0),
        runs: RefCell::new(0),
        at_hand: RefCell::new(start.at_hand.take()),
        last: RefCell::new(None),
        budget: budget.saturating_sub(start.evaluations),
    };
    let z = std::mem::take(&mut start.z);
    start.z = match problem.weighted(&z) {
        Some(r0) => lm::minimize(&mut problem, z, r0, settings).0,
        None => z,
    };
    start.evaluations += *problem.evaluations.borrow();
    start.runs += *problem.runs.borrow();
    start.at_hand = problem.at_hand.take().filter(|(at, _)| *at == start.z);
    // The fit's last trial is usually where it ended (a fit stops on the step it would take
    // next, untried): its residuals are at hand.
    let r = match problem.last.take() {
        Some((at, r)) if at == start.z => r,
        _ => {
            start.evaluations += 1;
            start.runs += records;
            raw_residuals(sims, target, &start.z, &mut buf)?
        }
    };
    let sse = sse_per_block(&r, &blocks);
    let s_new: Vec<f64> = (0..blocks.len())
        .map(|b| {
            optimal_log_noise(
                blocks[b].1 as f64,
                sse[b],
                means[b],
                target.noise_var,
                start.s[b],
            )
        })
        .collect();
    let moved = s_new
        .iter()
        .zip(&start.s)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    start.s = s_new;
    start.objective = neg_log_posterior(target, &sse, &start.s, &start.z);
    start.outer += 1;
    start.done = (moved < 1e-3 && start.fine) || start.outer >= OUTER_ITERATIONS;
    start.fine = moved < NOISE_NEARLY_SETTLED;
    Some(())
}

/// Run `start` on to its end within `budget` evaluations in all.
pub(super) fn finish_start<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    mut start: Running,
    budget: usize,
) -> Option<StartResult> {
    // The last outer iteration leaves the objective at the start's final (z, s): no run more.
    while !start.done {
        outer_iteration(sims, target, &mut start, budget)?;
    }
    start.objective.is_finite().then_some(StartResult {
        z: start.z,
        s: start.s,
        objective: start.objective,
        runs: start.runs,
    })
}

/// One start from `z0` (the noise from its priors' means), within `budget` evaluations.
pub(super) fn run_start<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z0: Vec<f64>,
    budget: usize,
) -> Option<StartResult> {
    finish_start(sims, target, new_start(target, z0), budget)
}

/// Starts whose negative log posterior after their first outer iteration is more than this
/// above the best start's stop there (nats). Measured on dataset3's diagnosis (58 starts of 16
/// fits): a start near its fit's best gained at most 14 nats after its first outer iteration
/// (a start far behind, up to 183 — still thousands of nats behind).
pub const RACE_MARGIN: f64 = 50.0;
/// Two starts whose parameters (in prior standard deviations) after their first outer
/// iteration differ by less than this in every coordinate have reached the same optimum (the
/// same fit's starts there differed by at most 0.012; distinct optima by 0.2 or more): only
/// the better goes on.
pub const SAME_OPTIMUM: f64 = 0.05;

/// The race after the first outer iteration: the starts (index, state) that go on — the best,
/// and every other within [`RACE_MARGIN`] of it at an optimum of its own — and those that stop.
pub(super) fn race(
    mut first: Vec<(usize, Running)>,
) -> (Vec<(usize, Running)>, Vec<(usize, Running)>) {
    first.sort_by(|a, b| a.1.objective.total_cmp(&b.1.objective));
    let best = first.first().map_or(f64::INFINITY, |b| b.1.objective);
    let (mut going, mut stopped) = (Vec::new(), Vec::new());
    for (i, start) in first {
        let behind = start.objective > best + RACE_MARGIN;
        let same = going.iter().any(|(_, kept): &(usize, Running)| {
            kept.z
                .iter()
                .zip(&start.z)
                .all(|(a, b)| (a - b).abs() < SAME_OPTIMUM)
        });
        if behind || same {
            stopped.push((i, start));
        } else {
            going.push((i, start));
        }
    }
    (going, stopped)
}

/// Every start for a few iterations, then the best [`SCREEN_KEEP`] on (the screen: more starts
/// than that, and a budget above the screen's); then every start still going for its first
/// outer iteration, and the [`race`]'s on to their end. Every start's outcome, the simulations
/// spent, and the best start.
pub(super) fn screened_starts(
    target: &Target,
    starts: &[Vec<f64>],
    p: usize,
    threads: usize,
) -> Result<(Vec<StartOutcome>, usize, Option<StartResult>), TwinError> {
    let screen_budget = SCREEN_EVALUATIONS_PER_PARAMETER * (p + 1);
    let screening = starts.len() > SCREEN_KEEP && target.budget > screen_budget;
    let mut jobs: Vec<StartJob> = starts.iter().cloned().enumerate().collect();
    let mut outcomes = Vec::new();
    let mut simulations = 0;
    let mut stop = |i: usize, objective: f64, runs: usize| {
        simulations += runs;
        outcomes.push(StartOutcome {
            start: i,
            neg_log_posterior: objective,
            evaluations: runs,
            screened_out: true,
        });
    };
    let mut spent = BTreeMap::new();
    let mut budget = target.budget;
    if screening {
        let mut first = run_starts(target, jobs, screen_budget, threads)?;
        first.sort_by(|a, b| match (&a.1, &b.1) {
            (Some(x), Some(y)) => x.objective.total_cmp(&y.objective),
            (Some(_), None) => std::cmp::Ordering::Less,
            (None, Some(_)) => std::cmp::Ordering::Greater,
            (None, None) => a.0.cmp(&b.0),
        });
        let rest = first.split_off(SCREEN_KEEP.min(first.len()));
        for (i, res) in rest.into_iter() {
            if let Some(res) = res {
                stop(i, res.objective, res.runs);
            }
        }
        jobs = first
            .into_iter()
            .filter_map(|(i, res)| {
                let res = res?;
                spent.insert(i, res.runs);
                // The noise starts again from its prior mean, as every start does: from the
                // screen's (a poor fit's) larger noise the prior outweighs the data and the
                // outer iterations end before the fit is done.
                Some((i, res.z))
            })
            .collect();
        budget = target.budget.saturating_sub(screen_budget);
    }
    // The first outer iteration of every start still going, the race, the rest to the end: a
    // start the screen kept can still be far behind (on two long roving runs one of the three
    // kept wandered for its whole budget, ten times the winner's simulations).
    let first = on_threads(target, jobs, threads, |sims, (i, z0)| {
        let mut start = new_start(target, z0);
        (
            i,
            outer_iteration(sims, target, &mut start, budget).map(|()| start),
        )
    })?;
    let (going, stopped) = race(
        first
            .into_iter()
            .filter_map(|(i, s)| Some((i, s?)))
            .collect(),
    );
    let before = |i: usize| spent.get(&i).copied().unwrap_or(0);
    for (i, start) in stopped {
        stop(i, start.objective, start.runs + before(i));
    }
    let finished = on_threads(target, going, threads, |sims, (i, start)| {
        (i, finish_start(sims, target, start, budget))
    })?;
    let mut best: Option<StartResult> = None;
    for (i, res) in finished {
        let Some(mut res) = res else { continue };
        res.runs += before(i);
        simulations += res.runs;
        outcomes.push(StartOutcome {
            start: i,
            neg_log_posterior: res.objective,
            evaluations: res.runs,
            screened_out: false,
        });
        if best.as_ref().map_or(true, |b| res.objective < b.objective) {
            best = Some(res);
        }
    }
    outcomes.sort_by_key(|o| o.start);
    Ok((outcomes, simulations, best))
}

/// A start: its index and parameters.
pub(super) type StartJob = (usize, Vec<f64>);

/// The starts `jobs` within `budget` evaluations each, over `threads` threads (one FMU instance
/// each), in no particular order.
pub(super) fn run_starts(
    target: &Target,
    jobs: Vec<StartJob>,
    budget: usize,
    threads: usize,
) -> Result<Vec<(usize, Option<StartResult>)>, TwinError> {
    on_threads(target, jobs, threads, |sims, (i, z0)| {
        (i, run_start(sims, target, z0, budget))
    })
}

/// `work` on every job over `threads` threads, each with simulators of its own (one FMU
/// instance per record), results in no particular order.
pub(super) fn on_threads<'a, J: Send, T: Send>(
    target: &Target<'a>,
    jobs: Vec<J>,
    threads: usize,
    work: impl Fn(&mut [Simulator<'a>], J) -> T + Sync,
) -> Result<Vec<T>, TwinError> {
    let threads = threads.clamp(1, jobs.len().max(1));
    if threads == 1 {
        // One thread's work on this one: no thread to start and schedule, no fresh heap.
        let mut sims = simulators(target, "calibration")?;
        return Ok(jobs.into_iter().map(|job| work(&mut sims, job)).collect());
    }
    let mut chunks: Vec<Vec<J>> = (0..threads).map(|_| Vec::new()).collect();
    for (k, job) in jobs.into_iter().enumerate() {
        chunks[k % threads].push(job);
    }
    let work = &work;
    let results: Vec<Result<Vec<T>, TwinError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|chunk| {
                scope.spawn(move || -> Result<Vec<T>, TwinError> {
                    let mut sims = simulators(target, "calibration")?;
                    Ok(chunk.into_iter().map(|job| work(&mut sims, job)).collect())
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(TwinError::Invalid {
                        path: "calibration".into(),
                        message: "a worker thread panicked".into(),
                    })
                })
            })
            .collect()
    });
    let mut out = Vec::new();
    for r in results {
        out.extend(r?);
    }
    Ok(out)
}
/// The starts, in the priors' standardised coordinates: the prior mean (or `setup.initial`),
/// then the values `setup.starts_at`, then draws from the prior widened ×3.
pub(super) fn starts(setup: &CalibrationSetup, priors: &[Prior]) -> Vec<Vec<f64>> {
    let mut rng = StdRng::seed_from_u64(setup.seed);
    let p = setup.parameters.len();
    let at = |given: &BTreeMap<String, f64>| -> Vec<f64> {
        setup
            .parameters
            .iter()
            .zip(priors)
            .map(|(name, prior)| match given.get(name) {
                Some(&v) if prior.space == Space::Linear || v > 0.0 => {
                    (prior.coordinate(v) - prior.mean) / prior.sd()
                }
                _ => 0.0,
            })
            .collect()
    };
    (0..setup.starts.max(1))
        .map(|i| {
            if i == 0 {
                at(&setup.initial)
            } else if let Some(given) = setup.starts_at.get(i - 1) {
                at(given)
            } else {
                (0..p)
                    .map(|_| 3.0 * rng.sample::<f64, _>(StandardNormal))
                    .collect()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(objective: f64, z: &[f64]) -> Running {
        Running {
            z: z.to_vec(),
            s: Vec::new(),
            fine: false,
            done: false,
            outer: 1,
            evaluations: 10,
            runs: 10,
            objective,
            at_hand: None,
        }
    }

    /// The race keeps the best start and every start within the margin at an optimum of its
    /// own; a start behind by more than the margin, or at the best's optimum, stops.
    #[test]
    fn the_race_keeps_the_best_and_the_distinct_near_it() {
        let first = vec![
            (0, at(-1000.0, &[0.5, 0.2])),
            (1, at(-2000.0, &[0.9, 0.0])),
            // The best's optimum, a little behind it.
            (
                2,
                at(-1999.0, &[0.9 + 0.4 * SAME_OPTIMUM, -0.4 * SAME_OPTIMUM]),
            ),
            // Another optimum, within the margin.
            (3, at(-2000.0 + 0.9 * RACE_MARGIN, &[-0.3, 0.0])),
            // Another optimum, beyond the margin.
            (4, at(-2000.0 + 1.1 * RACE_MARGIN, &[2.0, 1.0])),
        ];
        let (going, stopped) = race(first);
        let going: Vec<usize> = going.iter().map(|g| g.0).collect();
        let mut stopped: Vec<usize> = stopped.iter().map(|s| s.0).collect();
        stopped.sort();
        assert_eq!(
            going,
            vec![1, 3],
            "the best first, then the distinct one near it"
        );
        assert_eq!(stopped, vec![0, 2, 4]);
    }
}
