//! What `twin control` reports: each design's run, the passive structure's, the retune's rows,
//! the schedule's switches, the estimators' costs and the contacts — and the outcome those make.

use super::closed_loop::{ContactEvent, Response};
use super::design::{self, Design, StateUnit};
use super::options::ControlOptions;
use super::response::{acc_rms, floor_frfs};
use super::runs::{ControlBasis, LoopPlan, Runs};
use crate::evaluation::frf::FrequencyResponse;
use crate::twin::data::Measurement;
use numerics::lqr::Estimator;
use serde::Serialize;
use structure::channel::Channel;

/// Attenuation at one resonance: passive peak over controlled peak, per floor, dB.
#[derive(Clone, Debug, Serialize)]
pub struct Attenuation {
    pub mode: usize,
    pub frequency_hz: f64,
    pub floors_db: Vec<f64>,
}

/// A design run on the structure.
#[derive(Clone, Debug, Serialize)]
pub struct DesignRun {
    #[serde(flatten)]
    pub design: Design,
    /// "requested", "retuned".
    pub role: String,
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub contact_events: Vec<ContactEvent>,
    pub attenuation_db: Vec<Attenuation>,
    pub mean_attenuation_db: f64,
    pub control_rms: f64,
    pub control_peak: f64,
    pub acc_rms: Vec<f64>,
    /// Why the run stopped, when the closed loop went unstable (then no figures).
    pub unstable: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Passive {
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub contact_events: Vec<ContactEvent>,
    pub acc_rms: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RetuneRow {
    pub q: f64,
    pub contacts: Option<usize>,
    pub control_rms: Option<f64>,
    pub control_peak: Option<f64>,
    pub mean_attenuation_db: Option<f64>,
    pub unstable: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RetuneReport {
    pub target_contacts: usize,
    pub max_force: Option<f64>,
    pub grid: Vec<RetuneRow>,
    /// The smallest q that met the target (None: none on the grid did).
    pub chosen_q: Option<f64>,
    pub verdict: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Switch {
    pub time: f64,
    /// "high" or "low".
    pub to: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct ScheduleReport {
    pub q_low: f64,
    pub q_high: f64,
    pub storey: String,
    pub gap: f64,
    pub margin: f64,
    pub lookahead: f64,
    pub dwell: f64,
    pub switches: Vec<Switch>,
    pub high_fraction: f64,
    /// The corrector's latent variance above which the high gain comes on, per floor (None:
    /// the twin has no corrector, or the trigger is off).
    pub variance_threshold: Option<Vec<f64>>,
    /// Fractions of the time the drift and the latent-variance triggers held.
    pub drift_trigger_fraction: f64,
    pub variance_trigger_fraction: f64,
    pub contacts: usize,
    pub contact_times: Vec<f64>,
    pub attenuation_db: Vec<Attenuation>,
    pub mean_attenuation_db: f64,
    pub control_rms: f64,
    pub control_peak: f64,
    pub acc_rms: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct EstimatorCost {
    /// "exact" (the structure's true state), "integrate", "kalman".
    pub estimator: String,
    pub mean_attenuation_db: f64,
    pub attenuation_db: Vec<Attenuation>,
    pub control_rms: f64,
    pub contacts: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct GapReport {
    pub storey: String,
    pub gap: f64,
    pub side: i32,
}

/// The report of `twin control` (its JSON is the report contract).
#[derive(Clone, Debug, Serialize)]
pub struct ControlReport {
    pub twin: String,
    pub data: String,
    pub parameters: std::collections::BTreeMap<String, f64>,
    /// What excites the structure: `force:K` or `base`.
    pub excitation: String,
    /// The floor the control force acts on (1-based).
    pub actuator_floor: usize,
    /// The channels the controller reads (the record's responses), in the order of
    /// `sensor_noise_sd` and of a Kalman estimator's `sensor_sd`.
    pub measured: Vec<String>,
    #[serde(rename = "A")]
    pub a: Vec<Vec<f64>>,
    #[serde(rename = "B")]
    pub b: Vec<f64>,
    #[serde(rename = "R")]
    pub r: f64,
    /// Metres per state unit.
    pub state_scale: f64,
    pub state_unit: String,
    pub units_note: String,
    pub estimator: String,
    /// The estimator as the controller runs it (what `twin synth --controller` rebuilds).
    pub estimator_settings: Estimator,
    pub highpass_hz: f64,
    pub substeps: usize,
    pub control_rate_hz: f64,
    pub sensor_noise_sd: Option<Vec<f64>>,
    pub resonances_hz: Vec<f64>,
    pub gaps: Vec<GapReport>,
    pub passive: Passive,
    pub designs: Vec<DesignRun>,
    pub retune: Option<RetuneReport>,
    pub schedule: Option<ScheduleReport>,
    pub estimator_costs: Vec<EstimatorCost>,
}

/// Everything `twin control` computed: the report, and the time histories and frequency
/// responses for the plot.
pub struct ControlOutcome {
    pub report: ControlReport,
    pub passive: Response,
    /// One per entry of `report.designs` (empty when unstable).
    pub designs: Vec<Option<Response>>,
    pub scheduled: Option<Response>,
    pub force: Vec<f64>,
    pub dt: f64,
    /// Per floor, the frequency response from the excitation to the floor's acceleration
    /// ([`floor_frfs`]) of the passive run, of each design's (None when it did not run), of the
    /// gain schedule's.
    pub passive_frf: Vec<Option<FrequencyResponse>>,
    pub design_frfs: Vec<Option<Vec<Option<FrequencyResponse>>>>,
    pub scheduled_frf: Option<Vec<Option<FrequencyResponse>>>,
}

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
