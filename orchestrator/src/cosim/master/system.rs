//! Nodes, connections and the stepping loop.

use super::{Block, Clock, MasterError, NodeId, Observer, Port, Slave};
use crate::cosim::import::StepEnd;

/// The FMI type a slave's port carries. Enumerations travel as `Integer`, as FMI 2.0 gets and
/// sets them. Real, Integer and Boolean values move through the master as `f64` (exact for
/// every `i32` and for 0/1); String values beside them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PortType {
    #[default]
    Real,
    Integer,
    Boolean,
    String,
}

const PORT_TYPES: [PortType; 4] = [
    PortType::Real,
    PortType::Integer,
    PortType::Boolean,
    PortType::String,
];

/// One port of a slave: the value reference and its type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypedPort {
    pub vr: u32,
    pub ty: PortType,
}

impl TypedPort {
    pub fn real(vr: u32) -> Self {
        TypedPort {
            vr,
            ty: PortType::Real,
        }
    }
}

/// How the master steps the slaves within a communication step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Algorithm {
    #[default]
    GaussSeidel,
    Jacobi,
}

impl crate::choice::Choice for Algorithm {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        (
            "gauss-seidel",
            "each component sees what the ones before it produced at this point",
            Algorithm::GaussSeidel,
        ),
        (
            "jacobi",
            "every component reads the outputs as the last step left them",
            Algorithm::Jacobi,
        ),
    ];
}

crate::choice::display_by_name!(Algorithm);

/// When observers see a communication point `t_k` (k ≥ 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Recording {
    /// After the point's inputs are applied and the outputs evaluated (the twin's
    /// convention: a feedthrough output reflects the input measured at `t_k`).
    #[default]
    AfterInputs,
    /// As the step left the slaves, before the point's inputs are applied: fmpy's
    /// `simulate_fmu` convention (SPEC §5). Point 0 is recorded after the inputs either way.
    BeforeInputs,
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub enum RunEnd {
    /// Every step of the clock was taken.
    Completed,
    /// A slave ended the simulation itself at `at` (recorded as the last point).
    Terminated { at: f64, node: String },
}

/// A slave's ports of one type: their indices among the slave's ports and value references.
#[derive(Default)]
struct Group {
    ports: Vec<usize>,
    vrs: Vec<u32>,
}

// A slave carries its port groups inline: there are a handful of nodes, and the stepping loop
// reads them at every point.
#[allow(clippy::large_enum_variant)]
enum Kind {
    Slave {
        slave: Box<dyn Slave>,
        input_vrs: Vec<u32>,
        input_types: Vec<PortType>,
        /// Output ports by type (fixed at `add`).
        output_groups: [Group; 4],
        /// Connected input ports by type (fixed when the run starts).
        input_groups: [Group; 4],
    },
    Block(Box<dyn Block>),
}

struct Node {
    name: String,
    kind: Kind,
    /// Per input port: where its value comes from (None: left at the FMU's own value).
    sources: Vec<Option<Port>>,
    /// Per input port: whether it is sampled (see [`System::connect_sampled`]).
    sampled: Vec<bool>,
    /// The outputs as the last step left them, before the point's inputs were applied (kept
    /// only when some sampled connection reads this node).
    held: Vec<f64>,
    inputs: Vec<f64>,
    outputs: Vec<f64>,
    /// String values, per port (empty for the other types).
    text_inputs: Vec<String>,
    text_outputs: Vec<String>,
    /// The outputs before an evaluation (to tell whether it changed them).
    previous: Vec<f64>,
    /// Whether a String input is connected (fixed when the run starts).
    text_inputs_connected: bool,
    /// Whether the slave takes input slopes and has a connected Real input (fixed when the
    /// run starts).
    interpolated: bool,
    /// Scratch for typed get/set.
    ints: Vec<i32>,
    bools: Vec<bool>,
    reals: Vec<f64>,
}

fn groups(ports: &[TypedPort], keep: impl Fn(usize) -> bool) -> [Group; 4] {
    let mut out: [Group; 4] = Default::default();
    for (i, p) in ports.iter().enumerate() {
        if keep(i) {
            let g = &mut out[PORT_TYPES.iter().position(|t| *t == p.ty).unwrap_or(0)];
            g.ports.push(i);
            g.vrs.push(p.vr);
        }
    }
    out
}

impl Node {
    /// Read every output of a slave into `outputs` / `text_outputs`.
    fn read_outputs(&mut self) -> Result<(), MasterError> {
        let Kind::Slave {
            slave,
            output_groups,
            ..
        } = &mut self.kind
        else {
            return Ok(());
        };
        let [real, int, boolean, text] = output_groups;
        if !real.vrs.is_empty() {
            if real.ports.len() == self.outputs.len() {
                // All outputs Real, in port order: read in place.
                slave.get_real(&real.vrs, &mut self.outputs)?;
            } else {
                self.reals.resize(real.vrs.len(), 0.0);
                slave.get_real(&real.vrs, &mut self.reals)?;
                for (&p, &v) in real.ports.iter().zip(&self.reals) {
                    self.outputs[p] = v;
                }
            }
        }
        if !int.vrs.is_empty() {
            self.ints.resize(int.vrs.len(), 0);
            slave.get_integer(&int.vrs, &mut self.ints)?;
            for (&p, &v) in int.ports.iter().zip(&self.ints) {
                self.outputs[p] = f64::from(v);
            }
        }
        if !boolean.vrs.is_empty() {
            self.bools.resize(boolean.vrs.len(), false);
            slave.get_boolean(&boolean.vrs, &mut self.bools)?;
            for (&p, &v) in boolean.ports.iter().zip(&self.bools) {
                self.outputs[p] = if v { 1.0 } else { 0.0 };
            }
        }
        if !text.vrs.is_empty() {
            let values = slave.get_string(&text.vrs)?;
            for (&p, v) in text.ports.iter().zip(values) {
                self.text_outputs[p] = v;
            }
        }
        Ok(())
    }

    /// Set a slave's connected inputs from `inputs` / `text_inputs`.
    fn write_inputs(&mut self) -> Result<(), MasterError> {
        let Kind::Slave {
            slave,
            input_groups,
            ..
        } = &mut self.kind
        else {
            return Ok(());
        };
        let [real, int, boolean, text] = input_groups;
        if !real.vrs.is_empty() {
            self.reals.clear();
            self.reals
                .extend(real.ports.iter().map(|&p| self.inputs[p]));
            slave.set_real(&real.vrs, &self.reals)?;
        }
        if !int.vrs.is_empty() {
            self.ints.clear();
            for &p in &int.ports {
                self.ints
                    .push(integer_value(self.inputs[p], &self.name, p)?);
            }
            slave.set_integer(&int.vrs, &self.ints)?;
        }
        if !boolean.vrs.is_empty() {
            self.bools.clear();
            self.bools
                .extend(boolean.ports.iter().map(|&p| self.inputs[p] != 0.0));
            slave.set_boolean(&boolean.vrs, &self.bools)?;
        }
        if !text.vrs.is_empty() {
            let values: Vec<&str> = text
                .ports
                .iter()
                .map(|&p| self.text_inputs[p].as_str())
                .collect();
            slave.set_string(&text.vrs, &values)?;
        }
        Ok(())
    }
}

/// An Integer input's value: refused unless it is a whole number in `i32`'s range.
fn integer_value(v: f64, node: &str, port: usize) -> Result<i32, MasterError> {
    if v.fract() == 0.0 && v >= f64::from(i32::MIN) && v <= f64::from(i32::MAX) {
        Ok(v as i32)
    } else {
        Err(MasterError::Config(format!(
            "input {port} of '{node}' is an Integer but receives {v}"
        )))
    }
}

/// A signal fed into the system from outside: replayed samples (one per communication point of a
/// run), or values given point by point ([`System::set_input`]).
struct Signal {
    name: String,
    samples: Vec<f64>,
    /// The value at the current communication point …
    now: f64,
    /// … and at the next one (the slope over the step is `(next − now) / h`).
    next: f64,
}

/// A system's state between two communication steps: every slave's own state, every node's
/// outputs, the signals' values and the time of the current point. See [`System::save`].
#[derive(Debug, Clone, PartialEq)]
pub struct SavedState {
    pub time: f64,
    pub signals: Vec<f64>,
    pub nodes: Vec<SavedNode>,
}

/// One slave's part of a [`SavedState`].
#[derive(Debug, Clone, PartialEq)]
pub struct SavedNode {
    pub name: String,
    pub state: Vec<u8>,
    pub outputs: Vec<f64>,
}

/// A co-simulation system. Build it, then `run` it over a clock, or step it one communication
/// point at a time: [`System::set_input`] → [`System::initialize`] (the first point) or
/// [`System::step`] (each next one) → [`System::value`]. `run` is written on the same steps.
pub struct System {
    nodes: Vec<Node>,
    signals: Vec<Signal>,
    pub algorithm: Algorithm,
    pub recording: Recording,
    /// Send input slopes to the slaves that can interpolate inputs (default); off, every input
    /// is held over the step, as by a host that never calls `fmi2SetRealInputDerivatives`.
    pub interpolate_inputs: bool,
    /// Whether some node's input comes from another node's output (fixed when the run starts).
    coupled: bool,
    /// Whether some connection is sampled (fixed when the run starts).
    sampling: bool,
    /// The current communication point's time, once the system is stepping.
    time: Option<f64>,
}

impl Default for System {
    fn default() -> Self {
        Self::new()
    }
}

impl System {
    pub fn new() -> Self {
        System {
            nodes: Vec::new(),
            signals: Vec::new(),
            algorithm: Algorithm::default(),
            recording: Recording::default(),
            interpolate_inputs: true,
            coupled: false,
            sampling: false,
            time: None,
        }
    }

    /// Add a slave whose input ports are `input_vrs` and output ports `output_vrs` (value
    /// references of Real variables). Nodes are evaluated in the order they are added.
    pub fn add_slave(
        &mut self,
        name: &str,
        slave: Box<dyn Slave>,
        input_vrs: Vec<u32>,
        output_vrs: Vec<u32>,
    ) -> NodeId {
        let inputs = input_vrs.into_iter().map(TypedPort::real).collect();
        let outputs = output_vrs.into_iter().map(TypedPort::real).collect();
        self.add_typed_slave(name, slave, inputs, outputs)
    }

    /// Add a slave with ports of any FMI type.
    pub fn add_typed_slave(
        &mut self,
        name: &str,
        slave: Box<dyn Slave>,
        inputs: Vec<TypedPort>,
        outputs: Vec<TypedPort>,
    ) -> NodeId {
        let (n_in, n_out) = (inputs.len(), outputs.len());
        let kind = Kind::Slave {
            slave,
            input_vrs: inputs.iter().map(|p| p.vr).collect(),
            input_types: inputs.iter().map(|p| p.ty).collect(),
            output_groups: groups(&outputs, |_| true),
            input_groups: Default::default(),
        };
        self.push(name, kind, n_in, n_out)
    }

    pub fn add_block(
        &mut self,
        name: &str,
        block: Box<dyn Block>,
        n_inputs: usize,
        n_outputs: usize,
    ) -> NodeId {
        self.push(name, Kind::Block(block), n_inputs, n_outputs)
    }

    fn push(&mut self, name: &str, kind: Kind, n_in: usize, n_out: usize) -> NodeId {
        self.nodes.push(Node {
            name: name.to_owned(),
            kind,
            sources: vec![None; n_in],
            sampled: vec![false; n_in],
            held: vec![0.0; n_out],
            inputs: vec![0.0; n_in],
            outputs: vec![0.0; n_out],
            text_inputs: vec![String::new(); n_in],
            text_outputs: vec![String::new(); n_out],
            previous: Vec::with_capacity(n_out),
            text_inputs_connected: false,
            interpolated: false,
            ints: Vec::new(),
            bools: Vec::new(),
            reals: Vec::new(),
        });
        NodeId(self.nodes.len() - 1)
    }

    /// A measured signal replayed as an input: `samples[k]` at `t_k`, linear in between. A
    /// system stepped point by point takes its values from [`System::set_input`] instead (give
    /// no samples).
    pub fn add_signal(&mut self, name: &str, samples: Vec<f64>) -> Port {
        self.signals.push(Signal {
            name: name.to_owned(),
            samples,
            now: 0.0,
            next: 0.0,
        });
        Port::Signal(self.signals.len() - 1)
    }

    fn output_type(&self, port: Port) -> PortType {
        match port {
            Port::Output(NodeId(n), p) => match &self.nodes[n].kind {
                Kind::Slave { output_groups, .. } => PORT_TYPES
                    .into_iter()
                    .zip(output_groups.iter())
                    .find(|(_, g)| g.ports.contains(&p))
                    .map_or(PortType::Real, |(t, _)| t),
                Kind::Block(_) => PortType::Real,
            },
            Port::Signal(_) => PortType::Real,
        }
    }

    pub fn connect(&mut self, from: Port, to: NodeId, input: usize) -> Result<(), MasterError> {
        match from {
            Port::Output(NodeId(n), p)
                if n >= self.nodes.len() || p >= self.nodes[n].outputs.len() =>
            {
                return Err(MasterError::Config(format!(
                    "no output port {p} on node {n}"
                )))
            }
            Port::Signal(s) if s >= self.signals.len() => {
                return Err(MasterError::Config(format!("no signal {s}")))
            }
            _ => {}
        }
        let from_type = self.output_type(from);
        let node = self
            .nodes
            .get_mut(to.0)
            .ok_or_else(|| MasterError::Config(format!("no node {}", to.0)))?;
        let name = node.name.clone();
        let to_type = match &node.kind {
            Kind::Slave { input_types, .. } => input_types.get(input).copied(),
            Kind::Block(_) => Some(PortType::Real),
        }
        .unwrap_or_default();
        if (from_type == PortType::String) != (to_type == PortType::String) {
            return Err(MasterError::Config(format!(
                "input {input} of '{name}' is {to_type:?} but its source is {from_type:?}"
            )));
        }
        let slot = node.sources.get_mut(input).ok_or_else(|| {
            MasterError::Config(format!("node '{name}' has no input port {input}"))
        })?;
        if slot.is_some() {
            return Err(MasterError::Config(format!(
                "input {input} of '{name}' is already connected"
            )));
        }
        *slot = Some(from);
        Ok(())
    }

    /// Connect as a sampled-data controller reads its sensors: `to`'s input takes `from`'s
    /// value as the last step left it, before the communication point's inputs are applied
    /// (at `t_0`: after initialisation, before any input is set). Inside a point the value is
    /// constant, so a loop through a feedthrough output (a measured acceleration fed back as
    /// a control force) closes without an algebraic loop: what a digital controller does when
    /// it samples, computes and then holds its output over the next step.
    pub fn connect_sampled(
        &mut self,
        from: Port,
        to: NodeId,
        input: usize,
    ) -> Result<(), MasterError> {
        if !matches!(from, Port::Output(..)) {
            return Err(MasterError::Config(
                "only a node's output can be sampled (a replayed signal already is)".into(),
            ));
        }
        self.connect(from, to, input)?;
        self.nodes[to.0].sampled[input] = true;
        Ok(())
    }

    pub fn node_name(&self, id: NodeId) -> &str {
        &self.nodes[id.0].name
    }

    /// A port's value at the current communication point: a node's output as the point's
    /// evaluation left it, or a signal's value there.
    pub fn value(&self, port: Port) -> f64 {
        match port {
            Port::Output(NodeId(n), p) => self.nodes[n].outputs[p],
            Port::Signal(s) => self.signals[s].now,
        }
    }

    /// A sampled connection's value: the source's outputs as the last step left them.
    fn held_value(&self, port: Port) -> f64 {
        match port {
            Port::Output(NodeId(n), p) => self.nodes[n].held[p],
            Port::Signal(_) => self.value(port),
        }
    }

    /// Before a point's inputs are applied: read every slave's outputs and keep every node's
    /// outputs for the sampled connections.
    fn hold_outputs(&mut self) -> Result<(), MasterError> {
        for node in &mut self.nodes {
            node.read_outputs()?;
            node.held.clear();
            node.held.extend_from_slice(&node.outputs);
        }
        Ok(())
    }

    fn text(&self, port: Port) -> &str {
        match port {
            Port::Output(NodeId(n), p) => &self.nodes[n].text_outputs[p],
            Port::Signal(_) => "",
        }
    }

    /// Set node `i`'s inputs from `inputs` and compute its outputs at `time`.
    fn evaluate_node(&mut self, i: usize, time: f64) -> Result<bool, MasterError> {
        let node = &mut self.nodes[i];
        node.previous.clear();
        node.previous.extend_from_slice(&node.outputs);
        let has_text = matches!(&node.kind,
            Kind::Slave { output_groups, .. } if !output_groups[3].vrs.is_empty());
        let texts_before = has_text.then(|| node.text_outputs.clone());
        match &mut node.kind {
            Kind::Slave { .. } => {
                node.write_inputs()?;
                node.read_outputs()?;
            }
            Kind::Block(block) => block
                .evaluate(time, &node.inputs, &mut node.outputs)
                .map_err(|e| match e {
                    MasterError::Block { .. } => e,
                    other => MasterError::Block {
                        block: node.name.clone(),
                        message: other.to_string(),
                    },
                })?,
        }
        let texts_changed = texts_before.is_some_and(|t| t != node.text_outputs);
        Ok(texts_changed
            || node
                .outputs
                .iter()
                .zip(&node.previous)
                .any(|(a, b)| a.to_bits() != b.to_bits()))
    }

    /// Copy node `i`'s connected inputs; true if any changed.
    fn gather_inputs(&mut self, i: usize) -> bool {
        let mut changed = false;
        for p in 0..self.nodes[i].sources.len() {
            if let Some(port) = self.nodes[i].sources[p] {
                let v = if self.nodes[i].sampled[p] {
                    self.held_value(port)
                } else {
                    self.value(port)
                };
                changed |= self.nodes[i].inputs[p].to_bits() != v.to_bits();
                self.nodes[i].inputs[p] = v;
                let is_text = self.nodes[i].text_inputs_connected
                    && matches!(&self.nodes[i].kind,
                        Kind::Slave { input_types, .. } if input_types[p] == PortType::String);
                if is_text && self.text(port) != self.nodes[i].text_inputs[p] {
                    self.nodes[i].text_inputs[p] = self.text(port).to_owned();
                    changed = true;
                }
            }
        }
        changed
    }
    /// Zero-time evaluation of every node at the current communication point.
    fn propagate(&mut self, time: f64) -> Result<(), MasterError> {
        match self.algorithm {
            Algorithm::GaussSeidel => {
                // Each pass can settle one more link of a chain through non-feedthrough outputs;
                // more passes than nodes means an algebraic loop that does not converge.
                for pass in 0..=self.nodes.len() + 1 {
                    let mut changed = false;
                    for i in 0..self.nodes.len() {
                        // Outputs are functions of the inputs at a fixed point in time: a node
                        // whose inputs did not move since the last pass needs no new call.
                        let inputs_moved = self.gather_inputs(i);
                        if pass == 0 || inputs_moved {
                            changed |= self.evaluate_node(i, time)?;
                        }
                    }
                    // Without node-to-node connections one pass sets every input there is.
                    if !changed || !self.coupled {
                        return Ok(());
                    }
                }
                Err(MasterError::Config(
                    "outputs do not settle at a communication point: an algebraic loop?".into(),
                ))
            }
            Algorithm::Jacobi => {
                for i in 0..self.nodes.len() {
                    self.gather_inputs(i);
                }
                for i in 0..self.nodes.len() {
                    self.evaluate_node(i, time)?;
                }
                Ok(())
            }
        }
    }

    /// Input slopes over the step for slaves that interpolate: the signals' segments from this
    /// point's value to the next's. Values coming from other nodes are held (slope 0).
    fn set_input_derivatives(&mut self, step: f64) -> Result<(), MasterError> {
        // Only Real inputs are interpolated (the connected ones: `input_groups[0]`); the
        // others are held.
        let signals = &self.signals;
        for node in self.nodes.iter_mut().filter(|n| n.interpolated) {
            let Kind::Slave {
                slave,
                input_groups,
                ..
            } = &mut node.kind
            else {
                continue;
            };
            let real = &input_groups[0];
            node.reals.clear();
            for &p in &real.ports {
                node.reals.push(match node.sources[p] {
                    Some(Port::Signal(s)) => (signals[s].next - signals[s].now) / step,
                    _ => 0.0,
                });
            }
            slave.set_real_input_derivatives(&real.vrs, &node.reals)?;
        }
        Ok(())
    }

    /// Run over `clock`, recording into `observers` at every point `t_0 … t_steps`.
    /// `progress` is called after each step with (k, steps).
    pub fn run(
        &mut self,
        clock: Clock,
        observers: &mut [&mut dyn Observer],
        progress: impl FnMut(u64, u64),
    ) -> Result<RunEnd, MasterError> {
        self.run_points(clock.steps, |k| clock.time(k), observers, progress)
    }

    /// Run through the communication points `times` (increasing; signals have one sample per
    /// point), for schedules that are not uniform (input events).
    pub fn run_at(
        &mut self,
        times: &[f64],
        observers: &mut [&mut dyn Observer],
        progress: impl FnMut(u64, u64),
    ) -> Result<RunEnd, MasterError> {
        if times.is_empty()
            || times
                .windows(2)
                .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
        {
            return Err(MasterError::Config(
                "the communication points must be at least one, strictly increasing".into(),
            ));
        }
        self.run_points(
            (times.len() - 1) as u64,
            |k| times[k as usize],
            observers,
            progress,
        )
    }

    /// Every signal has a sample for each of the run's `steps + 1` points.
    fn check_samples(&self, steps: u64) -> Result<(), MasterError> {
        for signal in &self.signals {
            if (signal.samples.len() as u64) < steps + 1 {
                return Err(MasterError::Config(format!(
                    "signal '{}' has {} samples; {} communication points need {}",
                    signal.name,
                    signal.samples.len(),
                    steps + 1,
                    steps + 1
                )));
            }
        }
        Ok(())
    }

    /// Fix what the wiring implies before the first point: which nodes feed others, which
    /// connections are sampled, each slave's connected ports by type, who takes input slopes.
    fn check_wiring(&mut self) -> Result<(), MasterError> {
        self.coupled = self.nodes.iter().any(|n| {
            n.sources
                .iter()
                .any(|s| matches!(s, Some(Port::Output(..))))
        });
        self.sampling = self.nodes.iter().any(|n| n.sampled.contains(&true));
        let interpolate = self.interpolate_inputs;
        for (i, node) in self.nodes.iter_mut().enumerate() {
            if let Some(p) = node.sources.iter().position(Option::is_none) {
                if matches!(node.kind, Kind::Block(_)) {
                    return Err(MasterError::Config(format!(
                        "input {p} of block '{}' (node {i}) is not connected",
                        node.name
                    )));
                }
            }
            let sources = &node.sources;
            if let Kind::Slave {
                slave,
                input_vrs,
                input_types,
                input_groups,
                ..
            } = &mut node.kind
            {
                let ports: Vec<TypedPort> = input_vrs
                    .iter()
                    .zip(input_types.iter())
                    .map(|(&vr, &ty)| TypedPort { vr, ty })
                    .collect();
                *input_groups = groups(&ports, |p| sources[p].is_some());
                node.text_inputs_connected = !input_groups[3].vrs.is_empty();
                node.interpolated = interpolate
                    && !input_groups[0].vrs.is_empty()
                    && slave.can_interpolate_inputs();
            }
        }
        Ok(())
    }

    fn observe(&self, observers: &mut [&mut dyn Observer], time: f64, buffer: &mut Vec<f64>) {
        for observer in observers.iter_mut() {
            buffer.clear();
            buffer.extend(observer.ports().iter().map(|&p| self.value(p)));
            observer.record(time, buffer);
            if !observer.text_ports().is_empty() {
                let texts: Vec<&str> = observer
                    .text_ports()
                    .iter()
                    .map(|&p| self.text(p))
                    .collect();
                observer.record_text(&texts);
            }
        }
    }

    // -----------------------------------------------------------------------------------------
    // Stepping: one communication point at a time. `run` is these same calls in a loop.

    /// The value `signal` takes at the next communication point: the one [`System::initialize`]
    /// or [`System::step`] goes to. Between the current point and that one the signal is linear
    /// (its slope goes to the slaves that interpolate inputs).
    pub fn set_input(&mut self, signal: Port, value: f64) -> Result<(), MasterError> {
        match signal {
            Port::Signal(s) if s < self.signals.len() => {
                self.signals[s].next = value;
                Ok(())
            }
            other => Err(MasterError::Config(format!(
                "{other:?} is not one of the system's signals"
            ))),
        }
    }

    /// Start stepping at the first communication point `time`: the wiring fixed, the signals
    /// at the values [`System::set_input`] gave, every node evaluated there. The slaves must
    /// be initialised (out of initialisation mode) at `time`.
    pub fn initialize(&mut self, time: f64) -> Result<(), MasterError> {
        self.check_wiring()?;
        self.enter_first_point(time).map_err(at_time(time))
    }

    /// One communication step from the current point to `to`: input slopes to the signals'
    /// next values, every slave stepped, then every node evaluated at `to` with those values.
    /// A slave that ends the simulation itself stops the step there (`StepEnd::Terminated`:
    /// the outputs as the step left them; the system does not step again).
    pub fn step(&mut self, to: f64) -> Result<StepEnd, MasterError> {
        let from = self.time.ok_or_else(|| {
            MasterError::Config("the system was stepped before it was initialised".into())
        })?;
        if let Some((end, _)) = self.step_slaves(to).map_err(at_time(from))? {
            self.read_all_outputs().map_err(at_time(end))?;
            self.time = None;
            return Ok(StepEnd::Terminated { at: end });
        }
        if self.sampling {
            self.hold_outputs().map_err(at_time(to))?;
        }
        self.propagate(to).map_err(at_time(to))?;
        Ok(StepEnd::Completed)
    }

    /// The current communication point's time (None before [`System::initialize`]).
    pub fn time(&self) -> Option<f64> {
        self.time
    }

    /// A node's slave, for what the wiring does not carry (a learning flag, a status output).
    /// None for a block.
    pub fn slave_mut(&mut self, node: NodeId) -> Option<&mut dyn Slave> {
        match &mut self.nodes.get_mut(node.0)?.kind {
            Kind::Slave { slave, .. } => Some(slave.as_mut()),
            Kind::Block(_) => None,
        }
    }

    /// The nodes' names, in the order they were added.
    pub fn node_names(&self) -> impl Iterator<Item = &str> {
        self.nodes.iter().map(|n| n.name.as_str())
    }

    /// The system's state at the current point: what [`System::restore`] needs to go on from
    /// here exactly. Refused when a node is a block (its state is its own) or a slave cannot
    /// save its state.
    pub fn save(&mut self) -> Result<SavedState, MasterError> {
        let time = self.time.ok_or_else(|| {
            MasterError::Config("the system was saved before it was initialised".into())
        })?;
        let mut nodes = Vec::with_capacity(self.nodes.len());
        for node in &mut self.nodes {
            let Kind::Slave { slave, .. } = &mut node.kind else {
                return Err(MasterError::Block {
                    block: node.name.clone(),
                    message: "a block's state cannot be saved".into(),
                });
            };
            nodes.push(SavedNode {
                name: node.name.clone(),
                state: slave.save_state()?,
                outputs: node.outputs.clone(),
            });
        }
        Ok(SavedState {
            time,
            signals: self.signals.iter().map(|s| s.now).collect(),
            nodes,
        })
    }

    /// Go on from a state [`System::save`] gave, on a system wired the same way (its slaves
    /// initialised): the next call is [`System::step`].
    pub fn restore(&mut self, saved: &SavedState) -> Result<(), MasterError> {
        if saved.nodes.len() != self.nodes.len() || saved.signals.len() != self.signals.len() {
            return Err(MasterError::Config(format!(
                "the saved state has {} nodes and {} signals, the system {} and {}",
                saved.nodes.len(),
                saved.signals.len(),
                self.nodes.len(),
                self.signals.len()
            )));
        }
        self.check_wiring()?;
        for (node, s) in self.nodes.iter_mut().zip(&saved.nodes) {
            if s.name != node.name || s.outputs.len() != node.outputs.len() {
                return Err(MasterError::Config(format!(
                    "the saved state is for node '{}' with {} outputs, the system's is '{}' \
                     with {}",
                    s.name,
                    s.outputs.len(),
                    node.name,
                    node.outputs.len()
                )));
            }
            let Kind::Slave { slave, .. } = &mut node.kind else {
                return Err(MasterError::Block {
                    block: node.name.clone(),
                    message: "a block's state cannot be restored".into(),
                });
            };
            slave.restore_state(&s.state)?;
            node.outputs.clone_from(&s.outputs);
        }
        for (signal, &v) in self.signals.iter_mut().zip(&saved.signals) {
            signal.now = v;
            signal.next = v;
        }
        self.time = Some(saved.time);
        Ok(())
    }

    /// The first point: the signals take their set values, every node is evaluated.
    fn enter_first_point(&mut self, time: f64) -> Result<(), MasterError> {
        for signal in &mut self.signals {
            signal.now = signal.next;
        }
        self.time = Some(time);
        if self.sampling {
            self.hold_outputs()?;
        }
        self.propagate(time)
    }

    /// Every slave stepped from the current point to `to`, the signals' slopes given first
    /// and their values moved on to `to`'s. Some((end, node)) when a slave ended the
    /// simulation at `end`.
    fn step_slaves(&mut self, to: f64) -> Result<Option<(f64, usize)>, MasterError> {
        let time = self.time.unwrap_or(to);
        let step = to - time;
        self.set_input_derivatives(step)?;
        for signal in &mut self.signals {
            signal.now = signal.next;
        }
        self.time = Some(to);
        for i in 0..self.nodes.len() {
            let Kind::Slave { slave, .. } = &mut self.nodes[i].kind else {
                continue;
            };
            if let StepEnd::Terminated { at } = slave.step(time, step)? {
                self.time = Some(at);
                return Ok(Some((at, i)));
            }
        }
        Ok(None)
    }

    fn read_all_outputs(&mut self) -> Result<(), MasterError> {
        for node in &mut self.nodes {
            node.read_outputs()?;
        }
        Ok(())
    }

    fn run_points(
        &mut self,
        steps: u64,
        time_of: impl Fn(u64) -> f64,
        observers: &mut [&mut dyn Observer],
        mut progress: impl FnMut(u64, u64),
    ) -> Result<RunEnd, MasterError> {
        self.check_samples(steps)?;
        self.check_wiring()?;
        for observer in observers.iter_mut() {
            observer.will_record(steps as usize + 1);
        }
        let mut buffer = Vec::new();
        let first = time_of(0);
        for signal in &mut self.signals {
            signal.next = signal.samples[0];
        }
        self.enter_first_point(first).map_err(at_time(first))?;
        self.observe(observers, first, &mut buffer);
        for k in 1..=steps {
            let (from, time) = (time_of(k - 1), time_of(k));
            for signal in &mut self.signals {
                signal.next = signal.samples[k as usize];
            }
            if let Some((end, i)) = self.step_slaves(time).map_err(at_time(from))? {
                // The slave's last successful time is the run's last point, recorded as the
                // step left it.
                self.read_all_outputs().map_err(at_time(end))?;
                self.observe(observers, end, &mut buffer);
                self.time = None;
                return Ok(RunEnd::Terminated {
                    at: end,
                    node: self.nodes[i].name.clone(),
                });
            }
            progress(k, steps);
            if self.sampling {
                self.hold_outputs().map_err(at_time(time))?;
            }
            if self.recording == Recording::BeforeInputs {
                if !self.sampling {
                    self.read_all_outputs().map_err(at_time(time))?;
                }
                self.observe(observers, time, &mut buffer);
                self.propagate(time).map_err(at_time(time))?;
            } else {
                self.propagate(time).map_err(at_time(time))?;
                self.observe(observers, time, &mut buffer);
            }
        }
        Ok(RunEnd::Completed)
    }
}

/// An error at a communication point says which.
fn at_time(time: f64) -> impl Fn(MasterError) -> MasterError {
    move |e| MasterError::AtTime {
        time,
        inner: Box::new(e),
    }
}

#[cfg(test)]
mod tests;
