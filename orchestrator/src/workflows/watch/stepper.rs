//! The twin's FMUs stepped one sample at a time, in the order and with the calls `run_twin`'s
//! master makes (inputs set and outputs read at a point, Gauss–Seidel passes while coupled
//! outputs move, the measured force's slope to the next sample for FMUs that interpolate
//! inputs, then the step), so a stream gives the batch run's prediction.

use std::collections::BTreeMap;

use crate::cosim::import::{Fmu, ImportError, Instance};
use crate::twin::{apply_parameters, ParameterValue, Twin, TwinError, OUTPUTS};

use super::WatchError;

/// Where an FMU input comes from.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// The measured force.
    Force,
    /// Another node's output (node, output port).
    Node(usize, usize),
}

struct Node {
    name: String,
    // Dropped before `fmu`, whose library it runs in.
    instance: Option<Instance>,
    fmu: Fmu,
    parameters: BTreeMap<String, ParameterValue>,
    input_vrs: Vec<u32>,
    sources: Vec<Source>,
    output_vrs: Vec<u32>,
    inputs: Vec<f64>,
    outputs: Vec<f64>,
    slopes: Vec<f64>,
    /// The outputs were read after the last step with the inputs as they are now.
    fresh: bool,
}

/// The GP corrector's learning interface: the measured accelerations and the learn flag it
/// takes, the latent variances and training-set size it gives.
struct Learner {
    node: usize,
    measured: [u32; 3],
    learn: u32,
    latent: [u32; 3],
    points: u32,
    /// Learn the point at the next step (then the flag is lowered again).
    pending: bool,
}

pub struct Stepper {
    nodes: Vec<Node>,
    /// The system's accelerations: (node, output port) per floor.
    acc: [(usize, usize); 3],
    coupled: bool,
    /// The last point's force and time (None before the first point of a segment).
    last: Option<(f64, f64)>,
    learner: Option<Learner>,
}

impl Stepper {
    /// Load the twin's FMUs and wire them as `run_twin` does; instances come with [`Stepper::start`].
    pub fn new(twin: &Twin) -> Result<Self, WatchError> {
        let mut nodes = Vec::new();
        for c in &twin.components {
            let fmu = Fmu::open(&c.fmu_path).map_err(|e| component_error(twin, &c.name, e))?;
            let outputs: Vec<String> = twin
                .connections
                .iter()
                .filter(|x| x.start_element.as_deref() == Some(&c.name))
                .map(|x| x.start_connector.clone())
                .collect();
            let output_vrs = outputs
                .iter()
                .map(|n| fmu.value_reference(n))
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| component_error(twin, &c.name, e))?;
            nodes.push((c, fmu, outputs, output_vrs));
        }
        let find = |name: &str| nodes.iter().position(|(c, ..)| c.name == name);
        let mut built = Vec::new();
        for (c, _, _, _) in &nodes {
            let mut input_vrs = Vec::new();
            let mut sources = Vec::new();
            for conn in twin
                .connections
                .iter()
                .filter(|x| x.end_element.as_deref() == Some(&c.name))
            {
                let source = match &conn.start_element {
                    None if conn.start_connector == "force" => Source::Force,
                    // Other system inputs (a control force) are not in the stream.
                    None => continue,
                    Some(from) => {
                        let n = find(from).ok_or_else(|| {
                            WatchError::Twin(TwinError::Message(format!(
                                "a connection starts at no component '{from}'"
                            )))
                        })?;
                        let port = nodes[n]
                            .2
                            .iter()
                            .position(|o| *o == conn.start_connector)
                            .unwrap_or(0);
                        Source::Node(n, port)
                    }
                };
                let fmu = &nodes[find(&c.name).unwrap_or(0)].1;
                let vr = fmu
                    .value_reference(&conn.end_connector)
                    .map_err(|e| component_error(twin, &c.name, e))?;
                input_vrs.push(vr);
                sources.push(source);
            }
            built.push((input_vrs, sources));
        }
        let coupled = built
            .iter()
            .any(|(_, s)| s.iter().any(|s| matches!(s, Source::Node(..))));
        let mut acc = [(0, 0); 3];
        for (f, output) in OUTPUTS.iter().enumerate() {
            let conn = twin
                .connections
                .iter()
                .find(|c| c.end_element.is_none() && c.end_connector == *output)
                .ok_or_else(|| {
                    WatchError::Twin(TwinError::Message(format!(
                        "no connection feeds the system output '{output}'"
                    )))
                })?;
            let from = conn.start_element.as_deref().unwrap_or("");
            let n = find(from).ok_or_else(|| {
                WatchError::Twin(TwinError::Message(format!(
                    "'{output}' is fed by no component"
                )))
            })?;
            let port = nodes[n]
                .2
                .iter()
                .position(|o| *o == conn.start_connector)
                .unwrap_or(0);
            acc[f] = (n, port);
        }
        let nodes = nodes
            .into_iter()
            .zip(built)
            .map(|((c, fmu, _, output_vrs), (input_vrs, sources))| Node {
                name: c.name.clone(),
                instance: None,
                fmu,
                parameters: c.parameters.clone(),
                inputs: vec![0.0; input_vrs.len()],
                slopes: vec![0.0; input_vrs.len()],
                outputs: vec![0.0; output_vrs.len()],
                fresh: false,
                input_vrs,
                sources,
                output_vrs,
            })
            .collect::<Vec<Node>>();
        let learner = nodes.iter().enumerate().find_map(|(i, node)| {
            let vr = |name: &str| node.fmu.value_reference(name).ok();
            let three = |stem: &str| -> Option<[u32; 3]> {
                Some([
                    vr(&format!("{stem}1"))?,
                    vr(&format!("{stem}2"))?,
                    vr(&format!("{stem}3"))?,
                ])
            };
            Some(Learner {
                node: i,
                measured: three("measured_acc")?,
                learn: vr("learn")?,
                latent: three("latent_var")?,
                points: vr("training_points")?,
                pending: false,
            })
        });
        Ok(Stepper {
            nodes,
            acc,
            coupled,
            last: None,
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
        let node = &mut self.nodes[l.node];
        if node.fmu.value_reference(name).is_err() {
            return false;
        }
        node.parameters
            .insert(name.to_owned(), ParameterValue::Integer(value));
        true
    }

    /// The corrector's instance with its interface (None: the twin has no corrector).
    fn learner_instance(&mut self) -> Result<Option<(&mut Learner, &mut Instance)>, WatchError> {
        let Some(l) = &mut self.learner else {
            return Ok(None);
        };
        let instance = self.nodes[l.node]
            .instance
            .as_mut()
            .ok_or(WatchError::NotStarted)?;
        Ok(Some((l, instance)))
    }

    /// The corrector's latent variances V(f) per floor at the current point.
    pub fn latent_variance(&mut self) -> Result<Option<[f64; 3]>, WatchError> {
        let Some((l, instance)) = self.learner_instance()? else {
            return Ok(None);
        };
        let mut v = [0.0; 3];
        instance.get_real(&l.latent, &mut v)?;
        Ok(Some(v))
    }

    /// The corrector's training-set size.
    pub fn training_points(&mut self) -> Result<Option<i32>, WatchError> {
        let Some((l, instance)) = self.learner_instance()? else {
            return Ok(None);
        };
        let mut n = [0];
        instance.get_integer(&[l.points], &mut n)?;
        Ok(Some(n[0]))
    }

    /// The current point joins the corrector's training sets, with these measured
    /// accelerations, at the next step.
    pub fn learn_current(&mut self, measured: [f64; 3]) -> Result<(), WatchError> {
        let Some((l, instance)) = self.learner_instance()? else {
            return Ok(());
        };
        instance.set_real(&l.measured, &measured)?;
        instance.set_boolean(&[l.learn], &[true])?;
        l.pending = true;
        Ok(())
    }

    /// (Re)start every FMU at rest at `start` (s): new instances, the twin's parameters,
    /// initialised.
    pub fn start(&mut self, start: f64) -> Result<(), WatchError> {
        for node in &mut self.nodes {
            node.instance = None;
            let mut instance = node.fmu.instantiate(&node.name)?;
            instance.setup_experiment(start, None)?;
            instance.enter_initialization_mode()?;
            apply_parameters(&node.fmu, &mut instance, &node.parameters)?;
            instance.exit_initialization_mode()?;
            node.instance = Some(instance);
            node.fresh = false;
        }
        if let Some(l) = &mut self.learner {
            l.pending = false;
        }
        self.last = None;
        Ok(())
    }

    /// Advance to the point `time` with force `force` (stepping from the last point with the
    /// force's ramp) and return the predicted accelerations there.
    pub fn advance(&mut self, time: f64, force: f64) -> Result<[f64; 3], WatchError> {
        if let Some((t0, f0)) = self.last {
            let step = time - t0;
            let slope = (force - f0) / step;
            for node in &mut self.nodes {
                let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
                if instance.can_interpolate_inputs() && !node.input_vrs.is_empty() {
                    for (s, source) in node.slopes.iter_mut().zip(&node.sources) {
                        *s = match source {
                            Source::Force => slope,
                            Source::Node(..) => 0.0,
                        };
                    }
                    instance.set_real_input_derivatives(&node.input_vrs, &node.slopes)?;
                }
            }
            for node in &mut self.nodes {
                let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
                instance.do_step(t0, step)?;
                node.fresh = false;
            }
            if let Some(l) = &mut self.learner {
                if l.pending {
                    l.pending = false;
                    let instance = self.nodes[l.node]
                        .instance
                        .as_mut()
                        .ok_or(WatchError::NotStarted)?;
                    instance.set_boolean(&[l.learn], &[false])?;
                }
            }
        }
        self.last = Some((time, force));
        let passes = if self.coupled {
            self.nodes.len() + 2
        } else {
            1
        };
        for _ in 0..passes {
            let mut changed = false;
            for i in 0..self.nodes.len() {
                let mut same = self.nodes[i].fresh;
                for p in 0..self.nodes[i].sources.len() {
                    let value = match self.nodes[i].sources[p] {
                        Source::Force => force,
                        Source::Node(n, o) => self.nodes[n].outputs[o],
                    };
                    same &= value.to_bits() == self.nodes[i].inputs[p].to_bits();
                    self.nodes[i].inputs[p] = value;
                }
                if same {
                    // Read after this step with these very inputs: the outputs stand.
                    continue;
                }
                let node = &mut self.nodes[i];
                let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
                if !node.input_vrs.is_empty() {
                    instance.set_real(&node.input_vrs, &node.inputs)?;
                }
                let before = node.outputs.clone();
                instance.get_real(&node.output_vrs, &mut node.outputs)?;
                node.fresh = true;
                changed |= before
                    .iter()
                    .zip(&node.outputs)
                    .any(|(a, b)| a.to_bits() != b.to_bits());
            }
            if !changed {
                break;
            }
        }
        Ok(self.acc.map(|(n, o)| self.nodes[n].outputs[o]))
    }

    /// Every FMU's state, serialised (refused when an FMU does not declare serialisable states).
    pub fn save(&mut self) -> Result<Vec<NodeState>, WatchError> {
        let mut out = Vec::new();
        for node in &mut self.nodes {
            let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
            out.push(NodeState {
                component: node.name.clone(),
                state: instance.state_bytes()?,
                outputs: node.outputs.clone(),
            });
        }
        Ok(out)
    }

    /// Put the FMUs (started) back in saved states; `last`: the last point's (time, force).
    pub fn restore(
        &mut self,
        states: &[NodeState],
        last: Option<(f64, f64)>,
    ) -> Result<(), WatchError> {
        if states.len() != self.nodes.len() {
            return Err(WatchError::Checkpoint(format!(
                "it holds {} FMU states, the twin has {} components",
                states.len(),
                self.nodes.len()
            )));
        }
        for (node, saved) in self.nodes.iter_mut().zip(states) {
            if saved.component != node.name || saved.outputs.len() != node.outputs.len() {
                return Err(WatchError::Checkpoint(format!(
                    "its FMU state is for component '{}', the twin's is '{}'",
                    saved.component, node.name
                )));
            }
            let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
            instance.restore_state_bytes(&saved.state)?;
            node.outputs.clone_from(&saved.outputs);
            node.fresh = false;
        }
        self.last = last;
        // The corrector's learn flag may have been raised when the state was saved: lowered
        // after the next step either way.
        if let Some(l) = &mut self.learner {
            l.pending = true;
        }
        Ok(())
    }

    pub fn last(&self) -> Option<(f64, f64)> {
        self.last
    }
}

/// One component's saved state in a checkpoint.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct NodeState {
    pub component: String,
    pub state: Vec<u8>,
    pub outputs: Vec<f64>,
}

fn component_error(twin: &Twin, component: &str, e: ImportError) -> WatchError {
    WatchError::Twin(TwinError::Component {
        twin: twin.describe(),
        component: component.to_owned(),
        fmu: String::new(),
        inner: Box::new(TwinError::Import(e)),
    })
}
