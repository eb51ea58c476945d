//! What `twin control` reports: each design's run, the passive structure's, the retune's rows,
//! the schedule's switches, the estimators' costs and the contacts — and the outcome those make
//! (assembled from the runs in outcome.rs).

use super::closed_loop::{ContactEvent, Response};
use super::design::Design;
use crate::evaluation::frf::FrequencyResponse;
use numerics::lqr::Estimator;
use serde::Serialize;

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
    /// ([`floor_frfs`](super::response::floor_frfs)) of the passive run, of each design's (None when it did not run), of the
    /// gain schedule's.
    pub passive_frf: Vec<Option<FrequencyResponse>>,
    pub design_frfs: Vec<Option<Vec<Option<FrequencyResponse>>>>,
    pub scheduled_frf: Option<Vec<Option<FrequencyResponse>>>,
}
