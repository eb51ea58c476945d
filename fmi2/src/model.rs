//! The safe side of the export layer: what a co-simulation model implements, and the variable
//! table that both the C exports and the modelDescription.xml are derived from.

use std::path::PathBuf;

use serde::{de::DeserializeOwned, Serialize};

use crate::variables::ModelInfo;

/// What went wrong inside a model call. Every variant becomes `fmi2Error` at the C boundary,
/// with the `Display` text sent to the host's logger.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum ModelError {
    #[error("unknown value reference {vr} for a {kind} variable")]
    UnknownVariable { vr: u32, kind: &'static str },
    #[error("invalid value for '{name}': {reason}")]
    InvalidValue { name: String, reason: String },
    #[error("the state diverged at t = {time}: {what}")]
    Diverged { time: f64, what: String },
    #[error("{0}")]
    Other(String),
}

/// Where and how the host instantiated the FMU.
#[derive(Debug, Clone, Default)]
pub struct InstantiateContext {
    pub instance_name: String,
    /// The unpacked FMU's `resources/` directory, when the host gave a `file:` URI.
    pub resource_dir: Option<PathBuf>,
}

/// A co-simulation model: the only thing an FMU of this project writes by hand.
///
/// Call order, enforced by the export layer before any of these methods run:
/// `instantiate` → (`set_*`)* → `exit_initialization` → (`set_*` / `set_real_input_derivative` /
/// `do_step` / `get_*`)* → drop. `get_*` may run from initialization mode on. A `reset` is a
/// fresh `instantiate` with the same context. `Clone` is the in-memory FMU state (`fmi2GetFMUstate`);
/// serde is the serialized one.
///
/// The layer has already checked, before calling a setter, that the value reference exists in
/// `info()` with the right type, that the variable may be set in the current state and that a real
/// value is finite; a model still returns `UnknownVariable` for anything it does not know.
/// To set a batch of several values whole or not at all, the layer first reads them with the
/// matching `get_*` (in any state), and puts them back if the model refuses a later one: `get_*`
/// of a settable variable returns what its `set_*` stored.
pub trait CoSimModel: Sized + Clone + Serialize + DeserializeOwned + 'static {
    /// The variable table and identity (GUID, model identifier, capabilities) of the model's
    /// default configuration. Built once.
    fn info() -> &'static ModelInfo;

    /// This instance's variable table. A model whose variables depend on what it read at
    /// `instantiate` (the shear FMU's storeys, from its resources) returns the table of that
    /// configuration, built once per configuration and kept for the life of the library; the
    /// layer checks the host's GUID, value references and types against it. By default
    /// [`CoSimModel::info`].
    fn table(&self) -> &'static ModelInfo {
        Self::info()
    }

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError>;

    /// `fmi2Reset`: the model as `instantiate` made it. By default instantiated again; a model
    /// that reads files at `instantiate` may rebuild itself from what it read instead (a
    /// calibration resets an instance once per simulation).
    fn reset(&mut self, context: &InstantiateContext) -> Result<(), ModelError> {
        *self = Self::instantiate(context)?;
        Ok(())
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError>;
    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError>;

    /// One `fmi2GetReal` call: `out[i]` the value of `vrs[i]`. By default [`Self::get_real`] one
    /// by one; a model whose outputs share a computation (every floor's acceleration from one
    /// solve) does it once per call here, as nothing can change between the values of one call.
    fn get_reals(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), ModelError> {
        for (slot, &vr) in out.iter_mut().zip(vrs) {
            *slot = self.get_real(vr)?;
        }
        Ok(())
    }

    fn get_integer(&mut self, vr: u32) -> Result<i32, ModelError> {
        Err(ModelError::UnknownVariable {
            vr,
            kind: "Integer",
        })
    }
    fn set_integer(&mut self, vr: u32, _value: i32) -> Result<(), ModelError> {
        Err(ModelError::UnknownVariable {
            vr,
            kind: "Integer",
        })
    }
    fn get_boolean(&mut self, vr: u32) -> Result<bool, ModelError> {
        Err(ModelError::UnknownVariable {
            vr,
            kind: "Boolean",
        })
    }
    fn set_boolean(&mut self, vr: u32, _value: bool) -> Result<(), ModelError> {
        Err(ModelError::UnknownVariable {
            vr,
            kind: "Boolean",
        })
    }
    fn get_string(&mut self, vr: u32) -> Result<String, ModelError> {
        Err(ModelError::UnknownVariable { vr, kind: "String" })
    }
    fn set_string(&mut self, vr: u32, _value: &str) -> Result<(), ModelError> {
        Err(ModelError::UnknownVariable { vr, kind: "String" })
    }

    /// First time derivative of a real input, valid from the current communication point: the
    /// model treats the input as `u(t) = u + du·(t − t_c)` inside the next step (that step only:
    /// a model ends the step with the input at its end value and the derivative at zero). Only called
    /// when `info().can_interpolate_inputs`.
    fn set_real_input_derivative(&mut self, vr: u32, _derivative: f64) -> Result<(), ModelError> {
        Err(ModelError::UnknownVariable {
            vr,
            kind: "Real input",
        })
    }

    /// Leaving initialization mode: check the parameters together and precompute.
    fn exit_initialization(&mut self) -> Result<(), ModelError> {
        Ok(())
    }

    /// Advance from `time` to `time + step_size`. A non-finite state is `ModelError::Diverged`.
    fn do_step(&mut self, time: f64, step_size: f64) -> Result<(), ModelError>;
}
