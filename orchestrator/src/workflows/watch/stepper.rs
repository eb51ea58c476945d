//! The twin's system stepped one sample at a time: built by `twin::system` as `run_twin` builds
//! it, the measured force its one driven input, and driven through the master's step-at-a-time
//! calls (the force for the next point → `System::step` → the accelerations), so a stream gets
//! the batch run's prediction from the same stepping code.

use crate::cosim::import::StepEnd;
use crate::cosim::master::{MasterError, NodeId, Port, SavedNode, SavedState};
use crate::twin::system::{SystemBuilder, SystemError, TwinSystem};
use crate::twin::{ParameterValue, Twin, TwinError, OUTPUTS};

use super::WatchError;

/// The system input the stream drives.
const FORCE: &str = "force";

/// The GP corrector's learning interface: the measured accelerations and the learn flag it
/// takes, the latent variances and training-set size it gives.
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
    force: Port,
    /// The system's accelerations, per floor.
    acc: Vec<Port>,
    learner: Option<NodeId>,
}

pub struct Stepper<'t> {
    builder: SystemBuilder<'t>,
    running: Option<Running>,
    learner: Option<Learner>,
}

impl<'t> Stepper<'t> {
    /// Open the twin's FMUs; the system comes with [`Stepper::start`].
    pub fn new(twin: &'t Twin) -> Result<Self, WatchError> {
        let builder = SystemBuilder::open(twin)?;
        let learner = twin.components.iter().find_map(|c| {
            let fmu = builder.fmu(&c.name)?;
            let vr = |name: &str| fmu.value_reference(name).ok();
            let floors = |stem: &str| -> Option<Vec<u32>> {
                (1..=OUTPUTS.len())
                    .map(|f| vr(&format!("{stem}{f}")))
                    .collect()
            };
            Some(Learner {
                component: c.name.clone(),
                measured: floors("measured_acc")?,
                learn: vr("learn")?,
                latent: floors("latent_var")?,
                points: vr("training_points")?,
                pending: false,
            })
        });
        Ok(Stepper {
            builder,
            running: None,
            learner,
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

    /// The corrector's latent variances V(f) per floor at the current point.
    pub fn latent_variance(&mut self) -> Result<Option<[f64; 3]>, WatchError> {
        let Some((l, slave)) = self.learner_slave()? else {
            return Ok(None);
        };
        let mut v = [0.0; 3];
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

    /// The current point joins the corrector's training sets, with these measured
    /// accelerations, at the next step.
    pub fn learn_current(&mut self, measured: [f64; 3]) -> Result<(), WatchError> {
        let Some((l, slave)) = self.learner_slave()? else {
            return Ok(());
        };
        slave.set_real(&l.measured, &measured).map_err(master)?;
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
            .build(start, vec![(FORCE, Vec::new())])
            .map_err(system_error)?;
        let force = system.signal(FORCE).ok_or_else(|| {
            WatchError::Twin(TwinError::Message(format!(
                "{} takes no '{FORCE}' input",
                twin.describe()
            )))
        })?;
        let acc = OUTPUTS
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
            force,
            acc,
            learner,
        });
        if let Some(l) = &mut self.learner {
            l.pending = false;
        }
        Ok(())
    }

    /// Go to the point `time` with force `force` (the step from the last point, with the
    /// force's ramp; the first point of a segment is evaluated where it is) and return the
    /// predicted accelerations there.
    pub fn advance(&mut self, time: f64, force: f64) -> Result<[f64; 3], WatchError> {
        let running = self.running.as_mut().ok_or(WatchError::NotStarted)?;
        let system = &mut running.system.system;
        system.set_input(running.force, force).map_err(master)?;
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
        let mut acc = [0.0; 3];
        for (a, &port) in acc.iter_mut().zip(&running.acc) {
            *a = system.value(port);
        }
        Ok(acc)
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

    /// Put the FMUs (started) back in saved states; `last`: the last point's (time, force).
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
        let Some((time, force)) = last else {
            // Saved right after a start, before the segment's first point: the instances are
            // as started.
            return Ok(());
        };
        let saved = SavedState {
            time,
            signals: vec![force],
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

    /// The last point's (time, force), None before a segment's first point.
    pub fn last(&self) -> Option<(f64, f64)> {
        let running = self.running.as_ref()?;
        let time = running.system.system.time()?;
        Some((time, running.system.system.value(running.force)))
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
