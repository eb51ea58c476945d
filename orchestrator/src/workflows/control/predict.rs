//! A controller given as a spec (`twin control --spec`, the Python package): its designs, and
//! the twin's response under it predicted.

use super::closed_loop::{simulate, Gains, LoopLaw, LoopSetup, StateSource};
use super::design::{plant_measuring, with_actuator_at};
use super::runs::{check_record, force_limit};
use super::ControlError;
use crate::synth::InLoopController;
use crate::twin::data::Measurement;
use crate::twin::Twin;
use numerics::lqr::Estimator;
use structure::channel::Channel;
use structure::Structure;

/// A controller read back from a `twin control` report: what `twin synth --controller` puts in
/// the synthetic structure's loop.
#[derive(Clone, Debug, serde::Deserialize)]
pub struct ControllerSpec {
    pub parameters: std::collections::BTreeMap<String, f64>,
    pub state_scale: f64,
    pub estimator_settings: Estimator,
    pub control_rate_hz: f64,
    pub sensor_noise_sd: Option<Vec<f64>>,
    pub designs: Vec<SpecDesign>,
    /// `force:K` or `base` (a report from before excitations were named: a force at floor 1).
    #[serde(default)]
    pub excitation: Option<String>,
    /// The actuator's floor (absent: 1).
    #[serde(default)]
    pub actuator_floor: Option<usize>,
    /// The channels the controller reads (absent: every floor's acceleration).
    #[serde(default)]
    pub measured: Option<Vec<String>>,
}

#[derive(Clone, Debug, serde::Deserialize)]
pub struct SpecDesign {
    pub q: f64,
    pub gain: Vec<f64>,
    pub unstable: Option<String>,
}

impl ControllerSpec {
    /// Read a `twin control` report.
    pub fn load(path: &std::path::Path) -> Result<Self, ControlError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ControlError::Options(format!("cannot read {}: {e}", path.display())))?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// Parse a report's JSON text; `origin` names it in errors.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, ControlError> {
        let de = &mut serde_json::Deserializer::from_str(text);
        serde_path_to_error::deserialize(de).map_err(|e| {
            ControlError::Options(format!(
                "{origin}: not a `twin control` report: at {}: {}",
                e.path(),
                e.inner()
            ))
        })
    }

    /// The design with state weight `q` (None: the first stable one).
    pub fn design(&self, q: Option<f64>) -> Result<&SpecDesign, ControlError> {
        let stable = || self.designs.iter().filter(|d| d.unstable.is_none());
        match q {
            Some(q) => stable().find(|d| d.q == q).ok_or_else(|| {
                let have: Vec<String> = stable().map(|d| d.q.to_string()).collect();
                ControlError::Options(format!(
                    "the report has no stable design with q = {q} (it has {})",
                    have.join(", ")
                ))
            }),
            None => stable()
                .next()
                .ok_or_else(|| ControlError::Options("the report has no stable design".into())),
        }
    }

    /// The structure the design was made on: as many storeys as the report has masses
    /// (m1, m2, … without a gap), each with its c and k.
    pub fn structure(&self) -> Result<Structure, ControlError> {
        let get = |name: String| {
            self.parameters.get(&name).copied().ok_or_else(|| {
                ControlError::Options(format!("the report's parameters lack '{name}'"))
            })
        };
        let storeys = (1..)
            .take_while(|i| self.parameters.contains_key(&format!("m{i}")))
            .count();
        if storeys == 0 {
            return Err(ControlError::Options(
                "the report's parameters lack 'm1'".into(),
            ));
        }
        let excitation = match &self.excitation {
            None => structure::Excitation::default(),
            Some(text) => structure::Excitation::parse(text)
                .map_err(|e| ControlError::Options(format!("the report's excitation: {e}")))?,
        };
        let mut s = Structure::uniform(storeys, 0.0, 0.0, 0.0, excitation);
        for name in s.parameter_names() {
            let value = get(name.clone())?;
            s.set(&name, value);
        }
        s.validate()
            .map_err(|e| ControlError::Options(format!("the report's structure: {e}")))?;
        Ok(s)
    }

    /// The actuator's floor (1 for a report that names none).
    pub fn actuator_floor(&self) -> usize {
        self.actuator_floor.unwrap_or(1)
    }

    /// The channels the controller reads, in its order (every floor's acceleration for a
    /// report that names none).
    pub fn measured(&self) -> Result<Vec<Channel>, ControlError> {
        let storeys = self.structure()?.storeys();
        match &self.measured {
            None => Ok(fmu_lqr::model::every_acceleration(storeys)),
            Some(names) => names
                .iter()
                .map(|n| {
                    Channel::parse(n).ok_or_else(|| {
                        ControlError::Options(format!(
                            "the report's measured channel '{n}' is not acc<i>, vel<i> or disp<i>"
                        ))
                    })
                })
                .collect(),
        }
    }

    /// The design's plant: the report's structure, actuator and measured channels.
    pub fn plant(&self) -> Result<numerics::lqr::StateSpace, ControlError> {
        plant_measuring(
            &self.structure()?,
            self.actuator_floor(),
            &self.measured()?,
            self.state_scale,
        )
    }

    /// The controller for design `q`, sampling every `dt` seconds (the report's rate is
    /// `control_rate_hz`).
    pub fn controller(
        &self,
        q: Option<f64>,
        dt: f64,
    ) -> Result<numerics::lqr::Controller, ControlError> {
        let design = self.design(q)?;
        let plant = self.plant()?;
        if !(self.control_rate_hz.is_finite() && self.control_rate_hz > 0.0) {
            return Err(ControlError::Options(format!(
                "the report's control rate {} Hz is not positive",
                self.control_rate_hz
            )));
        }
        Ok(numerics::lqr::Controller::new(
            &plant,
            &design.gain,
            &self.estimator_settings,
            dt,
        )?)
    }
}

/// The twin's prediction of a controlled record: the twin's physics in the loop with the
/// report's controller (reading the twin's own accelerations, without noise), driven by the
/// record's force — not the record's control force replayed open-loop, which a high-gain loop
/// makes ill-conditioned (the structure answers to the small difference of two large forces).
pub fn predict_controlled(
    twin: &Twin,
    data: &Measurement,
    spec: &ControllerSpec,
    q: Option<f64>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<crate::twin::run::Prediction, ControlError> {
    let design = spec.design(q)?;
    let plant = spec.plant()?;
    let structure = spec.structure()?;
    check_record(data, &structure)?;
    let controlled = with_actuator_at(twin, spec.actuator_floor())?;
    let substeps = (spec.control_rate_hz * data.dt).round().max(1.0) as usize;
    let setup = LoopSetup {
        plant,
        measured: spec.measured()?,
        substeps,
        noise: None,
        gaps: Vec::new(),
        force_limit: force_limit(&structure, data),
        corrector: false,
    };
    let law = LoopLaw {
        gains: Gains::Fixed(design.gain.clone()),
        state: StateSource::Estimated(spec.estimator_settings.clone()),
    };
    let r = simulate(&controlled, data, &setup, Some(&law), progress)?;
    Ok(crate::twin::run::Prediction::of_accelerations(
        r.time, r.acc,
    ))
}

/// The synthetic structure's in-loop controller made from a control report: the control
/// workflow reads its own report, so the synthetic structure needs nothing above it.
impl InLoopController {
    /// A `twin control` report's design `q` (None: its first stable one) in the loop, at the
    /// report's controller rate and with its sensor noise (none if it had none), drawn from
    /// `seed`. A bad report or design is refused now, before a record is made.
    pub fn from_report(
        spec: ControllerSpec,
        q: Option<f64>,
        seed: u64,
    ) -> Result<Self, ControlError> {
        let interval = 1.0 / spec.control_rate_hz;
        spec.controller(q, interval)?;
        let floors = spec.structure()?.storeys();
        let sensor_sd = spec
            .sensor_noise_sd
            .clone()
            .unwrap_or_else(|| vec![0.0; floors]);
        Ok(InLoopController {
            make: Box::new(move |dt| spec.controller(q, dt).map_err(|e| e.to_string())),
            interval,
            sensor_sd,
            seed,
        })
    }
}
