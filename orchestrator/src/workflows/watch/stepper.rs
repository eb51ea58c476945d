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
}

pub struct Stepper {
    nodes: Vec<Node>,
    /// The system's accelerations: (node, output port) per floor.
    acc: [(usize, usize); 3],
    coupled: bool,
    /// The last point's force and time (None before the first point of a segment).
    last: Option<(f64, f64)>,
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
                input_vrs,
                sources,
                output_vrs,
            })
            .collect();
        Ok(Stepper {
            nodes,
            acc,
            coupled,
            last: None,
        })
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
                for p in 0..self.nodes[i].sources.len() {
                    self.nodes[i].inputs[p] = match self.nodes[i].sources[p] {
                        Source::Force => force,
                        Source::Node(n, o) => self.nodes[n].outputs[o],
                    };
                }
                let node = &mut self.nodes[i];
                let instance = node.instance.as_mut().ok_or(WatchError::NotStarted)?;
                if !node.input_vrs.is_empty() {
                    instance.set_real(&node.input_vrs, &node.inputs)?;
                }
                let before = node.outputs.clone();
                instance.get_real(&node.output_vrs, &mut node.outputs)?;
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
        }
        self.last = last;
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
