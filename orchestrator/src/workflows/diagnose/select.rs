//! Several changes at once: forward selection over the effect library.
//!
//! A structure can lose stiffness and start to touch a bumper in the same week, or rub at one
//! floor while another storey stiffens. No single candidate explains such a record, so the
//! diagnosis builds the model up one change at a time:
//!
//! 1. **Pick** from a round of candidate fits (each with everything else held): the candidates
//!    that pass the single-effect gates first (by evidence, as a single effect is chosen), else
//!    the one with the lowest held-out error among those that cut the model's worst-floor
//!    held-out NMSE by [`Gates::step_cut`].
//! 2. **A parameter change is a move too.** In the first round, when no effect passes alone
//!    and the recalibration (the nine physics parameters) cuts the error more than the best
//!    effect, the recalibrated physics is taken first and the whole library is tried again on
//!    it: a stiffness loss hides a contact from every fit that holds the old stiffness.
//! 3. **Refit** the effects chosen so far jointly, kept when it lowers the held-out error; the
//!    physics held, unless it was recalibrated (then it was fitted while the effect was
//!    missing, and is refitted with it).
//! 4. **Repeat** while the model is not yet good enough (some floor above
//!    [`Gates::none_factor`] × its explained held-out level and the worst above the tolerance)
//!    and fewer than [`Gates::max_effects`] are chosen. After a full round (the first, or the
//!    one on recalibrated physics) the next rounds try only its candidates that cut the error
//!    on their own by 10 % or more (at most [`SCREENED`]), at other FMU locations than those
//!    chosen:
//!    a second effect that shows no trace alone rarely matters beside the first, and the
//!    screening keeps a round to seconds. On a long record whose model error shows on its
//!    head, a round's candidates are first raced there as round 1's are (`race`): only those
//!    that cut the model's error on the head by 10 % are fitted on the whole record, the
//!    others are listed in the round's `tried` as raced out, with their head's error.
//!    On a long record the polish below is tried first, and when it explains the record no
//!    later round runs (`settled`).
//! 5. **Polish**: every chosen effect and the nine physics parameters jointly, one start from
//!    the values fitted (a local refinement: the globally searched fits are the rounds' own),
//!    kept when it lowers the held-out error. The physics is freed only here, at the end: freed
//!    after the first effect, a floor's viscous damping soaks up a friction that a second round
//!    would otherwise find.
//!
//! The caller then judges the whole combination with the gates a single effect meets: a cut of
//! [`Gates::required_cut`] from the twin as given, and [`Gates::beat_recalibration`] against
//! the recalibration alone.

use std::collections::BTreeMap;
use std::time::Instant;

use super::baseline::Baseline;
use super::race::{race, Head, RACE_HEAD, RACE_MIN};
pub use super::race::{CUT_ALONE, SCREENED};
pub use super::report::SelectionStep;
use super::{
    estimates, fit, with_switches, worst, Addition, Candidate, Channels, DiagnoseError,
    DiagnoseOptions, Estimates, Fitted, PhysicsReals, Result, Scales,
};
use crate::parallel::on_threads;
use crate::twin::data::Measurement;
use crate::twin::{ParameterValue, Twin, PHYSICS};
use structure::building::parameter_names;

/// Simulations the joint refit may use (one start from fitted values: it converges in a few
/// hundred; the budget stops a refit that wanders).
pub const JOINT_SIMULATIONS: usize = 900;

/// What the rounds read.
pub(super) struct Context<'a> {
    pub physics: &'a Twin,
    pub data: &'a Measurement,
    pub options: &'a DiagnoseOptions,
    pub scales: &'a Scales,
    pub reals: &'a PhysicsReals,
    pub split: super::Split<'a>,
    pub baseline_evidence: f64,
    /// Per channel, the held-out NMSE the twin's band explains.
    pub explained_held_out: Vec<f64>,
    pub channels: &'a Channels,
    /// The candidates a full round tries.
    pub candidates: &'a [Candidate],
    pub tolerance: f64,
}

impl<'a> Context<'a> {
    /// What the forward selection and discovery read of `baseline`; a full round tries
    /// `candidates`.
    pub(super) fn of(
        baseline: &'a Baseline,
        data: &'a Measurement,
        options: &'a DiagnoseOptions,
        baseline_evidence: f64,
        candidates: &'a [Candidate],
    ) -> Self {
        Context {
            physics: &baseline.physics,
            data,
            options,
            scales: &baseline.scales,
            reals: &baseline.reals,
            split: baseline.split(),
            baseline_evidence,
            explained_held_out: (0..baseline.nc)
                .map(|c| baseline.scores.noise_nmse_held_out[c] + baseline.scores.band_nmse[c])
                .collect(),
            channels: &baseline.channels,
            candidates,
            tolerance: baseline.scores.tolerance.value,
        }
    }
}

/// The chosen effects, in order, and the model they make.
#[derive(Clone)]
pub(super) struct Selection {
    pub chosen: Vec<Candidate>,
    /// Every fitted value of the final model (effects and physics), by FMU name.
    pub values: Estimates,
    /// The final model's fit (scores and run).
    pub fitted: Option<Fitted>,
    pub steps: Vec<SelectionStep>,
    /// The last round's candidates when none of them was added: label and worst-floor
    /// held-out NMSE.
    pub not_added: Vec<(String, f64)>,
}

impl Context<'_> {
    pub fn good_enough(&self, nmse_held_out: &[f64]) -> bool {
        let factor = self.options.gates.none_factor;
        worst(nmse_held_out) <= self.tolerance
            || (0..self.channels.len())
                .all(|c| nmse_held_out[c] <= factor * self.explained_held_out[c])
    }

    /// The names of the structure's physics parameters (m1..mN, c1..cN, k1..kN).
    fn physics_names(&self) -> Vec<String> {
        parameter_names(self.reals.storeys)
    }

    /// The physics twin with `chosen` switched on and `values` set.
    fn model(&self, chosen: &[Candidate], values: &Estimates) -> Result<Twin> {
        let mut twin = self.physics.duplicate();
        let component = twin.component_mut(PHYSICS).ok_or_else(|| {
            DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component"))
        })?;
        for c in chosen {
            component.parameters.extend(c.switches());
        }
        for (name, &(value, _)) in values {
            component
                .parameters
                .insert(name.clone(), ParameterValue::Real(value));
        }
        Ok(twin)
    }

    /// Each of `candidates` fitted alone on `base` (its parameters only).
    fn round(&self, base: &Twin, candidates: &[Candidate]) -> Vec<(Candidate, Result<Fitted>)> {
        let results = on_threads(candidates, self.options.threads, |c| {
            self.fit_on(base, c, self.data, self.split)
        });
        candidates.iter().copied().zip(results).collect()
    }

    /// `candidate` fitted alone on `base` on `data` under `split` (the record or its head).
    fn fit_on(
        &self,
        base: &Twin,
        candidate: &Candidate,
        data: &Measurement,
        split: super::Split,
    ) -> Result<Fitted> {
        let o = self.options;
        let twin = with_switches(base, Some(candidate))?;
        let params = candidate.parameters(self.scales);
        fit(
            &twin,
            data,
            params.iter().map(|p| p.0.clone()).collect(),
            params.iter().map(|p| (p.0.clone(), p.2)).collect(),
            split,
            o.starts,
            1,
            o.simulations_per_start,
            o,
            self.baseline_evidence,
            &BTreeMap::new(),
            candidate.starts_at(self.scales),
        )
    }

    /// A round's candidates after a race on the record's head on top of `base`, the model so
    /// far (see `race`), when the library is the default, the record long and the model's
    /// error shows on the head; else `next` as it is. The raced out go into `tried` with their
    /// head's worst-floor held-out NMSE.
    fn raced(
        &self,
        base: &Twin,
        selection: &Selection,
        next: &[Candidate],
        tried: &mut Vec<(String, f64)>,
    ) -> Vec<Candidate> {
        if self.options.candidates.is_some() || next.len() <= 1 {
            return next.to_vec();
        }
        let (Some(head), Some(model)) = (Head::of(self.data, &self.split), &selection.fitted)
        else {
            return next.to_vec();
        };
        let predicted = self.channels.predicted(&model.run);
        let Some(before) = head.error_shown(self.channels, &predicted, self.split.held_out) else {
            return next.to_vec();
        };
        let split = head.split(&self.split);
        let (kept, out) = race(next.to_vec(), before, self.options, |c| {
            self.fit_on(base, c, &head.data, split)
        });
        for (c, w) in out {
            let label = format!("{} (raced out on the first {RACE_HEAD} samples)", c.label());
            tried.push((label, w));
        }
        kept
    }

    /// `addition` on top of the model of `chosen` at `values`: its parameters and the nine
    /// physics parameters, one start from `values` (a discovered effect's coefficients from the
    /// regression's).
    pub fn fit_addition(
        &self,
        chosen: &[Candidate],
        values: &Estimates,
        addition: &Addition,
    ) -> Result<Fitted> {
        let mut twin = self.model(chosen, values)?;
        twin.component_mut(PHYSICS)
            .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?
            .parameters
            .extend(addition.switches());
        let params = addition.parameters(self.scales);
        let mut initial: BTreeMap<String, f64> =
            values.iter().map(|(k, v)| (k.clone(), v.0)).collect();
        if let Addition::Discovered(terms) = addition {
            for (p, t) in params.iter().zip(terms) {
                initial.insert(p.0.clone(), t.coefficient);
            }
        }
        for name in self.physics_names() {
            if !initial.contains_key(&name) {
                let value = self.reals.get(&name)?;
                initial.insert(name, value);
            }
        }
        let mut names: Vec<String> = params.iter().map(|p| p.0.clone()).collect();
        names.extend(self.physics_names());
        fit(
            &twin,
            self.data,
            names,
            params.iter().map(|p| (p.0.clone(), p.2)).collect(),
            self.split,
            1,
            // One start alone: its finite differences over the cores.
            self.options.threads,
            JOINT_SIMULATIONS,
            self.options,
            self.baseline_evidence,
            &initial,
            Vec::new(),
        )
    }

    /// Every chosen effect (and with `physics` the nine physics parameters), from `start`; what
    /// is not fitted is held at `start`.
    fn joint(&self, chosen: &[Candidate], start: &Estimates, physics: bool) -> Result<Fitted> {
        let twin = self.model(chosen, start)?;
        let mut names = Vec::new();
        let mut priors = BTreeMap::new();
        for c in chosen {
            for (name, _, prior) in c.parameters(self.scales) {
                priors.insert(name.clone(), prior);
                names.push(name);
            }
        }
        let mut initial: BTreeMap<String, f64> =
            start.iter().map(|(k, v)| (k.clone(), v.0)).collect();
        if physics {
            names.extend(self.physics_names());
            for name in self.physics_names() {
                if !initial.contains_key(&name) {
                    let value = self.reals.get(&name)?;
                    initial.insert(name, value);
                }
            }
        }
        fit(
            &twin,
            self.data,
            names,
            priors,
            self.split,
            1,
            // One start alone: its finite differences over the cores.
            self.options.threads,
            JOINT_SIMULATIONS,
            self.options,
            self.baseline_evidence,
            &initial,
            Vec::new(),
        )
    }
}

/// The pick of a round: the candidates that passed the single-effect gates (`passes`, the
/// first round only), by evidence, as a single-effect diagnosis always chose; else those that
/// cut `current` by the step gate, by held-out error (on a model still missing something, the
/// Laplace evidence of the fitted blocks can favour a wrong side of a contact that the
/// held-out blocks expose). Also whether the pick passed.
fn pick<'a>(
    results: &'a [(Candidate, Fitted)],
    passes: &[bool],
    current: f64,
    step_cut: f64,
) -> Option<(&'a (Candidate, Fitted), bool)> {
    let held_out = |i: usize| worst(&results[i].1.nmse_held_out);
    (0..results.len())
        .filter(|&i| passes[i])
        .max_by(|&a, &b| results[a].1.evidence.total_cmp(&results[b].1.evidence))
        .map(|i| (&results[i], true))
        .or_else(|| {
            (0..results.len())
                .filter(|&i| held_out(i) * step_cut <= current)
                .min_by(|&a, &b| held_out(a).total_cmp(&held_out(b)))
                .map(|i| (&results[i], false))
        })
}

/// The candidates of a round that cut `current` by 10 % or more alone, best first.
fn screen(results: &[(Candidate, Fitted)], current: f64) -> Vec<Candidate> {
    let mut cut: Vec<(Candidate, f64)> = results
        .iter()
        .map(|(c, f)| (*c, worst(&f.nmse_held_out)))
        .filter(|&(_, w)| w <= CUT_ALONE * current)
        .collect();
    cut.sort_by(|a, b| a.1.total_cmp(&b.1));
    cut.into_iter().map(|(c, _)| c).collect()
}
/// What a round's step records beside its pick: the round, the worst-floor held-out NMSE
/// before it, the candidates it tried, and when it began.
struct Step {
    round: usize,
    worst_before: f64,
    tried: Vec<(String, f64)>,
    started: Instant,
}

/// The round's pick `c` (fitted alone: `alone`) added to `selection`: refitted jointly with the
/// effects chosen before (and the physics when `physics_moved`), the better of the two kept,
/// its step recorded. The new worst-floor held-out NMSE, and whether the selection is done
/// (good enough, or the most effects chosen).
fn add_picked(
    ctx: &Context,
    selection: &mut Selection,
    c: Candidate,
    alone: &Fitted,
    physics_moved: bool,
    step: Step,
    progress: &dyn Fn(&str),
) -> (f64, bool) {
    let Step {
        round,
        worst_before,
        tried,
        started,
    } = step;
    selection.chosen.push(c);
    let mut values = selection.values.clone();
    values.extend(estimates(&alone.calibration));
    let mut kept = alone.clone();
    let mut refit_held_out = alone.nmse_held_out.clone();
    let mut refit_kept = false;
    // On recalibrated physics (fitted while the effect was missing) the physics is refitted
    // with the effects; else the effects alone, when there are several.
    if selection.chosen.len() > 1 || physics_moved {
        progress(&format!(
            "round {round}: {} chosen; refitting jointly",
            c.label()
        ));
        match ctx.joint(&selection.chosen, &values, physics_moved) {
            Ok(joint) => {
                refit_held_out = joint.nmse_held_out.clone();
                if worst(&joint.nmse_held_out) < worst(&alone.nmse_held_out) {
                    values.extend(estimates(&joint.calibration));
                    kept = joint;
                    refit_kept = true;
                }
            }
            Err(e) => progress(&format!("the joint refit failed ({e})")),
        }
    }
    selection.steps.push(SelectionStep {
        round,
        added: c.label(),
        worst_before,
        nmse_held_out_effect: alone.nmse_held_out.clone(),
        nmse_held_out_joint: refit_held_out,
        joint_kept: refit_kept,
        tried,
        seconds: started.elapsed().as_secs_f64(),
        settled: false,
    });
    let current = worst(&kept.nmse_held_out);
    selection.values = values;
    let good = ctx.good_enough(&kept.nmse_held_out);
    selection.fitted = Some(kept);
    (
        current,
        good || selection.chosen.len() >= ctx.options.gates.max_effects,
    )
}

/// Forward selection from the first round's fits (`first_round`, with which of them passed the
/// single-effect gates, and the recalibration `recalibrated`). `before` is the twin's
/// worst-floor held-out NMSE.
pub(super) fn forward(
    ctx: &Context,
    first_round: &[(Candidate, Fitted)],
    passes: &[bool],
    recalibrated: &Fitted,
    before: f64,
    progress: &dyn Fn(&str),
) -> Result<Selection> {
    let gates = ctx.options.gates;
    let mut selection = Selection {
        chosen: Vec::new(),
        values: BTreeMap::new(),
        fitted: None,
        steps: Vec::new(),
        not_added: Vec::new(),
    };
    // The candidates of the last full round that cut the error alone by 10 %, best first: what
    // the next rounds try.
    let mut screened = screen(first_round, before);
    let mut physics_moved = false;
    let mut full_round_next = false;

    let mut current = before;
    let mut results: Vec<(Candidate, Fitted)> = first_round.to_vec();
    let mut passing = passes.to_vec();
    let mut tried: Vec<(String, f64)> = first_round
        .iter()
        .map(|(c, f)| (c.label(), worst(&f.nmse_held_out)))
        .collect();
    let mut round = 1;
    // A long record's joint refit, tried before a later round (see `settled`).
    let mut probe: Option<Selection> = None;
    loop {
        let started = Instant::now();
        let picked = pick(&results, &passing, current, gates.step_cut);
        let recal = worst(&recalibrated.nmse_held_out);
        let take_recalibration =
            round == 1 && takes_recalibration(picked, recal, current, gates.step_cut);
        let step = Step {
            round,
            worst_before: current,
            tried: std::mem::take(&mut tried),
            started,
        };
        match (take_recalibration, picked) {
            (true, _) => {
                adopt_recalibration(&mut selection, recalibrated, step);
                current = recal;
                physics_moved = true;
                full_round_next = true;
                selection.fitted = Some(recalibrated.clone());
                if ctx.good_enough(&recalibrated.nmse_held_out) {
                    break;
                }
            }
            (false, Some(((c, alone), _))) => {
                let (worst_now, done) = add_picked(
                    ctx,
                    &mut selection,
                    *c,
                    alone,
                    physics_moved,
                    step,
                    progress,
                );
                current = worst_now;
                if done {
                    break;
                }
                if let Some(polished) = settled(ctx, &selection, &mut probe, progress) {
                    return Ok(polished);
                }
            }
            (false, None) => {
                selection.not_added = step.tried;
                break;
            }
        }
        // The next round, at locations not yet chosen: the whole library on recalibrated
        // physics, else the last full round's screened candidates.
        let full = std::mem::take(&mut full_round_next);
        let next = next_candidates(ctx, &selection.chosen, &screened, full);
        if next.is_empty() {
            break;
        }
        round += 1;
        results = next_round(ctx, &selection, &next, round, progress, &mut tried)?;
        passing = vec![false; results.len()];
        if full {
            screened = screen(&results, current);
        }
    }
    Ok(finish(ctx, selection, probe, progress))
}

/// Whether the first round takes the recalibration (worst-floor held-out NMSE `recal`) as its
/// move, the model's error `current`: a parameter change is a move too. When no effect passes
/// alone (`picked`, with whether it passed) and the recalibration cuts the error by the step
/// gate and more than the best effect, it is taken first and the effects are tried again on
/// the recalibrated physics.
fn takes_recalibration(
    picked: Option<(&(Candidate, Fitted), bool)>,
    recal: f64,
    current: f64,
    step_cut: f64,
) -> bool {
    !picked.is_some_and(|(_, passed)| passed)
        && recal * step_cut <= current
        && picked.is_none_or(|((_, f), _)| recal < worst(&f.nmse_held_out))
}

/// The selection polished (see `polish`); when nothing was added since a long record's
/// `probe`, its joint refit is this model's polish.
fn finish(
    ctx: &Context,
    mut selection: Selection,
    probe: Option<Selection>,
    progress: &dyn Fn(&str),
) -> Selection {
    match probe {
        Some(polished) if polished.chosen == selection.chosen => Selection {
            not_added: selection.not_added,
            ..polished
        },
        _ => {
            polish(ctx, &mut selection, progress);
            selection
        }
    }
}

/// On a long record (one whose candidates are raced, [`RACE_MIN`] samples or more), where a
/// later round costs minutes, the polish is tried before it: the selection so far refitted
/// jointly with the physics. When that explains the record ([`Context::good_enough`]) it is
/// the result and no further round runs; else it is kept in `probe`, to serve as the final
/// polish if the later rounds add nothing. On the bench's 131,072-sample record of a frame with
/// a hidden cubic spring, cubic@1 with the physics held left 14.4 % held-out NMSE (the twin's
/// damping calibrated on 1,024 samples was 1.2 % off) and the joint refit 0.09 %, at the noise:
/// a second round of five candidates had taken 343 s to add nothing.
///
/// Short records keep the order the module describes (the physics freed only at the end, as
/// a floor's viscous damping freed early soaks up a friction a second round would find). The
/// risk taken on a long record: a second effect the freed physics imitates to the noise of
/// every floor over all its samples is not looked for.
fn settled(
    ctx: &Context,
    selection: &Selection,
    probe: &mut Option<Selection>,
    progress: &dyn Fn(&str),
) -> Option<Selection> {
    if ctx.data.len() < RACE_MIN {
        return None;
    }
    let mut polished = selection.clone();
    polish(ctx, &mut polished, progress);
    let explained = polished
        .fitted
        .as_ref()
        .is_some_and(|f| ctx.good_enough(&f.nmse_held_out));
    if explained {
        progress("the joint refit explains the record: no further round");
        if let Some(last) = polished.steps.last_mut() {
            last.settled = true;
        }
        return Some(polished);
    }
    *probe = Some(polished);
    None
}

/// The recalibration taken as the round's move: its values in the selection, its step
/// reported (its held-out NMSE both alone and joint), its fit the selection's.
fn adopt_recalibration(selection: &mut Selection, recalibrated: &Fitted, step: Step) {
    selection
        .values
        .extend(estimates(&recalibrated.calibration));
    selection.steps.push(SelectionStep {
        round: step.round,
        added: "recalibration".into(),
        worst_before: step.worst_before,
        nmse_held_out_effect: recalibrated.nmse_held_out.clone(),
        nmse_held_out_joint: recalibrated.nmse_held_out.clone(),
        joint_kept: true,
        tried: step.tried,
        seconds: step.started.elapsed().as_secs_f64(),
        settled: false,
    });
}

/// Round `round`: each of `next` fitted on top of the selection so far; the fits, and each
/// candidate added to `tried` (its held-out worst NMSE, or its failure).
fn next_round(
    ctx: &Context,
    selection: &Selection,
    next: &[Candidate],
    round: usize,
    progress: &dyn Fn(&str),
    tried: &mut Vec<(String, f64)>,
) -> Result<Vec<(Candidate, Fitted)>> {
    progress(&format!(
        "round {round}: {} candidates on top of {}",
        next.len(),
        selection
            .steps
            .iter()
            .map(|s| s.added.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    ));
    let base = ctx.model(&selection.chosen, &selection.values)?;
    let next = ctx.raced(&base, selection, next, tried);
    let mut results = Vec::new();
    for (c, r) in ctx.round(&base, &next) {
        match r {
            Ok(f) => {
                tried.push((c.label(), worst(&f.nmse_held_out)));
                results.push((c, f));
            }
            Err(e) => tried.push((format!("{} (failed: {e})", c.label()), f64::NAN)),
        }
    }
    Ok(results)
}

/// The next round's candidates, at locations not yet `chosen`: the whole library when the round
/// is `full` (on recalibrated physics), else the first [`SCREENED`] of the last full round's
/// `screened`.
fn next_candidates(
    ctx: &Context,
    chosen: &[Candidate],
    screened: &[Candidate],
    full: bool,
) -> Vec<Candidate> {
    let taken: Vec<String> = chosen.iter().map(|c| c.prefix()).collect();
    let from = if full { ctx.candidates } else { screened };
    from.iter()
        .copied()
        .filter(|c| !taken.contains(&c.prefix()))
        .take(if full { usize::MAX } else { SCREENED })
        .collect()
}

/// The final polish: every chosen effect and the physics jointly, kept when it lowers the
/// held-out error.
fn polish(ctx: &Context, selection: &mut Selection, progress: &dyn Fn(&str)) {
    if selection.chosen.is_empty() {
        return;
    }
    progress("refitting the effects jointly with the physics");
    if let Ok(joint) = ctx.joint(&selection.chosen, &selection.values, true) {
        let better = selection
            .fitted
            .as_ref()
            .is_none_or(|f| worst(&joint.nmse_held_out) < worst(&f.nmse_held_out));
        if better {
            selection.values.extend(estimates(&joint.calibration));
            if let Some(last) = selection.steps.last_mut() {
                last.nmse_held_out_joint = joint.nmse_held_out.clone();
                last.joint_kept = true;
            }
            selection.fitted = Some(joint);
        }
    }
}
