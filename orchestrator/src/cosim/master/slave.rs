//! What the master steps and watches: a slave (an FMU instance, or a mock in tests), a block
//! evaluated in zero time, an observer of the communication points.

use super::MasterError;
use crate::cosim::import::{Instance, StepEnd};

/// A node of the system: a slave or a block, by its place in the system's list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodeId(pub usize);

/// Where a value comes from: a node's output port, or a replayed signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Port {
    Output(NodeId, usize),
    Signal(usize),
}

fn unsupported(what: &str) -> MasterError {
    MasterError::Config(format!("this slave has no {what} variables"))
}

/// Something that advances in simulated time: an FMU instance, or a mock in tests.
/// Call order: `set_*`/`set_real_input_derivatives` → `get_*` (any number, zero time) →
/// `do_step(t_k, h)` → … with `t_k` the end of the previous step. Only Real is required; the
/// other types default to an error, for slaves that have none.
pub trait Slave {
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), MasterError>;
    fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError>;
    fn set_integer(&mut self, _vrs: &[u32], _values: &[i32]) -> Result<(), MasterError> {
        Err(unsupported("Integer"))
    }
    fn get_integer(&mut self, _vrs: &[u32], _values: &mut [i32]) -> Result<(), MasterError> {
        Err(unsupported("Integer"))
    }
    fn set_boolean(&mut self, _vrs: &[u32], _values: &[bool]) -> Result<(), MasterError> {
        Err(unsupported("Boolean"))
    }
    fn get_boolean(&mut self, _vrs: &[u32], _values: &mut [bool]) -> Result<(), MasterError> {
        Err(unsupported("Boolean"))
    }
    fn set_string(&mut self, _vrs: &[u32], _values: &[&str]) -> Result<(), MasterError> {
        Err(unsupported("String"))
    }
    fn get_string(&mut self, _vrs: &[u32]) -> Result<Vec<String>, MasterError> {
        Err(unsupported("String"))
    }
    /// Only called when `can_interpolate_inputs`.
    fn set_real_input_derivatives(
        &mut self,
        vrs: &[u32],
        slopes: &[f64],
    ) -> Result<(), MasterError>;
    fn can_interpolate_inputs(&self) -> bool;
    fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError>;
    /// A step that may end the simulation (an FMU's `fmi2Discard` + `fmi2Terminated`).
    fn step(&mut self, time: f64, step: f64) -> Result<StepEnd, MasterError> {
        self.do_step(time, step).map(|()| StepEnd::Completed)
    }
    /// The slave's whole state as bytes (an FMU's serialised `fmi2FMUstate`), for
    /// [`System::save`]. Slaves that cannot save their state say so.
    fn save_state(&mut self) -> Result<Vec<u8>, MasterError> {
        Err(MasterError::Config(
            "this slave cannot save its state".into(),
        ))
    }
    /// Put the slave back in a state [`Slave::save_state`] gave.
    fn restore_state(&mut self, _state: &[u8]) -> Result<(), MasterError> {
        Err(MasterError::Config(
            "this slave cannot restore a state".into(),
        ))
    }
}

impl Slave for Instance {
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), MasterError> {
        Ok(Instance::set_real(self, vrs, values)?)
    }
    fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError> {
        Ok(Instance::get_real(self, vrs, values)?)
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), MasterError> {
        Ok(Instance::set_integer(self, vrs, values)?)
    }
    fn get_integer(&mut self, vrs: &[u32], values: &mut [i32]) -> Result<(), MasterError> {
        Ok(Instance::get_integer(self, vrs, values)?)
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[bool]) -> Result<(), MasterError> {
        Ok(Instance::set_boolean(self, vrs, values)?)
    }
    fn get_boolean(&mut self, vrs: &[u32], values: &mut [bool]) -> Result<(), MasterError> {
        Ok(Instance::get_boolean(self, vrs, values)?)
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), MasterError> {
        Ok(Instance::set_string(self, vrs, values)?)
    }
    fn get_string(&mut self, vrs: &[u32]) -> Result<Vec<String>, MasterError> {
        Ok(Instance::get_string(self, vrs)?)
    }
    fn set_real_input_derivatives(
        &mut self,
        vrs: &[u32],
        slopes: &[f64],
    ) -> Result<(), MasterError> {
        Ok(Instance::set_real_input_derivatives(self, vrs, slopes)?)
    }
    fn can_interpolate_inputs(&self) -> bool {
        Instance::can_interpolate_inputs(self)
    }
    fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError> {
        Ok(Instance::do_step(self, time, step)?)
    }
    fn step(&mut self, time: f64, step: f64) -> Result<StepEnd, MasterError> {
        Ok(Instance::step(self, time, step)?)
    }
    fn save_state(&mut self) -> Result<Vec<u8>, MasterError> {
        Ok(Instance::state_bytes(self)?)
    }
    fn restore_state(&mut self, state: &[u8]) -> Result<(), MasterError> {
        Ok(Instance::restore_state_bytes(self, state)?)
    }
}

/// A function of its inputs evaluated in zero simulated time (the LQR, the supervisor). Its
/// outputs must depend only on its inputs (and the time): the master skips a call whose inputs
/// did not change within a communication point.
pub trait Block {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError>;
}

impl<F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), MasterError>> Block for F {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError> {
        self(time, inputs, outputs)
    }
}

/// Records values at each communication point.
pub trait Observer {
    /// `values[i]` is the current value of the i-th port this observer watches (NaN for a
    /// String port: those come through `record_text`).
    fn record(&mut self, time: f64, values: &[f64]);
    fn ports(&self) -> &[Port];
    /// String ports to watch; their values are handed to `record_text` after each `record`.
    fn text_ports(&self) -> &[Port] {
        &[]
    }
    fn record_text(&mut self, _values: &[&str]) {}
    /// Called once before a run with the number of points it will record at most.
    fn will_record(&mut self, _points: usize) {}
}
