//! The twin's system stepped one sample at a time: built by `twin::system` as `run_twin` builds
//! it, the measured excitation (`force` or `ground_acc`) its one driven input, and driven
//! through the master's step-at-a-time calls (the excitation for the next point →
//! `System::step` → the measured channels' predictions), so a stream gets the batch run's
//! prediction from the same stepping code. A channel the twin does not give out under its name
//! is read from its physics component, as `run_twin` reads it ([`Twin::wired_for`]).

use ::structure::channel::Channel;

use crate::cosim::import::StepEnd;
use crate::cosim::master::{MasterError, NodeId, Port, SavedNode, SavedState};
use crate::twin::system::{SystemBuilder, SystemError, TwinSystem};
use crate::twin::{ParameterValue, Twin, TwinError, PHYSICS};

use super::WatchError;

/// The GP corrector's learning interface: the measured values and the learn flag it takes,
/// the latent variances and training-set size it gives; per measured channel, in the stream's
/// order.
struct Learner {
    component: String,
    measured: Vec<u32>,
    learn: u32,
    latent: Vec<u32>,
    points: u32,
    /// Lower the learn flag after the next step.
    pending: bool,
}

/// The running system and where its ports are.
struct Running {
    system: TwinSystem,
    excitation: Port,
    /// The system's predictions, per measured channel.
    outputs: Vec<Port>,
    learner: Option<NodeId>,
}

pub struct Stepper {
    builder: SystemBuilder,
    running: Option<Running>,
    learner: Option<Learner>,
    /// The driven input (`force` or `ground_acc`) and the predicted channels.
    excitation: String,
    channels: Vec<String>,
}

impl Stepper {
    /// Open the twin's FMUs (`twin` gives out every one of `channels`: see [`wired`]); the
    /// system comes with [`Stepper::start`]. `excitation`: the stream's, driving the twin.
    /// A GP corrector that learns must take every measured channel (`measured_<name>`) and give
    /// its latent variance, and learn from no channel the stream lacks: refused otherwise.
    pub fn new(twin: &Twin, excitation: Channel, channels: &[Channel]) -> Result<Self, WatchError> {
        let builder = SystemBuilder::open(twin)?;
        let mut learner = None;
        for c in &twin.components {
            let Some(fmu) = builder.fmu(&c.name) else {
                continue;
            };
            let vr = |name: &str| fmu.value_reference(name).ok();
            let (Some(learn), Some(points)) = (vr("learn"), vr("training_points")) else {
                continue;
            };
            let refuse = |what: String| {
                WatchError::Options(format!(
                    "{}: its GP corrector (component '{}') {what}; watch a stream of the \
                     channels it corrects, or the twin without its corrector",
                    twin.describe(),
                    c.name
                ))
            };
            let mut measured = Vec::new();
            let mut latent = Vec::new();
            for channel in channels {
                let name = channel.name();
                measured.push(vr(&format!("measured_{name}")).ok_or_else(|| {
                    refuse(format!(
                        "takes no 'measured_{name}' to learn the stream's '{name}'"
                    ))
                })?);
                let band = fmu_gp_corrector::layout::band_name("latent_var", channel);
                latent.push(vr(&band).ok_or_else(|| {
                    refuse(format!("gives no '{band}' for the stream's '{name}'"))
                })?);
            }
            let names: Vec<String> = channels.iter().map(Channel::name).collect();
            if let Some(lacking) = fmu
                .model_description
                .inputs()
                .filter_map(|v| v.name.strip_prefix("measured_"))
                .find(|n| !names.iter().any(|m| m == n))
            {
                return Err(refuse(format!(
                    "learns from '{lacking}', which the stream does not measure"
                )));
            }
            learner = Some(Learner {
                component: c.name.clone(),
                measured,
                learn,
                latent,
                points,
                pending: false,
            });
            break;
        }
        Ok(Stepper {
            builder,
            running: None,
            learner,
            excitation: excitation.name(),
            channels: channels.iter().map(Channel::name).collect(),
        })
    }

    /// Whether the twin has a corrector that learns (the GP corrector FMU).
    pub fn has_learner(&self) -> bool {
        self.learner.is_some()
    }

    /// Set an integer parameter of the corrector for the next [`Stepper::start`]; false when
    /// its FMU has no such parameter (a corrector built before it had one).
    pub fn set_learner_parameter(&mut self, name: &str, value: i32) -> bool {
        let Some(l) = &self.learner else {
            return false;
        };
        self.builder
            .set_parameter(&l.component, name, ParameterValue::Integer(value))
    }

    fn running(&mut self) -> Result<&mut Running, WatchError> {
        self.running.as_mut().ok_or(WatchError::NotStarted)
    }

    /// The corrector's slave with its interface (None: the twin has no corrector).
    fn learner_slave(
        &mut self,
    ) -> Result<Option<(&mut Learner, &mut dyn crate::cosim::master::Slave)>, WatchError> {
        let Some(l) = &mut self.learner else {
            return Ok(None);
        };
        let running = self.running.as_mut().ok_or(WatchError::NotStarted)?;
        let slave = running
            .learner
            .and_then(|node| running.system.system.slave_mut(node))
            .ok_or(WatchError::NotStarted)?;
        Ok(Some((l, slave)))
    }

    /// The corrector's latent variances V(f) per measured channel at the current point.
    pub fn latent_variance(&mut self) -> Result<Option<Vec<f64>>, WatchError> {
        let Some((l, slave)) = self.learner_slave()? else {
            return Ok(None);
        };
        let mut v = vec![0.0; l.latent.len()];
        slave.get_real(&l.latent, &mut v).map_err(master)?;
        Ok(Some(v))
    }

    /// The corrector's training-set size.
    pub fn training_points(&mut self) -> Result<Option<i32>, WatchError> {
        let Some((l, slave)) = self.learner_slave()? else {
            return Ok(None);
        };
        let mut n = [0];
        slave.get_integer(&[l.points], &mut n).map_err(master)?;
        Ok(Some(n[0]))
    }

    /// The current point joins the corrector's training sets, with these measured values
    /// (per measured channel), at the next step.
    pub fn learn_current(&mut self, measured: &[f64]) -> Result<(), WatchError> {
        let Some((l, slave)) = self.learner_slave()? else {
            return Ok(());
        };
        slave.set_real(&l.measured, measured).map_err(master)?;
        slave.set_boolean(&[l.learn], &[true]).map_err(master)?;
        l.pending = true;
        Ok(())
    }

    /// (Re)start the twin's system at rest at `start` (s): new instances, the twin's
    /// parameters, initialised; the first point comes with [`Stepper::advance`].
    pub fn start(&mut self, start: f64) -> Result<(), WatchError> {
        self.running = None;
        let twin = self.builder.twin();
        let system = self
            .builder
            .build(start, vec![(self.excitation.as_str(), Vec::new())])
            .map_err(system_error)?;
        let excitation = system.signal(&self.excitation).ok_or_else(|| {
            WatchError::Twin(TwinError::Message(format!(
                "{} takes no '{}' input",
                twin.describe(),
                self.excitation
            )))
        })?;
        let outputs = self
            .channels
            .iter()
            .map(|output| system.system_output(twin, output))
            .collect::<Result<Vec<_>, _>>()
            .map_err(system_error)?;
        let learner = self
            .learner
            .as_ref()
            .and_then(|l| system.node(&l.component));
        self.running = Some(Running {
            system,
            excitation,
            outputs,
            learner,
        });
        if let Some(l) = &mut self.learner {
            l.pending = false;
        }
        Ok(())
    }

    /// [`Stepper::start`] with the physics starting from `state` (its shear FMU's start values,
    /// `disp{i}_start`, `vel{i}_start`) instead of rest; a later start is at rest again.
    pub fn start_from(&mut self, start: f64, state: &[(String, f64)]) -> Result<(), WatchError> {
        let set = |builder: &mut SystemBuilder, zero: bool| {
            for (name, value) in state {
                let value = if zero { 0.0 } else { *value };
                builder.set_parameter(PHYSICS, name, ParameterValue::Real(value));
            }
        };
        set(&mut self.builder, false);
        let started = self.start(start);
        set(&mut self.builder, true);
        started
    }

    /// Go to the point `time` with excitation `excitation` (the step from the last point,
    /// with the excitation's ramp; the first point of a segment is evaluated where it is) and
    /// write the measured channels' predictions there into `predicted`.
    pub fn advance(
        &mut self,
        time: f64,
        excitation: f64,
        predicted: &mut [f64],
    ) -> Result<(), WatchError> {
        let running = self.running.as_mut().ok_or(WatchError::NotStarted)?;
        let system = &mut running.system.system;
        system
            .set_input(running.excitation, excitation)
            .map_err(master)?;
        if system.time().is_some() {
            if let StepEnd::Terminated { at } = system.step(time).map_err(master)? {
                return Err(WatchError::Twin(TwinError::Message(format!(
                    "a component of the twin ended the simulation at t = {at} s"
                ))));
            }
            if let Some(l) = &mut self.learner {
                if l.pending {
                    l.pending = false;
                    let slave = running
                        .learner
                        .and_then(|node| system.slave_mut(node))
                        .ok_or(WatchError::NotStarted)?;
                    slave.set_boolean(&[l.learn], &[false]).map_err(master)?;
                }
            }
        } else {
            system.initialize(time).map_err(master)?;
        }
        for (p, &port) in predicted.iter_mut().zip(&running.outputs) {
            *p = system.value(port);
        }
        Ok(())
    }

    /// Every FMU's state, serialised (refused when an FMU does not declare serialisable states).
    pub fn save(&mut self) -> Result<Vec<NodeState>, WatchError> {
        let saved = self.running()?.system.system.save().map_err(master)?;
        Ok(saved
            .nodes
            .into_iter()
            .map(|n| NodeState {
                component: n.name,
                state: n.state,
                outputs: n.outputs,
            })
            .collect())
    }

    /// Put the FMUs (started) back in saved states; `last`: the last point's (time,
    /// excitation).
    pub fn restore(
        &mut self,
        states: &[NodeState],
        last: Option<(f64, f64)>,
    ) -> Result<(), WatchError> {
        let running = self.running()?;
        let system = &mut running.system.system;
        let names: Vec<&str> = system.node_names().collect();
        if states.len() != names.len() {
            return Err(WatchError::Checkpoint(format!(
                "it holds {} FMU states, the twin has {} components",
                states.len(),
                names.len()
            )));
        }
        for (name, saved) in names.iter().zip(states) {
            if saved.component != *name {
                return Err(WatchError::Checkpoint(format!(
                    "its FMU state is for component '{}', the twin's is '{name}'",
                    saved.component
                )));
            }
        }
        let Some((time, excitation)) = last else {
            // Saved right after a start, before the segment's first point: the instances are
            // as started.
            return Ok(());
        };
        let saved = SavedState {
            time,
            signals: vec![excitation],
            nodes: states
                .iter()
                .map(|s| SavedNode {
                    name: s.component.clone(),
                    state: s.state.clone(),
                    outputs: s.outputs.clone(),
                })
                .collect(),
        };
        system.restore(&saved).map_err(|e| match e {
            MasterError::Config(message) => WatchError::Checkpoint(message),
            other => master(other),
        })?;
        // The corrector's learn flag may have been raised when the state was saved: lowered
        // after the next step either way.
        if let Some(l) = &mut self.learner {
            l.pending = true;
        }
        Ok(())
    }

    /// The last point's (time, excitation), None before a segment's first point.
    pub fn last(&self) -> Option<(f64, f64)> {
        let running = self.running.as_ref()?;
        let time = running.system.system.time()?;
        Some((time, running.system.system.value(running.excitation)))
    }
}

/// One component's saved state in a checkpoint.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct NodeState {
    pub component: String,
    pub state: Vec<u8>,
    pub outputs: Vec<f64>,
}

/// An FMU's refusal stays an import error (with or without the time the master adds).
fn master(e: MasterError) -> WatchError {
    match e {
        MasterError::Import(e) => WatchError::Import(e),
        MasterError::AtTime { inner, .. } if matches!(*inner, MasterError::Import(_)) => {
            master(*inner)
        }
        other => WatchError::Twin(TwinError::Message(other.to_string())),
    }
}

fn system_error(e: SystemError) -> WatchError {
    match e {
        SystemError::Twin(e) => WatchError::Twin(e),
        SystemError::Master(e) => master(e),
        SystemError::Wiring(message) => WatchError::Twin(TwinError::Message(message)),
    }
}
