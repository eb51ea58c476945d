//! Stage 4, round 1: the recalibration and every screened candidate fitted alone, in parallel
//! threads, each scored against the twin's own evidence; their reports and gates into the
//! diagnosis.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use structure::building::parameter_names;

use super::baseline::{Baseline, Ground};
use super::channels::worst;
use super::fit::{fit, with_switches, Fitted};
use super::{
    Candidate, CandidateReport, DiagnoseError, DiagnoseOptions, Diagnosis, EffectName, Estimate,
    Kind, MovedParameter, RecalibrationReport, Result,
};
use crate::twin::data::Measurement;
use crate::workflows::calibrate::{fixed_log_evidence, CalibrationSetup};

/// Round 1's fits: the recalibration (and its worst-floor held-out NMSE) and every candidate
/// fitted alone that did not fail.
pub(super) struct RoundOne {
    pub(super) recal: Fitted,
    pub(super) recal_worst: f64,
    pub(super) fitted: Vec<(Candidate, Fitted)>,
}

/// The log evidence of the twin's physics as it is, on the fitted blocks: every alternative's
/// evidence is a log Bayes factor against it.
pub(super) fn baseline_evidence(
    b: &Baseline,
    data: &Measurement,
    options: &DiagnoseOptions,
) -> Result<f64> {
    let evidence_setup = CalibrationSetup {
        transient: options.transient,
        mask: Some(b.samples.mask.clone()),
        ..CalibrationSetup::default()
    };
    Ok(fixed_log_evidence(&b.physics, data, &evidence_setup)?)
}

#[derive(Clone, Copy)]
pub(super) enum Job {
    Recalibrate,
    Effect(Candidate),
}

impl Job {
    /// The order of a job's usual cost, dearest first: the smooth effects (RK4 sub-steps),
    /// then the recalibration, then the contacts (exact maps).
    pub(super) fn cost_rank(&self) -> u8 {
        match self {
            Job::Effect(c) if c.kind == Kind::Friction => 0,
            Job::Effect(c) if c.kind == Kind::Cubic => 1,
            Job::Recalibrate => 2,
            Job::Effect(_) => 3,
        }
    }
}

/// Calls its closure when dropped: a fit counts as done however it ended.
pub(super) struct Told<F: FnMut()>(F);

impl<F: FnMut()> Drop for Told<F> {
    fn drop(&mut self) {
        (self.0)()
    }
}

/// Round 1's fits, in parallel: the recalibration first, then every candidate alone; each
/// with the seconds it took.
pub(super) fn fit_round_one(
    g: &Ground,
    candidates: &[Candidate],
    baseline_evidence: f64,
) -> Result<Vec<Result<(Fitted, f64)>>> {
    let Ground {
        data,
        options,
        physics,
        storeys,
        split,
        reals,
        ..
    } = *g;
    let current = parameter_names(storeys)
        .into_iter()
        .map(|name| Ok((name.clone(), reals.get(&name)?)))
        .collect::<Result<BTreeMap<String, f64>>>()?;
    let mut jobs = vec![Job::Recalibrate];
    jobs.extend(candidates.iter().map(|c| Job::Effect(*c)));
    let done = AtomicUsize::new(0);
    let total = jobs.len();
    options.tell(&format!(
        "round 1: recalibration and {} candidates",
        total - 1
    ));
    // The dearest fits first, so that none starts last and runs alone: a smooth effect steps
    // RK4 sub-steps where a contact steps its exact maps (on dataset3 a friction fit took
    // 0.9–1.0 s, a cubic 0.4–0.5 s, the recalibration 0.5 s, a contact 0.1–0.7 s).
    let mut ordered: Vec<(usize, Job)> = jobs.iter().copied().enumerate().collect();
    ordered.sort_by_key(|(_, job)| job.cost_rank());
    let results = crate::parallel::on_threads(
        &ordered,
        options.threads,
        |&(_, job)| -> Result<(Fitted, f64)> {
            let t = Instant::now();
            let _told = Told(|| {
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                options.tell(&format!(
                    "round 1: {k}/{total} fits (recalibration and candidates)"
                ));
            });
            let fitted = match &job {
                // The prior's mean and random draws as a calibration starts, and one more start
                // at the twin's own values: a change near them (a storey's stiffness loss) is
                // found from there whatever the number of parameters, where random starts of a
                // tall building's 3N parameters rarely come near.
                Job::Recalibrate => fit(
                    &physics,
                    data,
                    parameter_names(storeys),
                    BTreeMap::new(),
                    split,
                    options.recalibration_starts + 1,
                    1,
                    crate::workflows::calibrate::SIMULATIONS_PER_START,
                    options,
                    baseline_evidence,
                    &BTreeMap::new(),
                    vec![current.clone()],
                ),
                Job::Effect(c) => fit_alone(g, c, baseline_evidence),
            }?;
            Ok((fitted, t.elapsed().as_secs_f64()))
        },
    );
    // Back in the jobs' order.
    let mut slots: Vec<Option<Result<(Fitted, f64)>>> = jobs.iter().map(|_| None).collect();
    for ((i, _), r) in ordered.iter().zip(results) {
        slots[*i] = Some(r);
    }
    Ok(slots.into_iter().flatten().collect())
}

/// `candidate` fitted alone on the ground's record and split (its own parameters under their
/// priors, from its starts; the physics held at the twin's values), in one thread.
pub(super) fn fit_alone(
    g: &Ground,
    candidate: &Candidate,
    baseline_evidence: f64,
) -> Result<Fitted> {
    let twin = with_switches(g.physics, Some(candidate))?;
    let params = candidate.parameters(g.scales);
    fit(
        &twin,
        g.data,
        params.iter().map(|p| p.0.clone()).collect(),
        params.iter().map(|p| (p.0.clone(), p.2)).collect(),
        g.split,
        g.options.starts,
        1,
        g.options.simulations_per_start,
        g.options,
        baseline_evidence,
        &BTreeMap::new(),
        candidate.starts_at(g.scales),
    )
}

/// Round 1's results into the diagnosis: the recalibration's report and every candidate's
/// (or its failure), the candidates' gates against `before_worst`, the twin's worst-floor
/// held-out NMSE.
pub(super) fn report_round_one(
    g: &Ground,
    diagnosis: &mut Diagnosis,
    candidates: &[Candidate],
    results: Vec<Result<(Fitted, f64)>>,
    before_worst: f64,
) -> Result<RoundOne> {
    let Ground {
        options,
        reals,
        scales,
        ..
    } = *g;
    let gates = options.gates;
    let mut results = results.into_iter();
    let (recal, recal_seconds) = results
        .next()
        .ok_or_else(|| DiagnoseError::Setup("no recalibration result".into()))?
        .map_err(|e| DiagnoseError::In {
            context: "recalibrating".into(),
            source: Box::new(e),
        })?;
    let recal_worst = worst(&recal.nmse_held_out);
    let mut moved: Vec<MovedParameter> = recal
        .calibration
        .parameters
        .iter()
        .map(|p| {
            let before = reals.get(&p.name).unwrap_or(f64::NAN);
            MovedParameter {
                name: p.name.clone(),
                before,
                after: p.value,
                sd: p.sd,
                change_in_sd: (p.value - before) / p.sd,
                relative_change: (p.value - before) / before,
            }
        })
        .collect();
    moved.sort_by(|a, b| b.change_in_sd.abs().total_cmp(&a.change_in_sd.abs()));
    diagnosis.recalibration = Some(RecalibrationReport {
        evidence: recal.evidence,
        nmse_after: recal.nmse_after.clone(),
        nmse_held_out: recal.nmse_held_out.clone(),
        parameters: moved,
        noise_variance: recal.calibration.noise_variance.clone(),
        simulations: recal.calibration.simulations,
        seconds: recal_seconds,
    });

    let mut fitted_candidates = Vec::new();
    for (c, r) in candidates.iter().zip(results) {
        let (fitted, seconds) = match r {
            Ok(x) => x,
            Err(e) => {
                diagnosis
                    .failed_candidates
                    .push((c.label(), format!("{e:#}")));
                continue;
            }
        };
        let w = worst(&fitted.nmse_held_out);
        let passes =
            w * gates.required_cut <= before_worst && w * gates.beat_recalibration <= recal_worst;
        let short = c.parameters(&scales);
        diagnosis.candidates.push(CandidateReport {
            name: EffectName::of(c),
            evidence: fitted.evidence,
            nmse_after: fitted.nmse_after.clone(),
            nmse_held_out: fitted.nmse_held_out.clone(),
            parameters: fitted
                .calibration
                .parameters
                .iter()
                .zip(&short)
                .map(|(p, s)| Estimate {
                    name: s.1.to_string(),
                    value: p.value,
                    sd: p.sd,
                })
                .collect(),
            passes,
            simulations: fitted.calibration.simulations,
            seconds,
        });
        fitted_candidates.push((*c, fitted));
    }
    Ok(RoundOne {
        recal,
        recal_worst,
        fitted: fitted_candidates,
    })
}
