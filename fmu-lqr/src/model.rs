//! The controller FMU's model: parameters → `numerics::lqr::Controller` at the end of
//! initialization, one `Controller::step` per `fmi2DoStep`.

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
use numerics::lqr::{Controller, ControllerMemory, Estimator, StateSpace};
use serde::{Deserialize, Serialize};
use structure::{Excitation, Structure};

use crate::variables::{self as vars, *};

/// Relative tolerance on the communication step against `sample_interval`.
pub const STEP_TOLERANCE: f64 = 1e-9;

/// Everything the host sets before initialization.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameters {
    /// One per state: the floors' displacements, then their velocities.
    pub gain: Vec<f64>,
    pub state_scale: f64,
    /// The observer's model: the structure (m, c, k; the shaker at floor 1, which `force` is).
    pub structure: Structure,
    /// The floor the control force acts on (1-based).
    pub actuator_floor: usize,
    /// 0 integrate, 1 Kalman.
    pub estimator: i32,
    pub highpass_hz: f64,
    pub process_sd: f64,
    /// One per floor.
    pub sensor_sd: Vec<f64>,
    pub sample_interval: f64,
}

impl Default for Parameters {
    fn default() -> Self {
        Parameters {
            gain: vec![0.0; 2 * FLOORS],
            state_scale: 1.0,
            structure: Structure::uniform(
                FLOORS,
                DEFAULT_MASS,
                DEFAULT_DAMPING,
                DEFAULT_STIFFNESS,
                Excitation::Force { floor: 1 },
            ),
            actuator_floor: DEFAULT_ACTUATOR_FLOOR,
            estimator: 0,
            highpass_hz: DEFAULT_HIGHPASS_HZ,
            process_sd: DEFAULT_PROCESS_SD,
            sensor_sd: vec![DEFAULT_SENSOR_SD; FLOORS],
            sample_interval: DEFAULT_SAMPLE_INTERVAL,
        }
    }
}

/// The controller's model of `structure` with the actuator at `actuator_floor`, the state in
/// units of `state_scale` metres: the one way from a structure to the LQR's plant, for this FMU
/// and the orchestrator's designs.
pub fn plant(
    structure: &Structure,
    actuator_floor: usize,
    state_scale: f64,
) -> Result<StateSpace, String> {
    let si = structure.state_space().map_err(|e| e.to_string())?;
    let actuator = structure
        .force_input(actuator_floor)
        .map_err(|e| format!("the actuator: {e}"))?;
    StateSpace::from_si(
        &si.a,
        &si.c,
        (&si.b, &si.d),
        (&actuator.0, &actuator.1),
        state_scale,
    )
    .map_err(|e| e.to_string())
}

impl Parameters {
    pub fn estimator(&self) -> Result<Estimator, String> {
        match self.estimator {
            0 => Ok(Estimator::Integrate {
                highpass_hz: self.highpass_hz,
            }),
            1 => Ok(Estimator::Kalman {
                process_sd: self.process_sd,
                sensor_sd: self.sensor_sd.clone(),
            }),
            e => Err(format!("estimator = {e}: 0 (integrate) or 1 (kalman)")),
        }
    }

    /// The controller these parameters describe, with no sample seen yet.
    pub fn controller(&self) -> Result<Controller, String> {
        let plant = plant(&self.structure, self.actuator_floor, self.state_scale)?;
        Controller::new(&plant, &self.gain, &self.estimator()?, self.sample_interval)
            .map_err(|e| e.to_string())
    }
}

/// The FMU instance. Its serialized state is the parameters, the inputs, the output and the
/// controller's memory; the controller's constant part is rebuilt from the parameters.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(into = "Saved", try_from = "Saved")]
pub struct LqrModel {
    pub params: Parameters,
    acc: [f64; FLOORS],
    force: f64,
    control_force: f64,
    controller: Option<Controller>,
}

#[derive(Serialize, Deserialize)]
struct Saved {
    params: Parameters,
    acc: [f64; FLOORS],
    force: f64,
    control_force: f64,
    memory: Option<ControllerMemory>,
}

impl From<LqrModel> for Saved {
    fn from(m: LqrModel) -> Self {
        Saved {
            memory: m.controller.as_ref().map(Controller::memory),
            params: m.params,
            acc: m.acc,
            force: m.force,
            control_force: m.control_force,
        }
    }
}

impl TryFrom<Saved> for LqrModel {
    type Error = String;
    fn try_from(s: Saved) -> Result<Self, String> {
        let controller = match &s.memory {
            None => None,
            Some(memory) => {
                let mut c = s.params.controller()?;
                if !c.restore(memory) {
                    return Err("the saved controller memory is of another estimator".into());
                }
                Some(c)
            }
        };
        Ok(LqrModel {
            params: s.params,
            acc: s.acc,
            force: s.force,
            control_force: s.control_force,
            controller,
        })
    }
}

fn unknown(vr: u32, kind: &'static str) -> ModelError {
    ModelError::UnknownVariable { vr, kind }
}

impl LqrModel {
    fn real_slot(&mut self, vr: u32) -> Option<&mut f64> {
        let p = &mut self.params;
        let i = |base: u32| (vr - base) as usize;
        Some(match vr {
            GAIN..=6 => &mut p.gain[i(GAIN)],
            STATE_SCALE => &mut p.state_scale,
            MASS..=12 => &mut p.structure.mass[i(MASS)],
            DAMPING..=15 => &mut p.structure.damping[i(DAMPING)],
            STIFFNESS..=18 => &mut p.structure.stiffness[i(STIFFNESS)],
            HIGHPASS_HZ => &mut p.highpass_hz,
            PROCESS_SD => &mut p.process_sd,
            SENSOR_SD..=25 => &mut p.sensor_sd[i(SENSOR_SD)],
            SAMPLE_INTERVAL => &mut p.sample_interval,
            ACC..=32 => &mut self.acc[i(ACC)],
            vars::FORCE => &mut self.force,
            _ => return None,
        })
    }
}

impl CoSimModel for LqrModel {
    fn info() -> &'static ModelInfo {
        vars::info()
    }

    fn instantiate(_context: &InstantiateContext) -> Result<Self, ModelError> {
        Ok(LqrModel {
            params: Parameters::default(),
            acc: [0.0; FLOORS],
            force: 0.0,
            control_force: 0.0,
            controller: None,
        })
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        if vr == CONTROL_FORCE {
            return Ok(self.control_force);
        }
        self.real_slot(vr).map(|x| *x).ok_or(unknown(vr, "Real"))
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        let slot = self.real_slot(vr).ok_or(unknown(vr, "Real"))?;
        *slot = value;
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        match vr {
            ESTIMATOR => Ok(self.params.estimator),
            _ => Err(unknown(vr, "Integer")),
        }
    }

    fn set_integer(&mut self, vr: u32, value: i32) -> Result<(), ModelError> {
        match vr {
            ESTIMATOR => {
                if !(0..=1).contains(&value) {
                    return Err(ModelError::InvalidValue {
                        name: "estimator".into(),
                        reason: format!("{value}: 0 (integrate) or 1 (kalman)"),
                    });
                }
                self.params.estimator = value;
                Ok(())
            }
            _ => Err(unknown(vr, "Integer")),
        }
    }

    fn exit_initialization(&mut self) -> Result<(), ModelError> {
        let controller = self
            .params
            .controller()
            .map_err(|reason| ModelError::InvalidValue {
                name: "the controller's parameters".into(),
                reason,
            })?;
        self.controller = Some(controller);
        self.control_force = 0.0;
        Ok(())
    }

    fn do_step(&mut self, time: f64, step_size: f64) -> Result<(), ModelError> {
        let dt = self.params.sample_interval;
        if (step_size - dt).abs() > STEP_TOLERANCE * dt {
            return Err(ModelError::InvalidValue {
                name: "communicationStepSize".into(),
                reason: format!(
                    "{step_size} s at t = {time} s, but the controller samples every \
                     sample_interval = {dt} s: step by exactly that"
                ),
            });
        }
        let controller = self
            .controller
            .as_mut()
            .ok_or_else(|| ModelError::Other("the controller was not initialised".into()))?;
        let u = controller
            .step(&self.acc, self.force)
            .map_err(|e| ModelError::Other(e.to_string()))?;
        if !u.is_finite() {
            return Err(ModelError::Diverged {
                time,
                what: format!("the control force is {u}"),
            });
        }
        self.control_force = u;
        Ok(())
    }
}
