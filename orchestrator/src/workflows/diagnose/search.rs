//! Stage 5, select: whether the recalibration explains the error, the forward selection over
//! the library's effects from round 1's fits ([`super::select`]), and, when neither explains
//! it, discovery of the missing force by sparse regression ([`super::discover`]).

use std::collections::BTreeMap;

use structure::effects::Term;

use super::baseline::Baseline;
use super::channels::worst;
use super::fit::Fitted;
use super::physics::PhysicsRun;
use super::round_one::RoundOne;
use super::{discover, select, Diagnosis, Gates, Result};

/// Whether the recalibration explains the error: it cuts the worst-floor held-out NMSE by
/// [`Gates::required_cut`] and brings every channel within
/// [`Gates::recalibration_noise_factor`] × its noise level.
pub(super) fn recalibration_explains(
    b: &Baseline,
    gates: &Gates,
    round: &RoundOne,
    before_worst: f64,
) -> bool {
    round.recal_worst * gates.required_cut <= before_worst
        && (0..b.nc).all(|c| {
            round.recal.nmse_held_out[c]
                <= gates.recalibration_noise_factor * b.scores.noise_nmse_held_out[c]
        })
}

/// Stage 5: whether the recalibration explains the error, and, when the error is to be
/// explained (`explain`), the forward selection (see [`select`]) from round 1's fits, the
/// candidates that passed alone first; its steps go into the diagnosis.
pub(super) fn search_library(
    ctx: &select::Context,
    b: &Baseline,
    diagnosis: &mut Diagnosis,
    round: &RoundOne,
    before_worst: f64,
    explain: bool,
) -> Result<Search> {
    let gates = ctx.options.gates;
    let recal_explains = recalibration_explains(b, &gates, round, before_worst);
    let selection = if explain {
        let passes: Vec<bool> = diagnosis.candidates.iter().map(|c| c.passes).collect();
        Some(select::forward(
            ctx,
            &round.fitted,
            &passes,
            &round.recal,
            before_worst,
            &|what| ctx.options.tell(what),
        )?)
    } else {
        None
    };
    if let Some(s) = &selection {
        diagnosis.selection = s.steps.clone();
    }
    Ok(Search {
        selection,
        gates,
        recal_explains,
        before_worst,
        recal_worst: round.recal_worst,
    })
}

/// The library's combination when it passes: the selection, its final fit and that fit's
/// worst-floor held-out NMSE.
pub(super) type Combination<'s> = (&'s select::Selection, &'s Fitted, f64);

/// The library's search after round 1: the forward selection, when it ran, and what discovery
/// and the decision read beside it.
pub(super) struct Search {
    pub(super) selection: Option<select::Selection>,
    pub(super) gates: Gates,
    /// The recalibration alone explains the error ([`recalibration_explains`]).
    pub(super) recal_explains: bool,
    /// Worst-floor held-out NMSE of the twin as given, and after recalibration.
    pub(super) before_worst: f64,
    pub(super) recal_worst: f64,
}

impl Search {
    /// The selection's model when it meets, as a whole, the gates a single effect meets: a cut
    /// of [`Gates::required_cut`] and [`Gates::beat_recalibration`] against the recalibration.
    pub(super) fn combination(&self) -> Option<Combination<'_>> {
        let gates = self.gates;
        self.selection.as_ref().and_then(|s| {
            if s.chosen.is_empty() {
                return None;
            }
            let fitted = s.fitted.as_ref()?;
            let w = worst(&fitted.nmse_held_out);
            (w * gates.required_cut <= self.before_worst
                && w * gates.beat_recalibration <= self.recal_worst)
                .then_some((s, fitted, w))
        })
    }
}

/// What discovery gave, and the library's combination it leaves standing.
pub(super) struct Discovery<'s> {
    /// What it found, and its terms and fit when they pass the gates; None when it did not
    /// run.
    pub(super) found: Option<discover::Discovered>,
    /// The library's combination, unless discovery's passing terms replace it.
    pub(super) combination: Option<Combination<'s>>,
    /// The library's combination passed but left the model short of good enough.
    pub(super) combination_short: bool,
}

impl Discovery<'_> {
    /// The discovered terms and their fit, when they pass the gates.
    pub(super) fn passes(&self) -> Option<&(Vec<Term>, Fitted)> {
        self.found.as_ref().and_then(|d| d.1.as_ref())
    }
}

/// Stage 7, discovery: when neither recalibration nor any combination of library effects
/// explains the error, the missing force by sparse regression on top of the selection's model
/// (see [`discover`]), refitted through FMI as the FMU's `discovered` effect and gated the same
/// way. Also when the library's combination passes but leaves the model short of good enough:
/// then discovery on the twin's own physics (`base_run`) competes with it, and replaces it when
/// its held-out error is lower by the step gate. What it found goes into the diagnosis.
pub(super) fn discovery<'s>(
    ctx: &select::Context,
    base_run: &PhysicsRun,
    search: &'s Search,
    diagnosis: &mut Diagnosis,
) -> Result<Discovery<'s>> {
    let combination = search.combination();
    let combination_short =
        combination.is_some_and(|(_, fitted, _)| !ctx.good_enough(&fitted.nmse_held_out));
    let found = match &search.selection {
        Some(s) if combination.is_none() && !search.recal_explains => {
            ctx.options
                .tell("discovering the missing force by sparse regression");
            let run = s.fitted.as_ref().map(|f| &f.run).unwrap_or(base_run);
            Some(discover::missing(
                ctx,
                &s.chosen,
                &s.values,
                run,
                search.before_worst,
                search.recal_worst,
            )?)
        }
        Some(_) if combination_short => {
            ctx.options
                .tell("the library's answer leaves more than the noise: discovering");
            let d = discover::missing(
                ctx,
                &[],
                &BTreeMap::new(),
                base_run,
                search.before_worst,
                search.recal_worst,
            )?;
            let better = |(_, fitted): &(Vec<_>, Fitted)| {
                combination.is_some_and(|(_, _, w)| {
                    worst(&fitted.nmse_held_out) * search.gates.step_cut <= w
                })
            };
            Some((d.0, d.1.filter(better)))
        }
        _ => None,
    };
    let replaced = found.as_ref().is_some_and(|d| d.1.is_some());
    diagnosis.discovery = found.as_ref().map(|d| d.0.clone());
    Ok(Discovery {
        combination: if replaced { None } else { combination },
        found,
        combination_short,
    })
}
