//! Long records fitted along a ladder of their heads.
//!
//! A long record's likelihood has narrow basins around the structure's frequencies: the phase
//! of a mode drifts by `Δω · T` over a record of duration `T`, so a start whose frequency is off
//! by more than about `π / T` sits on another hill. On 16,384 samples one start ended in a poor
//! basin (7–37 % NMSE) where twelve starts on 1,024 samples all found the optimum, and a start
//! cost sixteen times as much. So, when the longest record has more than twice [`STRETCH`]
//! samples, the starts are screened and raced on the first [`STRETCH`] samples of every record
//! (where the basins are wide and a fit is cheap); the best start's optimum (parameters and
//! noise) then starts a fit on heads [`RUNG`] times longer, and so on up to every sample. Each
//! rung's fit begins within its basin and ends in a few iterations; the last is on the whole
//! records, so the estimates and the posterior are those of all samples (to the fit's stopping
//! gain, [`FINE_GAIN`](super::FINE_GAIN)).

use super::starts::{finish_start, screened_starts, Running, StartResult};
use super::target::Target;
use super::{record_targets, CalibrateError, CalibrationSetup, RecordInput, StartOutcome};
use crate::cosim::import::Fmu;
use crate::twin::data::Measurement;
use crate::twin::Component;

/// Samples of every record's head the starts are screened on (when the longest record has more
/// than twice as many): on a record at 51.2 Hz 40 s, at 500 Hz 4 s — ten or more periods of a
/// frame's first mode above 2.5 Hz.
pub const STRETCH: usize = 2048;

/// Each rung of the ladder is this many times the one before (the last is every sample).
pub const RUNG: usize = 4;

/// The head lengths fitted before all samples, for records of at most `longest` samples: none
/// up to 2 × [`STRETCH`]; then [`STRETCH`], × [`RUNG`], … while twice the rung is still short of
/// `longest` (so the last step to every sample is less than 2 × [`RUNG`]).
pub fn rungs(longest: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut n = STRETCH;
    while 2 * n < longest {
        out.push(n);
        n *= RUNG;
    }
    out
}

/// What the climb found: every start's outcome (a start that stopped on a head has that head's
/// objective, and counts as screened out), the simulations of every rung, the best start at
/// every sample, and the heads fitted before (empty: the starts ran on every sample).
pub(super) struct Climb {
    pub outcomes: Vec<StartOutcome>,
    pub simulations: usize,
    pub best: Option<StartResult>,
    pub heads: Vec<usize>,
}

/// The starts screened on the records' heads and the best climbed to every sample (see the
/// module); on records no longer than 2 × [`STRETCH`], or when a head leaves too few samples
/// or the climb's fit fails, the starts run on every sample as they always did.
pub(super) fn climb(
    fmu: &Fmu,
    component: &Component,
    setup: &CalibrationSetup,
    inputs: &[RecordInput],
    full: &Target,
    starts: &[Vec<f64>],
    threads: usize,
) -> Result<Climb, CalibrateError> {
    let longest = inputs.iter().map(|i| i.data.len()).max().unwrap_or(0);
    let heads = if setup.climb {
        rungs(longest)
    } else {
        Vec::new()
    };
    // The records' heads, rung by rung.
    let cut: Vec<Vec<Measurement>> = heads
        .iter()
        .map(|&n| inputs.iter().map(|i| i.data.head(n)).collect())
        .collect();
    if let Some(targets) = head_targets(fmu, component, setup, inputs, full, &cut) {
        if let Some(climbed) = up_the_ladder(&targets, full, starts, threads)? {
            return Ok(Climb { heads, ..climbed });
        }
    }
    let (outcomes, simulations, best) = screened_starts(full, starts, full.priors.len(), threads)?;
    Ok(Climb {
        outcomes,
        simulations,
        best,
        heads: Vec::new(),
    })
}

/// Each rung's target: the records' heads `cut` (with their masks cut alike) and the full
/// target's parameters and priors. None when there is no rung or a head leaves a record too few
/// samples after the transient and the mask.
fn head_targets<'a>(
    fmu: &'a Fmu,
    component: &Component,
    setup: &CalibrationSetup,
    inputs: &[RecordInput<'a>],
    full: &Target,
    cut: &'a [Vec<Measurement>],
) -> Option<Vec<Target<'a>>> {
    if cut.is_empty() {
        return None;
    }
    cut.iter()
        .map(|measurements| {
            let head_inputs: Vec<RecordInput> = inputs
                .iter()
                .zip(measurements)
                .map(|(i, data)| RecordInput {
                    data,
                    mask: i.mask.map(|m| &m[..data.len().min(m.len())]),
                })
                .collect();
            let (records, _) = record_targets(fmu, &head_inputs, setup).ok()?;
            Some(Target::new(
                fmu,
                component,
                setup,
                records,
                full.vrs.clone(),
                full.priors.clone(),
            ))
        })
        .collect()
}

/// The starts screened and raced on the first rung, the best refined on each higher one and on
/// `full` (None when no start finished, or a refinement failed). The heads are the caller's.
fn up_the_ladder(
    targets: &[Target],
    full: &Target,
    starts: &[Vec<f64>],
    threads: usize,
) -> Result<Option<Climb>, CalibrateError> {
    let p = full.priors.len();
    let (mut outcomes, mut simulations, best) = screened_starts(&targets[0], starts, p, threads)?;
    let Some(mut best) = best else {
        return Ok(None);
    };
    for target in targets[1..].iter().chain(std::iter::once(full)) {
        let mut sims = super::simulators(target, "ladder")?;
        let from = Running {
            z: best.z.clone(),
            s: best.s.clone(),
            fine: true,
            done: false,
            outer: 0,
            evaluations: 0,
            runs: 0,
            objective: f64::INFINITY,
            at_hand: None,
        };
        let Some(next) = finish_start(&mut sims, target, from, target.budget) else {
            return Ok(None);
        };
        simulations += next.runs;
        best = StartResult {
            runs: best.runs + next.runs,
            ..next
        };
    }
    // The best start is the one whose objective on the first head is lowest and that went on.
    let leader = outcomes
        .iter()
        .filter(|o| !o.screened_out)
        .min_by(|a, b| a.neg_log_posterior.total_cmp(&b.neg_log_posterior))
        .map(|o| o.start);
    for o in &mut outcomes {
        if Some(o.start) == leader {
            o.neg_log_posterior = best.objective;
            o.evaluations = best.runs;
        } else {
            o.screened_out = true;
        }
    }
    Ok(Some(Climb {
        outcomes,
        simulations,
        best: Some(best),
        heads: Vec::new(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ladder_climbs_by_rungs_and_ends_short_of_every_sample() {
        assert!(rungs(1024).is_empty());
        assert!(rungs(2 * STRETCH).is_empty());
        assert_eq!(rungs(2 * STRETCH + 1), vec![STRETCH]);
        assert_eq!(rungs(15_000), vec![2048]);
        assert_eq!(rungs(16_384), vec![2048]);
        assert_eq!(rungs(131_072), vec![2048, 8192, 32_768]);
        for longest in [5_000, 40_000, 360_000] {
            let r = rungs(longest);
            let last = *r.last().unwrap();
            assert!(longest < 2 * RUNG * last, "{longest}: {r:?}");
        }
    }
}
