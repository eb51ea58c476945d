//! The run executed: the FMUs instantiated, their ports wired (connections, bindings, system
//! inputs), the master stepped over the plan and the outputs recorded into columns.

use crate::cosim::import::{Fmu, Instance, ScalarType, ScalarVariable};
use crate::cosim::master::{
    Algorithm, NodeId, Observer, Port, Recording, RunEnd, System, TypedPort,
};

use super::model::{port_type, set_value, Model, Value};
use super::plan::Plan;
use super::{Column, RunError, RunResult};

pub(super) struct Columns {
    pub(super) ports: Vec<Port>,
    pub(super) text_ports: Vec<Port>,
    pub(super) time: Vec<f64>,
    pub(super) values: Vec<Vec<f64>>,
    pub(super) texts: Vec<Vec<String>>,
}

impl Observer for Columns {
    fn record(&mut self, time: f64, values: &[f64]) {
        self.time.push(time);
        for (column, &v) in self.values.iter_mut().zip(values) {
            column.push(v);
        }
    }
    fn ports(&self) -> &[Port] {
        &self.ports
    }
    fn text_ports(&self) -> &[Port] {
        &self.text_ports
    }
    fn record_text(&mut self, values: &[&str]) {
        for (column, v) in self.texts.iter_mut().zip(values) {
            column.push((*v).to_owned());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The run

/// Each component's ports (inputs driven by the file or by connections, outputs recorded or
/// feeding connections) and the connections between them.
pub(super) struct Ports {
    pub(super) inputs: Vec<Vec<ScalarVariable>>,
    pub(super) outputs: Vec<Vec<ScalarVariable>>,
    /// (from component, output name) → (to component, input name).
    pub(super) links: Vec<((usize, String), (usize, String))>,
}

impl Ports {
    pub(super) fn of(model: &Model, plan: &Plan) -> Result<Ports, RunError> {
        let n = model.components.len();
        let mut ports = Ports {
            inputs: vec![Vec::new(); n],
            outputs: vec![Vec::new(); n],
            links: Vec::new(),
        };
        let add = |list: &mut Vec<ScalarVariable>, v: &ScalarVariable| {
            if !list.iter().any(|x| x.name == v.name) {
                list.push(v.clone());
            }
        };
        if let Some(table) = &plan.input {
            for column in &table.columns {
                for (i, v) in &column.targets {
                    add(&mut ports.inputs[*i], v);
                }
            }
        }
        for k in &model.connections {
            if let (Some(from), Some(to)) = (&k.start_element, &k.end_element) {
                let (fi, fv) = connector(model, from, &k.start_connector)?;
                let (ti, tv) = connector(model, to, &k.end_connector)?;
                add(&mut ports.outputs[fi], &fv);
                add(&mut ports.inputs[ti], &tv);
                ports.links.push(((fi, fv.name), (ti, tv.name)));
            }
        }
        for (i, v, _) in &plan.recorded {
            add(&mut ports.outputs[*i], v);
        }
        Ok(ports)
    }

    /// Component `i`'s input `name`'s port index.
    pub(super) fn input(&self, i: usize, name: &str) -> Option<usize> {
        self.inputs[i].iter().position(|v| v.name == name)
    }

    /// Component `i`'s output `name`'s port index.
    pub(super) fn output(&self, i: usize, name: &str) -> Option<usize> {
        self.outputs[i].iter().position(|v| v.name == name)
    }
}

/// The component `element` and its variable `connector`, as a connection names them.
pub(super) fn connector(
    model: &Model,
    element: &str,
    connector: &str,
) -> Result<(usize, ScalarVariable), RunError> {
    let bad = |message: String| RunError::Model {
        path: model.path.clone(),
        message,
    };
    let i = model.component_index(element).ok_or_else(|| {
        bad(format!(
            "a connection names the component '{element}', which the system does not have"
        ))
    })?;
    let v = model.components[i].md.variable(connector).ok_or_else(|| {
        bad(format!(
            "a connection names '{element}.{connector}', which its FMU does not have"
        ))
    })?;
    Ok((i, v.clone()))
}

/// Every component's FMU loaded, instantiated and initialised (start values, then the input
/// file's values at the start); the libraries must outlive the instances.
pub(super) fn instantiate(
    model: &mut Model,
    plan: &Plan,
) -> Result<(Vec<Fmu>, Vec<Instance>), RunError> {
    let mut loaded: Vec<Fmu> = Vec::new();
    let mut instances: Vec<Instance> = Vec::new();
    for (i, c) in model.components.iter_mut().enumerate() {
        let Some(unpacked) = c.fmu.take() else {
            continue;
        };
        let fmu = unpacked.load()?;
        let mut instance = fmu.instantiate(&c.name)?;
        instance.setup_experiment(plan.start, Some(plan.stop))?;
        instance.enter_initialization_mode()?;
        for (v, value) in &plan.starts[i] {
            set_value(&mut instance, v, value)?;
        }
        if let Some(table) = &plan.input {
            for column in &table.columns {
                let (x, _) = table.value_at(column, plan.start, false);
                for (_, v) in column.targets.iter().filter(|(j, _)| *j == i) {
                    set_value(&mut instance, v, &Value::Number(x))?;
                }
            }
        }
        instance.exit_initialization_mode()?;
        loaded.push(fmu);
        instances.push(instance);
    }
    Ok((loaded, instances))
}

/// The master's system: a slave per instance with its ports, the input file's columns
/// resampled at every communication point, and the connections.
pub(super) fn wire(
    model: &Model,
    plan: &Plan,
    ports: &Ports,
    instances: Vec<Instance>,
    hold_inputs: bool,
    algorithm: Algorithm,
) -> Result<(System, Vec<NodeId>), RunError> {
    let mut system = System::new();
    system.recording = Recording::BeforeInputs;
    system.interpolate_inputs = !hold_inputs;
    system.algorithm = algorithm;
    let typed = |vars: &[ScalarVariable]| {
        vars.iter()
            .map(|v| TypedPort {
                vr: v.value_reference,
                ty: port_type(v.scalar_type),
            })
            .collect()
    };
    let mut ids: Vec<NodeId> = Vec::new();
    for (i, instance) in instances.into_iter().enumerate() {
        ids.push(system.add_typed_slave(
            &model.components[i].name,
            Box::new(instance),
            typed(&ports.inputs[i]),
            typed(&ports.outputs[i]),
        ));
    }
    if let Some(table) = &plan.input {
        for column in &table.columns {
            let samples: Vec<f64> = plan
                .times
                .iter()
                .map(|&t| table.value_at(column, t, true).0)
                .collect();
            let signal = system.add_signal(&column.name, samples);
            for (i, v) in &column.targets {
                if let Some(p) = ports.input(*i, &v.name) {
                    system.connect(signal, ids[*i], p)?;
                }
            }
        }
    }
    for ((fi, fname), (ti, tname)) in &ports.links {
        let from = ports.output(*fi, fname).unwrap_or(0);
        let to = ports.input(*ti, tname).unwrap_or(0);
        system.connect(Port::Output(ids[*fi], from), ids[*ti], to)?;
    }
    Ok((system, ids))
}

/// What a run records: the columns' names and types, the observer that keeps their values, and
/// which of them are text (recorded apart, their numbers NaN).
pub(super) struct Recorded {
    pub(super) columns: Vec<Column>,
    pub(super) recorder: Columns,
    pub(super) text_columns: Vec<usize>,
}

impl Recorded {
    pub(super) fn of(plan: &Plan, ports: &Ports, ids: &[NodeId]) -> Recorded {
        let mut columns = Vec::new();
        let mut output_ports = Vec::new();
        let mut text_ports = Vec::new();
        let mut text_columns = Vec::new();
        for (c, (i, v, name)) in plan.recorded.iter().enumerate() {
            let port = Port::Output(ids[*i], ports.output(*i, &v.name).unwrap_or(0));
            output_ports.push(port);
            if v.scalar_type == ScalarType::String {
                text_ports.push(port);
                text_columns.push(c);
            }
            columns.push(Column {
                name: name.clone(),
                scalar_type: v.scalar_type,
            });
        }
        Recorded {
            columns,
            recorder: Columns {
                values: vec![Vec::new(); output_ports.len()],
                texts: vec![Vec::new(); text_ports.len()],
                ports: output_ports,
                text_ports,
                time: Vec::new(),
            },
            text_columns,
        }
    }

    /// The run's result once the system has run to `end`.
    pub(super) fn result(self, plan: &Plan, end: RunEnd) -> RunResult {
        let mut values = self.recorder.values;
        for &c in &self.text_columns {
            values[c].iter_mut().for_each(|x| *x = f64::NAN);
        }
        RunResult {
            columns: self.columns,
            time: self.recorder.time,
            values,
            texts: self
                .text_columns
                .into_iter()
                .zip(self.recorder.texts)
                .collect(),
            start: plan.start,
            stop: plan.stop,
            step: plan.step,
            terminated: match end {
                RunEnd::Completed => None,
                RunEnd::Terminated { at, node } => Some((node, at)),
            },
        }
    }
}

/// Run the planned model: its ports, its FMUs initialised, the system wired, run and recorded.
pub(super) fn execute(
    mut model: Model,
    plan: Plan,
    hold_inputs: bool,
    algorithm: Algorithm,
    progress: impl FnMut(u64, u64),
) -> Result<RunResult, RunError> {
    let ports = Ports::of(&model, &plan)?;
    let (loaded, instances) = instantiate(&mut model, &plan)?;
    let (mut system, ids) = wire(&model, &plan, &ports, instances, hold_inputs, algorithm)?;
    let mut recorded = Recorded::of(&plan, &ports, &ids);
    let end = system.run_at(&plan.times, &mut [&mut recorded.recorder], progress)?;
    // The instances go before the libraries they came from.
    drop(system);
    drop(loaded);
    Ok(recorded.result(&plan, end))
}
