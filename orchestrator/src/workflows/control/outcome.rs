//! The last stage of `twin control`: the runs made into its report and outcome.

use super::closed_loop::Response;
use super::design::{self, StateUnit};
use super::options::ControlOptions;
use super::report::{ControlOutcome, ControlReport, GapReport, Passive};
use super::response::{acc_rms, floor_frfs};
use super::runs::{ControlBasis, LoopPlan, Runs};
use crate::twin::data::Measurement;
use structure::channel::Channel;

/// The report and the time histories of the runs.
pub(super) fn control_outcome(
    basis: &ControlBasis,
    data: &Measurement,
    options: &ControlOptions,
    substeps: usize,
    plan: LoopPlan,
    runs: Runs,
) -> ControlOutcome {
    let (structure, plant) = (&basis.structure, &basis.plant);
    let units_note = match options.unit {
        StateUnit::M => "state in m and m/s; q weighs (m/s)², R weighs N²".to_owned(),
        StateUnit::Mm => "state in mm and mm/s; q weighs (mm/s)², R weighs N²".to_owned(),
    };
    let passive = runs.passive;
    let passive_report = Passive {
        contacts: passive.contacts.len(),
        contact_times: passive.contacts.iter().map(|c| c.time).collect(),
        contact_events: passive.contacts.clone(),
        acc_rms: acc_rms(&passive),
    };
    let (schedule, scheduled) = match runs.schedule {
        Some(s) => (Some(s.report), Some(s.response)),
        None => (None, None),
    };
    let report = ControlReport {
        twin: basis.twin.describe(),
        data: data.path.display().to_string(),
        parameters: design::parameter_map(structure),
        excitation: structure.excitation.name(),
        actuator_floor: options.actuator_floor,
        measured: basis.measured.iter().map(Channel::name).collect(),
        a: design::rows(&plant.a),
        b: plant.b.iter().copied().collect(),
        r: options.r,
        state_scale: plant.state_scale,
        state_unit: options.unit.name().into(),
        units_note,
        estimator: plan.estimator.name().into(),
        estimator_settings: plan.estimator.clone(),
        highpass_hz: options.highpass_hz,
        substeps,
        control_rate_hz: substeps as f64 / data.dt,
        sensor_noise_sd: plan.noise_sd,
        resonances_hz: plan.resonances,
        gaps: plan
            .gaps
            .iter()
            .map(|g| GapReport {
                storey: g.label(),
                gap: g.gap(),
                side: g.side(),
            })
            .collect(),
        passive: passive_report,
        designs: runs.designs.runs,
        retune: runs.retune,
        schedule,
        estimator_costs: runs.estimator_costs,
    };
    let force = &data.excitation.values;
    let frfs = |r: &Response| floor_frfs(force, r, data.dt);
    ControlOutcome {
        report,
        passive_frf: frfs(&passive),
        design_frfs: runs
            .designs
            .responses
            .iter()
            .map(|r| r.as_ref().map(frfs))
            .collect(),
        scheduled_frf: scheduled.as_ref().map(frfs),
        passive,
        designs: runs.designs.responses,
        scheduled,
        force: force.clone(),
        dt: data.dt,
    }
}
