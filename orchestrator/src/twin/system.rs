//! The one place the twin's SSP archive becomes a running `master::System`: its components'
//! FMUs opened once ([`SystemBuilder::open`]), instantiated at a start time with the twin's
//! parameters, added as slaves with the ports their connections use and connected as the SSP
//! says ([`SystemBuilder::build`]), or added one by one with the ports a caller names (the
//! control loop's physics and corrector, [`SystemBuilder::add_component`]). The system inputs a
//! caller drives (the measured force, a replayed control force) become the system's signals:
//! replayed from samples by `System::run`, or set point by point with `System::set_input`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::cosim::import::{Fmu, Instance};
use crate::cosim::master::{Decimated, MasterError, NodeId, Port, Slave, System};
use crate::twin::{apply_parameters, strip_temporary_path, ParameterValue, Twin, TwinError};

#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error("twin: {0}")]
    Wiring(String),
}

/// One component's FMU, opened, and the parameters its instances get.
struct Loaded {
    name: String,
    fmu_name: String,
    /// The `.fmu` the twin names (taken out of error messages).
    fmu_path: PathBuf,
    fmu: Arc<Fmu>,
    parameters: BTreeMap<String, ParameterValue>,
}

/// The twin's FMUs, opened once; every system built from them gets fresh instances. It holds
/// its own copy of the twin (a duplicate shares the unpacked FMUs), so that what it builds can
/// outlive the twin it was opened from (a watch that adopts another twin).
pub struct SystemBuilder {
    twin: Twin,
    components: Vec<Loaded>,
}

impl SystemBuilder {
    /// Open every component's FMU (an error names the twin and the component).
    pub fn open(twin: &Twin) -> Result<Self, TwinError> {
        let components = twin
            .components
            .iter()
            .map(|c| {
                let fmu = Fmu::open(&c.fmu_path).map_err(|e| TwinError::Component {
                    twin: twin.describe(),
                    component: c.name.clone(),
                    fmu: format!("resources/{}", c.fmu_name),
                    inner: Box::new(strip_temporary_path(e.into(), &c.fmu_path)),
                })?;
                Ok(Loaded {
                    name: c.name.clone(),
                    fmu_name: c.fmu_name.clone(),
                    fmu_path: c.fmu_path.clone(),
                    fmu: Arc::new(fmu),
                    parameters: c.parameters.clone(),
                })
            })
            .collect::<Result<Vec<_>, TwinError>>()?;
        Ok(SystemBuilder {
            twin: twin.duplicate(),
            components,
        })
    }

    pub fn twin(&self) -> &Twin {
        &self.twin
    }

    fn loaded(&self, component: &str) -> Option<&Loaded> {
        self.components.iter().find(|c| c.name == component)
    }

    /// A component's FMU (its value references, its model description).
    pub fn fmu(&self, component: &str) -> Option<&Fmu> {
        self.loaded(component).map(|c| c.fmu.as_ref())
    }

    /// Give a component's instances `name = value` from now on, over the twin's own value;
    /// false when the twin has no such component or its FMU no such variable.
    pub fn set_parameter(&mut self, component: &str, name: &str, value: ParameterValue) -> bool {
        let Some(c) = self.components.iter_mut().find(|c| c.name == component) else {
            return false;
        };
        if c.fmu.value_reference(name).is_err() {
            return false;
        }
        c.parameters.insert(name.to_owned(), value);
        true
    }

    /// A new instance of `component`, initialised at `start` with its parameters.
    pub fn instantiate(&self, component: &str, start: f64) -> Result<Instance, TwinError> {
        let c = self.loaded(component).ok_or_else(|| {
            TwinError::Message(format!(
                "{} has no component '{component}'",
                self.twin.describe()
            ))
        })?;
        let open = || -> Result<Instance, TwinError> {
            let mut instance = c.fmu.instantiate(&c.name)?;
            initialise(&c.fmu, &mut instance, start, &c.parameters, |_| Ok(()))?;
            Ok(instance)
        };
        // Name the twin and the component, not the temporary directory the FMU sits in.
        open().map_err(|e| TwinError::Component {
            twin: self.twin.describe(),
            component: c.name.clone(),
            fmu: format!("resources/{}", c.fmu_name),
            inner: Box::new(strip_temporary_path(e, &c.fmu_path)),
        })
    }

    /// A system with no node yet, for [`SystemBuilder::add_component`].
    pub fn empty(&self) -> TwinSystem {
        TwinSystem {
            system: System::new(),
            nodes: Vec::new(),
            signals: Vec::new(),
            fmus: Vec::new(),
        }
    }

    /// Add `component`, instantiated at `start`, to `system` as a slave whose input and output
    /// ports are the named variables; with `every` Some(n) it keeps its own rate, one step per
    /// n of the system's, its inputs held over it (`master::Decimated`).
    pub fn add_component(
        &self,
        system: &mut TwinSystem,
        component: &str,
        start: f64,
        inputs: Vec<String>,
        outputs: Vec<String>,
        every: Option<usize>,
    ) -> Result<NodeId, SystemError> {
        let instance = self.instantiate(component, start)?;
        let c = self
            .loaded(component)
            .ok_or_else(|| SystemError::Wiring(format!("no component '{component}'")))?;
        let vr = |name: &String| c.fmu.value_reference(name).map_err(TwinError::from);
        let input_vrs = inputs.iter().map(vr).collect::<Result<Vec<_>, _>>()?;
        let output_vrs = outputs.iter().map(vr).collect::<Result<Vec<_>, _>>()?;
        let slave: Box<dyn Slave> = match every {
            Some(n) => Box::new(Decimated::new(Box::new(instance), n)?),
            None => Box::new(instance),
        };
        let id = system
            .system
            .add_slave(&c.name, slave, input_vrs, output_vrs);
        system.nodes.push(Node {
            name: c.name.clone(),
            id,
            inputs,
            outputs,
        });
        system.fmus.push(Arc::clone(&c.fmu));
        Ok(id)
    }

    /// The twin's system as its SSP wires it, instantiated at `start`: every component with
    /// the connectors its connections use as ports, the connections made. Of the system's
    /// inputs, those named in `inputs` become signals with the samples given (none: set point
    /// by point); the others are left at the FMUs' own values.
    pub fn build(
        &self,
        start: f64,
        inputs: Vec<(&str, Vec<f64>)>,
    ) -> Result<TwinSystem, SystemError> {
        let twin = &self.twin;
        let mut system = self.empty();
        for c in &self.components {
            // Ports: every connector the twin's connections use on this component.
            let inputs: Vec<String> = twin
                .connections
                .iter()
                .filter(|x| x.end_element.as_deref() == Some(&c.name))
                .map(|x| x.end_connector.clone())
                .collect();
            let outputs: Vec<String> = twin
                .connections
                .iter()
                .filter(|x| x.start_element.as_deref() == Some(&c.name))
                .map(|x| x.start_connector.clone())
                .collect();
            self.add_component(&mut system, &c.name, start, inputs, outputs, None)?;
        }
        let mut samples: Vec<(&str, Option<Vec<f64>>)> =
            inputs.into_iter().map(|(n, s)| (n, Some(s))).collect();
        for conn in &twin.connections {
            let Some(end) = &conn.end_element else {
                continue;
            };
            let (to, port) = system.input_port(end, &conn.end_connector)?;
            let from = match &conn.start_element {
                None => match system.signal(&conn.start_connector) {
                    Some(port) => port,
                    None => {
                        let Some((_, given)) = samples
                            .iter_mut()
                            .find(|(name, _)| *name == conn.start_connector)
                        else {
                            continue;
                        };
                        let port = system
                            .system
                            .add_signal(&conn.start_connector, given.take().unwrap_or_default());
                        system.signals.push((conn.start_connector.clone(), port));
                        port
                    }
                },
                Some(start_el) => system.output_port(start_el, &conn.start_connector)?,
            };
            system.system.connect(from, to, port)?;
        }
        Ok(system)
    }
}

/// Bring an instance (new, or reset) to its first communication point at `start`: the
/// experiment set up, `parameters` applied in initialisation mode and then `more` (a
/// calibration's trial values), initialised. Every instance of a twin's component goes through
/// here.
pub fn initialise(
    fmu: &Fmu,
    instance: &mut Instance,
    start: f64,
    parameters: &BTreeMap<String, ParameterValue>,
    more: impl FnOnce(&mut Instance) -> Result<(), TwinError>,
) -> Result<(), TwinError> {
    instance.setup_experiment(start, None)?;
    instance.enter_initialization_mode()?;
    apply_parameters(fmu, instance, parameters)?;
    more(instance)?;
    instance.exit_initialization_mode()?;
    Ok(())
}

/// A node the builder added: its component's name and ports by variable name.
struct Node {
    name: String,
    id: NodeId,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

/// The twin's running system, with its ports by name.
pub struct TwinSystem {
    // Dropped before `fmus`, whose libraries its instances run in.
    pub system: System,
    nodes: Vec<Node>,
    /// The system inputs that are signals, by connector name.
    signals: Vec<(String, Port)>,
    fmus: Vec<Arc<Fmu>>,
}

impl TwinSystem {
    fn find(&self, component: &str) -> Result<&Node, SystemError> {
        self.nodes
            .iter()
            .find(|n| n.name == component)
            .ok_or_else(|| SystemError::Wiring(format!("no component '{component}'")))
    }

    /// The node of a component.
    pub fn node(&self, component: &str) -> Option<NodeId> {
        self.find(component).ok().map(|n| n.id)
    }

    /// The signal a system input (e.g. `force`) comes in by, when it is driven.
    pub fn signal(&self, connector: &str) -> Option<Port> {
        self.signals
            .iter()
            .find(|(n, _)| n == connector)
            .map(|(_, p)| *p)
    }

    /// A component's output port by variable name (the first, when it is listed twice).
    pub fn output_port(&self, component: &str, variable: &str) -> Result<Port, SystemError> {
        let node = self.find(component)?;
        Ok(Port::Output(node.id, port_of(&node.outputs, variable)))
    }

    fn input_port(&self, component: &str, variable: &str) -> Result<(NodeId, usize), SystemError> {
        let node = self.find(component)?;
        Ok((node.id, port_of(&node.inputs, variable)))
    }

    /// The port that feeds the system output `connector` (e.g. `acc1`) in `twin`'s SSP.
    pub fn system_output(&self, twin: &Twin, connector: &str) -> Result<Port, SystemError> {
        let conn = twin
            .connections
            .iter()
            .find(|c| c.end_element.is_none() && c.end_connector == connector)
            .ok_or_else(|| {
                SystemError::Wiring(format!(
                    "no connection feeds the system output '{connector}'"
                ))
            })?;
        let start_el = conn
            .start_element
            .as_ref()
            .ok_or_else(|| SystemError::Wiring(format!("'{connector}' is fed by no component")))?;
        self.output_port(start_el, &conn.start_connector)
    }
}

/// A named variable's index among a node's ports (0 when absent: every caller names one that
/// its wiring put there).
fn port_of(names: &[String], variable: &str) -> usize {
    names.iter().position(|c| c == variable).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::cosim::import::StepEnd;
    use crate::cosim::master::Clock;
    use crate::twin::data::Measurement;
    use crate::twin::run::run_twin;

    /// The twin's system built here and stepped point by point (the force set for each next
    /// point) predicts `run_twin`'s accelerations to the bit; a state saved halfway and restored
    /// into a system built anew goes on to the same bits.
    #[test]
    fn the_built_system_stepped_point_by_point_is_run_twin() {
        let csv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/dataset1.csv");
        let data = Measurement::read(&csv).expect("dataset one reads");
        let twin = Twin::default_twin().expect("the default twin");
        let batch = run_twin(&twin, &data, |_, _| {}).expect("run_twin");
        let clock = Clock::new(data.time[0], data.dt, (data.len() - 1) as u64);
        let builder = SystemBuilder::open(&twin).expect("the FMUs open");
        // The record's accelerometers, floor by floor: the twin's outputs of the same names.
        let outputs: Vec<String> = data.responses.iter().map(|r| r.channel.name()).collect();
        let start = |builder: &SystemBuilder| {
            let running = builder
                .build(clock.start, vec![("force", Vec::new())])
                .expect("builds");
            let force = running.signal("force").expect("the force is driven");
            let acc: Vec<Port> = outputs
                .iter()
                .map(|o| running.system_output(&twin, o).expect("an output"))
                .collect();
            (running, force, acc)
        };
        let (mut running, force, acc) = start(&builder);
        let half = data.len() / 2;
        let mut saved = None;
        for k in 0..data.len() {
            let system = &mut running.system;
            system.set_input(force, data.force()[k]).expect("the force");
            if k == 0 {
                system.initialize(clock.time(0)).expect("the first point");
            } else {
                let end = system.step(clock.time(k as u64)).expect("a step");
                assert_eq!(end, StepEnd::Completed);
            }
            for (f, &port) in acc.iter().enumerate() {
                assert_eq!(
                    system.value(port).to_bits(),
                    batch.acc(f)[k].to_bits(),
                    "floor {} at sample {k}",
                    f + 1
                );
            }
            if k == half {
                saved = Some(system.save().expect("the shear FMU saves its state"));
            }
        }
        let (mut resumed, force, acc) = start(&builder);
        let system = &mut resumed.system;
        system.restore(&saved.expect("saved")).expect("restores");
        for k in half + 1..data.len() {
            system.set_input(force, data.force()[k]).expect("the force");
            system.step(clock.time(k as u64)).expect("a step");
            for (f, &port) in acc.iter().enumerate() {
                assert_eq!(
                    system.value(port).to_bits(),
                    batch.acc(f)[k].to_bits(),
                    "resumed: floor {} at sample {k}",
                    f + 1
                );
            }
        }
    }
}
