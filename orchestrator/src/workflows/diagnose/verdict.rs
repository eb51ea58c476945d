//! Stage 6, the verdict: the action, its reason, the prediction after and the evidence panel
//! written into the diagnosis — the library's effects, the recalibration, discovery's terms or
//! `update_data_model` — and the reports of the effects and the physics that moved.

use std::collections::BTreeMap;

use structure::building::parameter_names;
use structure::effects::{Law, Placement, Term};

use super::baseline::Baseline;
use super::channels::{worst, Channels};
use super::effects::{effect_report, estimates, Estimates};
use super::fit::Fitted;
use super::localise::{missing_floor_force, storey_shear};
use super::physics::{PhysicsReals, PhysicsRun};
use super::search::{Discovery, Search};
use super::{
    discover, select, Action, Addition, Candidate, Diagnosis, Gates, MovedParameter, Scales,
};

/// The decision's stage: what each verdict's explanation reads (the round's results come as
/// arguments), and one method per verdict that writes its action, reason, scores and evidence
/// into the diagnosis.
pub(super) struct Verdict<'a> {
    pub(super) channels: &'a Channels,
    pub(super) mass: &'a [f64],
    pub(super) reals: &'a PhysicsReals,
    pub(super) scales: &'a Scales,
    pub(super) storeys: usize,
    /// The record's sampling interval.
    pub(super) dt: f64,
    /// Worst-floor held-out NMSE of the twin as given, and after recalibration.
    pub(super) before_worst: f64,
    pub(super) recal_worst: f64,
}

/// The decision's stage of a baseline.
impl Baseline {
    /// The decision's stage on this record (sampled every `dt`), with the twin's and the
    /// recalibration's worst-floor held-out NMSE.
    pub(super) fn verdict(&self, dt: f64, before_worst: f64, recal_worst: f64) -> Verdict<'_> {
        Verdict {
            channels: &self.channels,
            mass: &self.mass,
            reals: &self.reals,
            scales: &self.scales,
            storeys: self.storeys,
            dt,
            before_worst,
            recal_worst,
        }
    }
}

impl Verdict<'_> {
    /// Stage 6, when the error is to be explained and no sensor explains it: the library's
    /// combination, else the recalibration `recal`, else discovery's terms, else
    /// `update_data_model`. `order`: the candidates, best evidence first.
    pub(super) fn decide(
        &self,
        diagnosis: &mut Diagnosis,
        recal: &Fitted,
        search: &Search,
        discovery: &Discovery,
        order: &[usize],
    ) {
        if let Some((selection, fitted, w)) = discovery.combination {
            self.add_library(diagnosis, selection, fitted, w);
        } else if search.recal_explains {
            self.recalibrate(diagnosis, recal, &search.gates);
        } else if let (Some(s), Some((terms, fitted))) = (&search.selection, discovery.passes()) {
            self.add_discovered(diagnosis, s, terms, fitted, discovery.combination_short);
        } else {
            self.update_data_model(diagnosis, order);
        }
    }

    /// `add_physics` with the library's effects the forward selection chose.
    pub(super) fn add_library(
        &self,
        diagnosis: &mut Diagnosis,
        selection: &select::Selection,
        fitted: &Fitted,
        w: f64,
    ) {
        diagnosis.action = Action::AddPhysics;
        let labels: Vec<String> = selection.chosen.iter().map(|c| c.label()).collect();
        diagnosis.effects = selection
            .chosen
            .iter()
            .map(|c| effect_report(&Addition::Library(*c), &selection.values, self.scales))
            .collect();
        diagnosis.effect = diagnosis.effects.first().cloned();
        diagnosis.physics_moved = moved_physics(self.reals, &selection.values, self.storeys);
        let moved: Vec<String> = diagnosis
            .physics_moved
            .iter()
            .map(|p| format!("{} {:+.1} %", p.name, 100.0 * p.relative_change))
            .collect();
        let plural = if labels.len() == 1 { "s" } else { "" };
        diagnosis.reason =
            format!(
            "{} cut{plural} the worst-floor held-out NMSE from {:.3} % to {:.3} % ({:.1}×) and \
             beat{plural} recalibration ({:.3} %) by {:.1}×{}",
            labels.join(" + "),
            self.before_worst,
            w,
            self.before_worst / w,
            self.recal_worst,
            self.recal_worst / w,
            if moved.is_empty() {
                String::new()
            } else {
                format!("; refitted jointly, the physics moved: {}", moved.join(", "))
            }
        );
        diagnosis.nmse_after = fitted.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&fitted.run);
        // The evidence: along the fitted model's drift (which follows the structure), the
        // storey shear the linear part misses = the effect's force plus what is still missed.
        let c = &selection.chosen[0];
        if let Some(force) = effect_force(c, &selection.values, self.scales, &fitted.run) {
            self.evidence_panel(diagnosis, &fitted.run, c.at - 1, force);
        }
    }

    /// `recalibrate`: the recalibration explains the error and no effect beats it.
    pub(super) fn recalibrate(&self, diagnosis: &mut Diagnosis, recal: &Fitted, gates: &Gates) {
        diagnosis.action = Action::Recalibrate;
        let top: Vec<String> = diagnosis
            .recalibration
            .iter()
            .flat_map(|r| r.parameters.iter().take(3))
            .map(|p| {
                format!(
                    "{} {:+.1} % ({:+.1} sd)",
                    p.name,
                    100.0 * p.relative_change,
                    p.change_in_sd
                )
            })
            .collect();
        diagnosis.reason = format!(
            "recalibration cuts the worst-floor held-out NMSE from {:.3} % to {:.3} % ({:.1}×), \
             within {}× of the noise level on every floor, and no effect beats it by {}×; moved \
             most: {}",
            self.before_worst,
            self.recal_worst,
            self.before_worst / self.recal_worst,
            gates.recalibration_noise_factor,
            gates.beat_recalibration,
            top.join(", ")
        );
        diagnosis.nmse_after = recal.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&recal.run);
    }

    /// `add_physics` with the terms discovery found, on top of the selection's effects unless
    /// they replaced them (`replaced`: the library's answer left more than the noise).
    pub(super) fn add_discovered(
        &self,
        diagnosis: &mut Diagnosis,
        selection: &select::Selection,
        terms: &[Term],
        fitted: &Fitted,
        replaced: bool,
    ) {
        diagnosis.action = Action::AddPhysics;
        let (chosen, mut values) = if replaced {
            (Vec::new(), BTreeMap::new())
        } else {
            (selection.chosen.clone(), selection.values.clone())
        };
        let mut additions: Vec<Addition> = chosen.into_iter().map(Addition::Library).collect();
        additions.push(Addition::Discovered(terms.to_vec()));
        values.extend(estimates(&fitted.calibration));
        diagnosis.effects = additions
            .iter()
            .map(|a| effect_report(a, &values, self.scales))
            .collect();
        diagnosis.effect = diagnosis.effects.first().cloned();
        diagnosis.physics_moved = moved_physics(self.reals, &values, self.storeys);
        let w = worst(&fitted.nmse_held_out);
        let found = diagnosis
            .effects
            .last()
            .map(discover::describe_terms)
            .unwrap_or_default();
        let library = if replaced {
            let best = diagnosis
                .selection
                .iter()
                .map(|s| s.added.as_str())
                .collect::<Vec<_>>()
                .join(" + ");
            format!("the library's best ({best}) leaves more than the noise")
        } else {
            "nothing in the library explains the error".to_string()
        };
        diagnosis.reason = format!(
            "{library} (recalibration leaves {:.3} % held out); sparse regression found {found}, \
             which, refitted through the FMU, cuts the worst-floor held-out NMSE from {:.3} % \
             to {:.3} % ({:.1}×) and beats recalibration by {:.1}×",
            self.recal_worst,
            self.before_worst,
            w,
            self.before_worst / w,
            self.recal_worst / w
        );
        diagnosis.nmse_after = fitted.nmse_after.clone();
        diagnosis.series.after = self.channels.predicted(&fitted.run);
        // The evidence panel: at a storey, the discovered terms' storey force along the fitted
        // model's drift or drift rate, beside the shear the linear part still misses.
        if let Some((force, axis)) = discover::storey_force(terms, &fitted.run) {
            diagnosis.series.evidence_axis = Some(axis);
            self.evidence_panel(diagnosis, &fitted.run, terms[0].site.at() - 1, force);
        }
    }

    /// `update_data_model`: neither recalibration, the library nor discovery explains the
    /// error. `order`: the candidates, best evidence first.
    pub(super) fn update_data_model(&self, diagnosis: &mut Diagnosis, order: &[usize]) {
        diagnosis.action = Action::UpdateDataModel;
        let best = order.first().map(|&i| &diagnosis.candidates[i]);
        let discovery = match &diagnosis.discovery {
            Some(d) if d.terms.is_empty() => {
                "; no sparse model of a few candidate functions at one storey or floor fits it \
                 either"
                    .to_string()
            }
            Some(d) => format!(
                "; the sparse model found ({}) leaves {} held out, short of the gates",
                d.terms
                    .iter()
                    .map(|t| t.function.as_str())
                    .collect::<Vec<_>>()
                    .join(" + "),
                d.nmse_held_out
                    .as_ref()
                    .map(|x| format!("{:.3} %", worst(x)))
                    .unwrap_or_else(|| "?".into())
            ),
            None => String::new(),
        };
        diagnosis.reason = format!(
            "neither recalibration (worst-floor held-out NMSE {:.3} % from {:.3} %) nor any \
             effect of the library (best: {}) explains the error{discovery}: the corrector \
             should learn it",
            self.recal_worst,
            self.before_worst,
            best.map(|b| format!("{} at {:.3} %", b.name.label, worst(&b.nmse_held_out)))
                .unwrap_or_else(|| "none tried".into())
        );
    }

    /// The evidence panel at storey `s` (0-based): along the fitted model's drift, the storey
    /// shear the linear part still misses plus the added `force`, beside that force.
    pub(super) fn evidence_panel(
        &self,
        diagnosis: &mut Diagnosis,
        run: &PhysicsRun,
        s: usize,
        force: Vec<f64>,
    ) {
        diagnosis.series.drift = run.drift.clone();
        let still = missing_floor_force(
            self.channels,
            self.mass,
            &self.channels.predicted(run),
            self.storeys,
            self.dt,
        );
        diagnosis.series.missing_shear[s] = storey_shear(&still, s)
            .iter()
            .zip(&force)
            .map(|(still, force)| still - force)
            .collect();
        diagnosis.series.effect_force = Some(force);
    }
}

/// The physics parameters in `values` that moved from the twin's by more than 3 posterior sd
/// and 1 %, largest move (in sd) first.
pub(super) fn moved_physics(
    reals: &PhysicsReals,
    values: &Estimates,
    storeys: usize,
) -> Vec<MovedParameter> {
    let mut moved: Vec<MovedParameter> = parameter_names(storeys)
        .into_iter()
        .filter_map(|name| {
            let &(after, sd) = values.get(&name)?;
            let before = reals.get(&name).ok()?;
            Some(MovedParameter {
                name,
                before,
                after,
                sd,
                change_in_sd: (after - before) / sd,
                relative_change: (after - before) / before,
            })
        })
        .filter(|p| p.change_in_sd.abs() > 3.0 && p.relative_change.abs() > 0.01)
        .collect();
    moved.sort_by(|a, b| b.change_in_sd.abs().total_cmp(&a.change_in_sd.abs()));
    moved
}

/// The fitted effect's storey force along the run's drift (contact and cubic), or its floor
/// force along the velocity (friction): what the evidence panel draws. The force law is the
/// library's own; its parameters are read from `fitted` by name.
pub(super) fn effect_force(
    c: &Candidate,
    fitted: &Estimates,
    scales: &Scales,
    run: &PhysicsRun,
) -> Option<Vec<f64>> {
    let values = c
        .parameters(scales)
        .iter()
        .map(|(name, _, _)| fitted.get(name).map(|v| v.0))
        .collect::<Option<Vec<f64>>>()?;
    let law = Law::new(c.kind, &values, c.side)?;
    let along = match c.placement() {
        Placement::Storey => &run.drift[c.at - 1],
        Placement::Floor => &run.velocity[c.at - 1],
    };
    Some(along.iter().map(|&x| law.force_at(x)).collect())
}
