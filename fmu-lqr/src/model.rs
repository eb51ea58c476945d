//! The controller FMU's model: parameters → `numerics::lqr::Controller` at the end of
//! initialization, one `Controller::step` per `fmi2DoStep`.

use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo};
use numerics::lqr::{Controller, ControllerMemory, Estimator, StateSpace};
use serde::{Deserialize, Serialize};
use structure::channel::{Channel, Quantity};
use structure::{Excitation, Structure};

pub use crate::variables::Layout;
use crate::variables::{self as vars, *};

/// Relative tolerance on the communication step against `sample_interval`.
pub const STEP_TOLERANCE: f64 = 1e-9;

/// Everything the host sets before initialization.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameters {
    /// One per state: the floors' displacements, then their velocities.
    pub gain: Vec<f64>,
    pub state_scale: f64,
    /// The observer's model (m, c, k and the excitation, which `force` or `ground_acc` is),
    /// the actuator's floor and the measured channels.
    #[serde(with = "layout_code")]
    pub layout: Layout,
    /// 0 integrate, 1 Kalman.
    pub estimator: i32,
    pub highpass_hz: f64,
    pub process_sd: f64,
    /// One per measured channel.
    pub sensor_sd: Vec<f64>,
    pub sample_interval: f64,
}

/// The layout in the FMU state as plain numbers and names: the serialized state is postcard,
/// which cannot read [`structure::Excitation`]'s tagged form.
mod layout_code {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use structure::channel::Channel;
    use structure::{Excitation, Structure};

    use crate::variables::Layout;

    #[derive(Serialize, Deserialize)]
    struct Plain {
        mass: Vec<f64>,
        damping: Vec<f64>,
        stiffness: Vec<f64>,
        /// 0 ground acceleration, K a force at floor K.
        excitation: u64,
        actuator_floor: u64,
        measured: Vec<String>,
    }

    pub fn serialize<S: Serializer>(l: &Layout, s: S) -> Result<S::Ok, S::Error> {
        Plain {
            mass: l.structure.mass.clone(),
            damping: l.structure.damping.clone(),
            stiffness: l.structure.stiffness.clone(),
            excitation: match l.structure.excitation {
                Excitation::Force { floor } => floor as u64,
                Excitation::Base => 0,
            },
            actuator_floor: l.actuator_floor as u64,
            measured: l.measured.iter().map(Channel::name).collect(),
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Layout, D::Error> {
        let p = Plain::deserialize(d)?;
        let measured = p
            .measured
            .iter()
            .map(|n| {
                Channel::parse(n)
                    .ok_or_else(|| serde::de::Error::custom(format!("measured channel '{n}'")))
            })
            .collect::<Result<_, _>>()?;
        Ok(Layout {
            structure: Structure {
                mass: p.mass,
                damping: p.damping,
                stiffness: p.stiffness,
                excitation: match p.excitation {
                    0 => Excitation::Base,
                    floor => Excitation::Force {
                        floor: floor as usize,
                    },
                },
            },
            actuator_floor: p.actuator_floor as usize,
            measured,
        })
    }
}

impl Default for Parameters {
    fn default() -> Self {
        Parameters::of(Layout::default())
    }
}

impl Parameters {
    /// The defaults of a layout: zero gains, the state in metres, the integrating estimator.
    pub fn of(layout: Layout) -> Self {
        Parameters {
            gain: vec![0.0; 2 * layout.storeys()],
            state_scale: 1.0,
            estimator: 0,
            highpass_hz: DEFAULT_HIGHPASS_HZ,
            process_sd: DEFAULT_PROCESS_SD,
            sensor_sd: vec![DEFAULT_SENSOR_SD; layout.measured.len()],
            sample_interval: DEFAULT_SAMPLE_INTERVAL,
            layout,
        }
    }
}

/// The controller's model of `structure` with the actuator at `actuator_floor`, measuring every
/// floor's acceleration, the state in units of `state_scale` metres.
pub fn plant(
    structure: &Structure,
    actuator_floor: usize,
    state_scale: f64,
) -> Result<StateSpace, String> {
    plant_measuring(
        structure,
        actuator_floor,
        &every_acceleration(structure.storeys()),
        state_scale,
    )
}

pub use crate::variables::every_acceleration;

/// The controller's model of `structure` with the actuator at `actuator_floor`, reading the
/// response channels `measured` (`acc<i>`: absolute acceleration; `vel<i>`, `disp<i>`: relative
/// to the ground; in that order the controller takes them), the state in units of
/// `state_scale` metres: the one way from a structure to the LQR's plant, for this FMU and the
/// orchestrator's designs. A channel the structure cannot give (no such floor, not a response)
/// is refused by name.
pub fn plant_measuring(
    structure: &Structure,
    actuator_floor: usize,
    measured: &[Channel],
    state_scale: f64,
) -> Result<StateSpace, String> {
    let si = structure.state_space().map_err(|e| e.to_string())?;
    let actuator = structure
        .force_input(actuator_floor)
        .map_err(|e| format!("the actuator: {e}"))?;
    let n = structure.storeys();
    if measured.is_empty() {
        return Err("the controller measures nothing: give it at least one channel".into());
    }
    let rows = measured.len();
    let mut c = nalgebra::DMatrix::zeros(rows, 2 * n);
    let mut excitation_d = nalgebra::DVector::zeros(rows);
    let mut actuator_d = nalgebra::DVector::zeros(rows);
    let mut ground = nalgebra::DVector::zeros(rows);
    for (row, channel) in measured.iter().enumerate() {
        let name = channel.name();
        channel
            .check(&name, structure)
            .map_err(|e| format!("the controller's measurement: {e}"))?;
        let Channel::Response { quantity, floor } = *channel else {
            return Err(format!(
                "the controller's measurement '{name}' is not a response (acc<i>, vel<i>, disp<i>)"
            ));
        };
        let i = floor - 1;
        match quantity {
            Quantity::Acceleration => {
                c.row_mut(row).copy_from(&si.c.row(i));
                excitation_d[row] = si.d[i];
                actuator_d[row] = actuator.1[i];
                if structure.excitation == Excitation::Base {
                    ground[row] = 1.0;
                }
            }
            Quantity::Velocity => c[(row, n + i)] = 1.0,
            Quantity::Displacement => c[(row, i)] = 1.0,
            Quantity::Time | Quantity::Force => {
                return Err(format!(
                    "the controller's measurement '{name}' is not a response"
                ))
            }
        }
    }
    StateSpace::from_si(
        &si.a,
        &c,
        (&si.b, &excitation_d),
        (&actuator.0, &actuator_d),
        state_scale,
    )
    .and_then(|p| p.with_ground_in_reading(ground))
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
        let l = &self.layout;
        let plant = plant_measuring(
            &l.structure,
            l.actuator_floor,
            &l.measured,
            self.state_scale,
        )?;
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
    /// One per measured channel, in the layout's order.
    measurements: Vec<f64>,
    force: f64,
    control_force: f64,
    controller: Option<Controller>,
    /// This instance's variable table (its layout's).
    table: &'static ModelInfo,
}

#[derive(Serialize, Deserialize)]
struct Saved {
    params: Parameters,
    measurements: Vec<f64>,
    force: f64,
    control_force: f64,
    memory: Option<ControllerMemory>,
}

impl From<LqrModel> for Saved {
    fn from(m: LqrModel) -> Self {
        Saved {
            memory: m.controller.as_ref().map(Controller::memory),
            params: m.params,
            measurements: m.measurements,
            force: m.force,
            control_force: m.control_force,
        }
    }
}

impl TryFrom<Saved> for LqrModel {
    type Error = String;
    fn try_from(s: Saved) -> Result<Self, String> {
        let layout = s.params.layout.clone().checked()?;
        if s.measurements.len() != layout.measured.len() {
            return Err("the saved measurements are not the layout's".into());
        }
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
            table: vars::table(&layout),
            params: s.params,
            measurements: s.measurements,
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
    /// An instance for `layout` (checked), with its defaults.
    pub fn for_layout(layout: Layout) -> Result<Self, String> {
        let layout = layout.checked()?;
        Ok(LqrModel {
            table: vars::table(&layout),
            measurements: vec![0.0; layout.measured.len()],
            params: Parameters::of(layout),
            force: 0.0,
            control_force: 0.0,
            controller: None,
        })
    }

    /// An instance for the layout in `resources/structure.json` under the FMU's resources, or
    /// the paper's rig without one.
    pub fn from_resources(resource_dir: Option<&std::path::Path>) -> Result<Self, ModelError> {
        let layout = match resource_dir.map(|d| d.join(LAYOUT_RESOURCE)) {
            Some(path) if path.exists() => read_layout(&path)?,
            _ => Layout::default(),
        };
        LqrModel::for_layout(layout).map_err(ModelError::Other)
    }

    fn real_slot(&mut self, vr: u32) -> Option<&mut f64> {
        let p = &mut self.params;
        let n = p.layout.storeys();
        let within = |base: u32, count: usize| {
            vr.checked_sub(base)
                .map(|i| i as usize)
                .filter(|&i| i < count)
        };
        if let Some(i) = within(GAIN, 2 * n) {
            return p.gain.get_mut(i);
        }
        if let Some(i) = within(MASS, n) {
            return p.layout.structure.mass.get_mut(i);
        }
        if let Some(i) = within(DAMPING, n) {
            return p.layout.structure.damping.get_mut(i);
        }
        if let Some(i) = within(STIFFNESS, n) {
            return p.layout.structure.stiffness.get_mut(i);
        }
        if let Some(j) = within(SENSOR_SD, p.sensor_sd.len()) {
            return p.sensor_sd.get_mut(j);
        }
        if (ACC..SENSOR_SD).contains(&vr) {
            let j = p
                .layout
                .measured
                .iter()
                .position(|c| vars::input_vr(c) == Some(vr))?;
            return self.measurements.get_mut(j);
        }
        let excitation_vr = match p.layout.structure.excitation {
            Excitation::Force { .. } => vars::FORCE,
            Excitation::Base => vars::GROUND_ACC,
        };
        Some(match vr {
            STATE_SCALE => &mut p.state_scale,
            HIGHPASS_HZ => &mut p.highpass_hz,
            PROCESS_SD => &mut p.process_sd,
            SAMPLE_INTERVAL => &mut p.sample_interval,
            vr if vr == excitation_vr => &mut self.force,
            _ => return None,
        })
    }
}

/// The resource that says which layout an FMU serves, under its `resources/`.
pub const LAYOUT_RESOURCE: &str = "structure.json";

fn read_layout(path: &std::path::Path) -> Result<Layout, ModelError> {
    let fail = |why: String| ModelError::Other(format!("{}: {why}", path.display()));
    let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
    let layout: Layout = serde_json::from_str(&text).map_err(|e| fail(e.to_string()))?;
    layout.checked().map_err(fail)
}

impl CoSimModel for LqrModel {
    fn info() -> &'static ModelInfo {
        vars::info()
    }

    fn table(&self) -> &'static ModelInfo {
        self.table
    }

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError> {
        LqrModel::from_resources(context.resource_dir.as_deref())
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
            .step(&self.measurements, self.force)
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
