//! The truth JSON: how a record was made, and what the fine grid saw.

use ::structure::effects::contact::{SIDE_NEGATIVE, SIDE_POSITIVE};
use ::structure::effects::drift;
use fmu_shear::ShearModel;
use serde::Serialize;
use serde_json::{json, Value};

use super::scenario::{DampingSite, EffectSpec, ForceWindow};

/// How the record was made: the resolved scenario and what came out of it.
#[derive(Debug, Clone, Serialize)]
pub struct Truth {
    pub generator: String,
    /// The scenario with every default filled in (valid `--scenario` input).
    pub scenario: Value,
    pub record: RecordTruth,
    pub structure: StructureTruth,
    pub effects: Vec<EffectTruth>,
    pub changes: Vec<ChangeTruth>,
    pub force: ForceTruth,
    pub noise: NoiseTruth,
    pub response: ResponseTruth,
    pub random_numbers: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct RecordTruth {
    pub columns: Vec<String>,
    pub samples: usize,
    pub sample_rate: f64,
    pub sample_interval: f64,
    pub first_time: f64,
    pub last_time: f64,
    pub fine_step: f64,
    pub oversample: u32,
    pub integrator: String,
    pub initial_state: String,
    pub sampling: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct StructureTruth {
    pub model: String,
    /// The excitation (`force:K` or `base`), when it is not the paper's force at floor 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excitation: Option<String>,
    /// Parameters at the start of the record: N floors' masses, N storeys' damping, stiffness.
    pub m: Vec<f64>,
    pub c: Vec<f64>,
    pub k: Vec<f64>,
    /// Parameters at the end of the record (after every change).
    pub final_m: Vec<f64>,
    pub final_c: Vec<f64>,
    pub final_k: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct EffectTruth {
    pub kind: String,
    /// As the scenario writes it: `[lower, upper]` for contact, `[storey]` for cubic,
    /// hysteresis and a storey's quadratic damping, `[floor]` for friction and a floor's
    /// quadratic damping (the scenario's `floor`; `floors` tells the two apart).
    pub location: Vec<usize>,
    /// The floors the effect acts between / on (0 = the ground).
    pub floors: Vec<usize>,
    pub description: String,
    /// The shear FMU's variable prefix, e.g. `contact23` (for an effect not in the library, as
    /// `hysteresis2`, no FMU variable has it).
    pub fmu_prefix: String,
    /// Whether the shear FMU's effect library has this kind (false for hysteresis and quadratic
    /// damping).
    pub in_library: bool,
    /// 0-based location in the FMU's effect library (hysteresis: the 0-based storey).
    pub library_location: usize,
    pub parameters: Value,
    /// Contact only: closings of the gap (open → closed on the fine grid).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact_events: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_in_contact: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_contact: Option<f64>,
    /// Contact only: largest |drift| − gap while closed, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_penetration: Option<f64>,
    /// Largest |drift| (storey effects) or |velocity| (friction; quadratic damping: the
    /// velocity it damps, a storey's relative velocity or a floor's) over the record.
    pub max_drift_or_velocity: f64,
    /// Hysteresis only: the bound of |z|, `yield · (1/(beta + gamma))^(1/exponent)`, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub z_saturation: Option<f64>,
    /// Hysteresis only: largest |z| on the fine grid, m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_abs_z: Option<f64>,
    /// Hysteresis only: `∫ k_h z dδ` over the record, J (dissipated, plus what z stores at the
    /// end).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hysteretic_work: Option<f64>,
    /// Quadratic damping only: the energy it dissipated over the record, `∫ c₂ |v|³ dt`, J
    /// (integrated with the structure on the fine grid).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dissipated_energy: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ChangeTruth {
    pub at: f64,
    pub parameter: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    pub before: f64,
    pub after: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ForceTruth {
    pub kind: String,
    pub rms_requested: f64,
    /// RMS of the force samples written (before noise).
    pub rms_record: f64,
    pub band_hz: [f64; 2],
    pub frequency_resolution: f64,
    pub bins: usize,
    pub windows: Vec<ForceWindow>,
    /// RMS of the force samples inside each window's plateau (between the ramps).
    pub rms_in_windows: Vec<Option<f64>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct NoiseTruth {
    pub kind: String,
    /// The sd added to each response channel (in the record's order), SI (m/s², m/s or m).
    pub acc_sd: Vec<f64>,
    pub force_sd: f64,
    /// Each response channel's noise-free RMS, SI.
    pub response_rms: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ResponseTruth {
    /// Largest |inter-storey drift| of storeys 1..3 on the fine grid, m.
    /// Largest |inter-storey drift| of storeys 1..N on the fine grid, m.
    pub max_abs_drift: Vec<f64>,
    pub max_abs_displacement: Vec<f64>,
    /// Largest |acceleration| of floors 1..N at the sample times (absolute under ground
    /// motion), m/s².
    pub max_abs_acceleration: Vec<f64>,
}

impl Truth {
    pub fn to_json(&self) -> Value {
        serde_json::to_value(self).unwrap_or(Value::Null)
    }
}

/// What the fine grid saw: drifts, contacts.
pub(super) struct Stats {
    pub(super) max_drift: Vec<f64>,
    pub(super) max_disp: Vec<f64>,
    pub(super) max_vel: Vec<f64>,
    pub(super) max_acc: Vec<f64>,
    contacts: Vec<ContactStats>,
}

#[derive(Default, Clone)]
struct ContactStats {
    /// Index in the scenario's effects, storey, gap, side.
    pub(super) effect: usize,
    pub(super) storey: usize,
    pub(super) gap: f64,
    pub(super) side: i32,
    pub(super) closed: bool,
    pub(super) events: usize,
    pub(super) time: f64,
    pub(super) first: Option<f64>,
    pub(super) max_penetration: f64,
}

impl Stats {
    pub(super) fn new(effects: &[EffectSpec], storeys: usize) -> Self {
        let contacts = effects
            .iter()
            .enumerate()
            .filter_map(|(i, e)| match *e {
                EffectSpec::Contact {
                    lower, gap, side, ..
                } => Some(ContactStats {
                    effect: i,
                    storey: lower,
                    gap,
                    side,
                    ..ContactStats::default()
                }),
                _ => None,
            })
            .collect();
        Stats {
            max_drift: vec![0.0; storeys],
            max_disp: vec![0.0; storeys],
            max_vel: vec![0.0; storeys],
            max_acc: vec![0.0; storeys],
            contacts,
        }
    }

    pub(super) fn observe(&mut self, model: &ShearModel, t: f64, h: f64) {
        let y = &model.displacement;
        for i in 0..y.len() {
            self.max_drift[i] = self.max_drift[i].max(drift(y, i).abs());
            self.max_disp[i] = self.max_disp[i].max(y[i].abs());
            self.max_vel[i] = self.max_vel[i].max(model.velocity[i].abs());
        }
        for c in &mut self.contacts {
            let d = drift(y, c.storey);
            let penetration = match c.side {
                SIDE_POSITIVE => d - c.gap,
                SIDE_NEGATIVE => -d - c.gap,
                _ => d.abs() - c.gap,
            };
            let closed = penetration > 0.0;
            if closed {
                if !c.closed {
                    c.events += 1;
                    c.first.get_or_insert(t);
                }
                c.time += h;
                c.max_penetration = c.max_penetration.max(penetration);
            }
            c.closed = closed;
        }
    }

    pub(super) fn effect_truth(&self, i: usize, e: &EffectSpec) -> EffectTruth {
        let (floors, max) = match *e {
            EffectSpec::Contact { lower, .. } => (vec![lower, lower + 1], self.max_drift[lower]),
            EffectSpec::Cubic { storey, .. } | EffectSpec::Hysteresis { storey, .. } => {
                (vec![storey - 1, storey], self.max_drift[storey - 1])
            }
            EffectSpec::Friction { floor, .. } => (vec![floor], self.max_vel[floor - 1]),
            // Its largest velocity is the structure's (see `Hysteretic::observe`).
            EffectSpec::QuadraticDamping { site, .. } => match site {
                DampingSite::Storey(s) => (vec![s - 1, s], 0.0),
                DampingSite::Floor(f) => (vec![f], 0.0),
            },
        };
        let mut parameters = e.parameters_json();
        if let EffectSpec::Contact { side, .. } = *e {
            parameters.insert("side_fmu".into(), json!(side));
        }
        let parameters = Value::Object(parameters);
        let contact = self.contacts.iter().find(|c| c.effect == i);
        EffectTruth {
            kind: e.kind().into(),
            location: e.location(),
            floors,
            description: format!("{} {}", e.kind(), e.describe_location()),
            fmu_prefix: e.fmu_prefix(),
            in_library: e.in_library(),
            library_location: e.library_location(),
            parameters,
            contact_events: contact.map(|c| c.events),
            time_in_contact: contact.map(|c| c.time),
            first_contact: contact.and_then(|c| c.first),
            max_penetration: contact.map(|c| c.max_penetration),
            max_drift_or_velocity: max,
            z_saturation: None,
            max_abs_z: None,
            hysteretic_work: None,
            dissipated_energy: None,
        }
    }
}
