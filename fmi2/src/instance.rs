//! One FMU instance: the model, the FMI state machine, the host's logger and the time of the
//! last communication point. The C exports in `export` only convert pointers and call into here.
#![allow(non_upper_case_globals)]

use std::ffi::{CStr, CString};

use crate::abi::*;
use crate::model::{CoSimModel, InstantiateContext};
use crate::variables::LOG_CATEGORIES;

/// The FMI 2.0 co-simulation states this layer distinguishes, as bits so a call can name the
/// set of states it is allowed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[repr(u8)]
pub enum FsmState {
    Instantiated = 1,
    InitializationMode = 2,
    StepComplete = 4,
    Terminated = 8,
    Error = 16,
    Fatal = 32,
}

impl FsmState {
    pub fn bit(self) -> u8 {
        self as u8
    }
    pub fn name(self) -> &'static str {
        match self {
            FsmState::Instantiated => "Instantiated",
            FsmState::InitializationMode => "InitializationMode",
            FsmState::StepComplete => "StepComplete",
            FsmState::Terminated => "Terminated",
            FsmState::Error => "Error",
            FsmState::Fatal => "Fatal",
        }
    }
    pub fn names_in(mask: u8) -> String {
        let all = [
            FsmState::Instantiated,
            FsmState::InitializationMode,
            FsmState::StepComplete,
            FsmState::Terminated,
            FsmState::Error,
            FsmState::Fatal,
        ];
        let names: Vec<&str> = all
            .iter()
            .filter(|s| mask & s.bit() != 0)
            .map(|s| s.name())
            .collect();
        names.join(" | ")
    }
}

/// Allowed-state masks, after the FMI 2.0 co-simulation state machine.
pub mod mask {
    use super::FsmState::*;
    pub const ANY_LIVE: u8 = Instantiated as u8
        | InitializationMode as u8
        | StepComplete as u8
        | Terminated as u8
        | Error as u8;
    pub const SETUP_EXPERIMENT: u8 = Instantiated as u8;
    pub const ENTER_INITIALIZATION: u8 = Instantiated as u8;
    pub const EXIT_INITIALIZATION: u8 = InitializationMode as u8;
    pub const TERMINATE: u8 = StepComplete as u8 | Error as u8;
    pub const GET: u8 =
        InitializationMode as u8 | StepComplete as u8 | Terminated as u8 | Error as u8;
    pub const SET: u8 = Instantiated as u8 | InitializationMode as u8 | StepComplete as u8;
    pub const DO_STEP: u8 = StepComplete as u8;
    pub const GET_STATE: u8 =
        Instantiated as u8 | InitializationMode as u8 | StepComplete as u8 | Terminated as u8;
    pub const SET_STATE: u8 = ANY_LIVE;
    pub const STATUS: u8 = StepComplete as u8 | Terminated as u8 | Error as u8;
}

/// Guards against a pointer that is not a live instance of this layer (a freed one, another
/// library's). Not a safety guarantee, a cheap and useful check.
const INSTANCE_MAGIC: u64 = 0x5348_4541_5254_5749; // "SHEARTWI"
const SNAPSHOT_MAGIC: u64 = 0x5354_5753_4e41_5053; // "STWSNAPS"

/// The host's logger, with the instance name and the categories the host switched on.
pub struct Logger {
    name: CString,
    callbacks: fmi2CallbackFunctions,
    debug_logging: bool,
    /// Enabled categories, as indices into `LOG_CATEGORIES`.
    categories: [bool; LOG_CATEGORIES.len()],
}

impl Logger {
    pub(crate) fn new(
        instance_name: &str,
        callbacks: fmi2CallbackFunctions,
        debug_logging: bool,
    ) -> Self {
        Logger {
            name: to_c_string(instance_name),
            callbacks,
            debug_logging,
            categories: [true; LOG_CATEGORIES.len()],
        }
    }

    pub(crate) fn set_debug_logging(
        &mut self,
        on: bool,
        categories: &[String],
    ) -> Result<(), String> {
        let mut enabled = [categories.is_empty(); LOG_CATEGORIES.len()];
        for category in categories {
            match LOG_CATEGORIES.iter().position(|(name, _)| name == category) {
                Some(i) => enabled[i] = true,
                None => {
                    let known: Vec<&str> = LOG_CATEGORIES.iter().map(|(n, _)| *n).collect();
                    return Err(format!(
                        "unknown log category '{category}'; known: {}",
                        known.join(", ")
                    ));
                }
            }
        }
        self.debug_logging = on;
        self.categories = enabled;
        Ok(())
    }

    /// Errors and warnings always reach the host (unless it switched their category off while
    /// debug logging is on); `logCalls` messages only with debug logging on.
    pub(crate) fn log(&self, status: fmi2Status, message: &str) {
        let category = match status {
            fmi2OK | fmi2Pending => 2,
            fmi2Warning | fmi2Discard => 1,
            _ => 0,
        };
        let wanted = if category == 2 {
            self.debug_logging && self.categories[2]
        } else {
            !self.debug_logging || self.categories[category]
        };
        if !wanted {
            return;
        }
        if let Some(logger) = self.callbacks.logger {
            let category_name = to_c_string(LOG_CATEGORIES[category].0);
            let message = to_c_string(message);
            // SAFETY: the host gave this logger for this purpose; all strings are NUL-terminated
            // and live across the call; "%s" keeps any '%' in the message literal.
            unsafe {
                logger(
                    self.callbacks.component_environment,
                    self.name.as_ptr(),
                    status,
                    category_name.as_ptr(),
                    c"%s".as_ptr(),
                    message.as_ptr(),
                )
            };
        }
    }

    pub(crate) fn logs_calls(&self) -> bool {
        self.debug_logging && self.categories[2]
    }
}

/// `repr(C)` with the magic first, so `from_ptr` can read it through a raw pointer before
/// trusting the rest.
#[repr(C)]
pub struct Instance<M> {
    magic: u64,
    pub(crate) context: InstantiateContext,
    pub(crate) logger: Logger,
    pub(crate) state: FsmState,
    /// End of the last communication step: the `currentCommunicationPoint` the next step must have.
    pub(crate) time: f64,
    pub(crate) stop_time: Option<f64>,
    pub(crate) model: M,
    /// Keeps the strings handed out by `fmi2GetString` alive until the next call.
    pub(crate) string_buffer: Vec<CString>,
}

impl<M: CoSimModel> Instance<M> {
    pub(crate) fn new(context: InstantiateContext, logger: Logger, model: M) -> Self {
        Instance {
            magic: INSTANCE_MAGIC,
            context,
            logger,
            state: FsmState::Instantiated,
            time: 0.0,
            stop_time: None,
            model,
            string_buffer: Vec::new(),
        }
    }

    /// # Safety
    /// `c` must be null or a pointer returned by `fmi2Instantiate` of this library.
    pub(crate) unsafe fn from_ptr<'a>(c: fmi2Component) -> Option<&'a mut Self> {
        if c.is_null() {
            return None;
        }
        // SAFETY: the caller promises `c` came from `Box::into_raw(Box<Instance<M>>)`; the magic
        // (first field of a repr(C) struct) is read before any reference to the whole is formed.
        if unsafe { std::ptr::read(c as *const u64) } != INSTANCE_MAGIC {
            return None;
        }
        Some(unsafe { &mut *(c as *mut Self) })
    }

    pub(crate) fn into_ptr(self) -> fmi2Component {
        Box::into_raw(Box::new(self)) as fmi2Component
    }

    /// # Safety
    /// As `from_ptr`; the pointer is dangling afterwards.
    pub(crate) unsafe fn free(c: fmi2Component) {
        // SAFETY: checked by from_ptr; ownership goes back to a Box exactly once because the
        // magic is cleared before the drop.
        if let Some(inst) = unsafe { Self::from_ptr(c) } {
            inst.magic = 0;
            drop(unsafe { Box::from_raw(c as *mut Self) });
        }
    }

    pub(crate) fn log(&self, status: fmi2Status, message: &str) {
        self.logger.log(status, message);
    }

    pub(crate) fn snapshot(&self) -> Snapshot<M> {
        Snapshot {
            magic: SNAPSHOT_MAGIC,
            model: self.model.clone(),
            time: self.time,
            stop_time: self.stop_time,
            state: self.state,
        }
    }

    pub(crate) fn restore(&mut self, snapshot: &Snapshot<M>) {
        self.model = snapshot.model.clone();
        self.time = snapshot.time;
        self.stop_time = snapshot.stop_time;
        self.state = snapshot.state;
    }
}

/// An FMU state (`fmi2FMUstate`): everything needed to resume from this point.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
#[repr(C)]
pub struct Snapshot<M> {
    magic: u64,
    model: M,
    time: f64,
    stop_time: Option<f64>,
    state: FsmState,
}

impl<M: CoSimModel> Snapshot<M> {
    /// # Safety
    /// `s` must be null or a pointer made by `into_ptr` of this library.
    pub(crate) unsafe fn from_ptr<'a>(s: fmi2FMUstate) -> Option<&'a mut Self> {
        if s.is_null() {
            return None;
        }
        // SAFETY: promised by the caller; the magic is read first, as in Instance::from_ptr.
        if unsafe { std::ptr::read(s as *const u64) } != SNAPSHOT_MAGIC {
            return None;
        }
        Some(unsafe { &mut *(s as *mut Self) })
    }

    pub(crate) fn into_ptr(self) -> fmi2FMUstate {
        Box::into_raw(Box::new(self)) as fmi2FMUstate
    }

    /// # Safety
    /// As `from_ptr`.
    pub(crate) unsafe fn free(s: fmi2FMUstate) {
        // SAFETY: as Instance::free.
        if let Some(snap) = unsafe { Self::from_ptr(s) } {
            snap.magic = 0;
            drop(unsafe { Box::from_raw(s as *mut Self) });
        }
    }

    /// The GUID of the model configuration this state belongs to.
    pub(crate) fn guid(&self) -> &'static str {
        &self.model.table().guid
    }

    /// Serialized form: a header naming the model's GUID, then postcard.
    pub(crate) fn to_bytes(&self) -> Result<Vec<u8>, String> {
        let mut bytes = serialization_header(self.guid());
        let body = postcard::to_stdvec(self)
            .map_err(|e| format!("cannot serialize the FMU state: {e}"))?;
        bytes.extend_from_slice(&body);
        Ok(bytes)
    }

    /// A state serialized by an instance whose table has the GUID `guid`.
    pub(crate) fn from_bytes(bytes: &[u8], guid: &str) -> Result<Self, String> {
        let header = serialization_header(guid);
        let body = bytes.strip_prefix(header.as_slice()).ok_or(
            "the serialized FMU state was not made by this model (header or GUID differs)",
        )?;
        let snap: Self = postcard::from_bytes(body)
            .map_err(|e| format!("the serialized FMU state is corrupt: {e}"))?;
        if snap.magic != SNAPSHOT_MAGIC {
            return Err("the serialized FMU state is corrupt: bad magic".into());
        }
        if !snap.time.is_finite() || matches!(snap.state, FsmState::Error | FsmState::Fatal) {
            return Err(format!(
                "the serialized FMU state is not a usable state (time {}, state {})",
                snap.time,
                snap.state.name()
            ));
        }
        Ok(snap)
    }
}

fn serialization_header(guid: &str) -> Vec<u8> {
    let mut h = b"STWIN-FMUSTATE-1 ".to_vec();
    h.extend_from_slice(guid.as_bytes());
    h
}

/// A C string from Rust text; interior NULs (which C cannot carry) become '?'.
pub(crate) fn to_c_string(text: &str) -> CString {
    CString::new(text.replace('\0', "?")).unwrap_or_default()
}

/// # Safety
/// `s` must be null or point to a NUL-terminated string.
pub(crate) unsafe fn from_c_str(s: fmi2String) -> Option<String> {
    if s.is_null() {
        return None;
    }
    // SAFETY: promised by the caller.
    Some(unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned())
}

/// The `resources/` directory from the URI a host passes to `fmi2Instantiate`.
pub(crate) fn resource_dir_from_uri(uri: &str) -> Option<std::path::PathBuf> {
    let rest = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))?;
    let rest = rest.strip_prefix("localhost").unwrap_or(rest);
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let Ok(b) = u8::from_str_radix(std::str::from_utf8(&bytes[i + 1..i + 3]).ok()?, 16) {
                out.push(b);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    let path = String::from_utf8(out).ok()?;
    Some(std::path::PathBuf::from(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resource_uris_become_paths() {
        assert_eq!(
            resource_dir_from_uri("file:///tmp/a%20b/resources"),
            Some("/tmp/a b/resources".into())
        );
        assert_eq!(resource_dir_from_uri("file:/tmp/x"), Some("/tmp/x".into()));
        assert_eq!(
            resource_dir_from_uri("file://localhost/tmp/x"),
            Some("/tmp/x".into())
        );
        assert_eq!(resource_dir_from_uri("http://example/x"), None);
    }

    #[test]
    fn masks_name_their_states() {
        assert_eq!(FsmState::names_in(mask::DO_STEP), "StepComplete");
        assert_eq!(
            FsmState::names_in(mask::EXIT_INITIALIZATION),
            "InitializationMode"
        );
    }
}
