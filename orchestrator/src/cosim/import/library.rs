//! Loading an FMU's shared library and driving one instance through a safe wrapper whose methods
//! return `Result`. FMI status → `Result` happens in one place, `Instance::check`.

#![allow(non_upper_case_globals)]
// Loading a shared library and calling its C functions: the orchestrator's only `unsafe`.
#![allow(unsafe_code)]

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use fmi2::abi::*;

use super::ImportError;

extern "C" {
    fn twin_set_log_sink(
        sink: unsafe extern "C" fn(*mut c_void, *const c_char, c_int, *const c_char, *const c_char),
    );
    fn twin_fmi2_logger(
        env: *mut c_void,
        instance: *const c_char,
        status: c_int,
        category: *const c_char,
        format: *const c_char,
        ...
    );
}

/// One message an FMU sent through the logger.
#[derive(Debug, Clone, PartialEq)]
pub struct FmuMessage {
    pub status: fmi2Status,
    pub category: String,
    pub text: String,
}

/// Where an instance's messages go: kept for error reports, and handed on as notices
/// ([`crate::notice`], topic `FmuLog`; `twin` prints them when `TWIN_FMU_LOG` is set).
#[derive(Debug, Default)]
struct MessageLog {
    instance: String,
    messages: Mutex<Vec<FmuMessage>>,
}

unsafe extern "C" fn log_sink(
    env: *mut c_void,
    _instance: *const c_char,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if env.is_null() {
        return;
    }
    // SAFETY: `env` is the componentEnvironment this module passed to fmi2Instantiate: a
    // `MessageLog` that lives until after fmi2FreeInstance. The strings are NUL-terminated
    // (the C shim guarantees it).
    let log = unsafe { &*(env as *const MessageLog) };
    let text = |p: *const c_char| {
        if p.is_null() {
            String::new()
        } else {
            unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    };
    let entry = FmuMessage {
        status: status as fmi2Status,
        category: text(category),
        text: text(message),
    };
    crate::notice::notify(crate::notice::Topic::FmuLog, || {
        format!("[{}] {}: {}", log.instance, entry.category, entry.text)
    });
    if let Ok(mut messages) = log.messages.lock() {
        messages.push(entry);
    }
}

type Fn0 = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
type GetReal = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *mut fmi2Real,
) -> fmi2Status;
type SetReal = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2Real,
) -> fmi2Status;
type GetInt = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *mut fmi2Integer,
) -> fmi2Status;
type SetInt = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2Integer,
) -> fmi2Status;
type GetString = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *mut fmi2String,
) -> fmi2Status;
type SetString = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2String,
) -> fmi2Status;

/// The functions of a loaded FMI 2.0 co-simulation library.
struct Api {
    instantiate: unsafe extern "C" fn(
        fmi2String,
        fmi2Type,
        fmi2String,
        fmi2String,
        *const fmi2CallbackFunctions,
        fmi2Boolean,
        fmi2Boolean,
    ) -> fmi2Component,
    free_instance: unsafe extern "C" fn(fmi2Component),
    setup_experiment: unsafe extern "C" fn(
        fmi2Component,
        fmi2Boolean,
        fmi2Real,
        fmi2Real,
        fmi2Boolean,
        fmi2Real,
    ) -> fmi2Status,
    enter_initialization_mode: Fn0,
    exit_initialization_mode: Fn0,
    terminate: Fn0,
    reset: Fn0,
    get_real: GetReal,
    set_real: SetReal,
    get_integer: GetInt,
    set_integer: SetInt,
    get_boolean: GetInt,
    set_boolean: SetInt,
    get_string: GetString,
    set_string: SetString,
    get_boolean_status:
        Option<unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Boolean) -> fmi2Status>,
    get_real_status:
        Option<unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Real) -> fmi2Status>,
    do_step: unsafe extern "C" fn(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean) -> fmi2Status,
    set_real_input_derivatives: Option<
        unsafe extern "C" fn(
            fmi2Component,
            *const fmi2ValueReference,
            usize,
            *const fmi2Integer,
            *const fmi2Real,
        ) -> fmi2Status,
    >,
    get_fmu_state: Option<unsafe extern "C" fn(fmi2Component, *mut fmi2FMUstate) -> fmi2Status>,
    set_fmu_state: Option<unsafe extern "C" fn(fmi2Component, fmi2FMUstate) -> fmi2Status>,
    free_fmu_state: Option<unsafe extern "C" fn(fmi2Component, *mut fmi2FMUstate) -> fmi2Status>,
    serialized_fmu_state_size:
        Option<unsafe extern "C" fn(fmi2Component, fmi2FMUstate, *mut usize) -> fmi2Status>,
    serialize_fmu_state: Option<
        unsafe extern "C" fn(fmi2Component, fmi2FMUstate, *mut fmi2Byte, usize) -> fmi2Status,
    >,
    deserialize_fmu_state: Option<
        unsafe extern "C" fn(
            fmi2Component,
            *const fmi2Byte,
            usize,
            *mut fmi2FMUstate,
        ) -> fmi2Status,
    >,
    // Keeps the code above mapped; dropped last.
    _library: libloading::Library,
}

/// A loaded FMU library, shared by its instances.
#[derive(Clone)]
pub struct Library {
    api: Arc<Api>,
    path: PathBuf,
    /// What messages name: the `.fmu` the library came from (the library itself until told).
    source: PathBuf,
    guid: String,
    resource_uri: String,
    /// `canInterpolateInputs` of the modelDescription: an FMU may export
    /// fmi2SetRealInputDerivatives and still not support it.
    interpolates: bool,
    /// `canGetAndSetFMUstate` and `canSerializeFMUstate` of the modelDescription: what the
    /// state-serialising methods of [`Instance`] check before calling the FMU.
    state_capabilities: StateCapabilities,
}

/// What the modelDescription declares about FMU states.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StateCapabilities {
    pub get_and_set: bool,
    pub serialize: bool,
}

impl Library {
    /// Load `path` (an unpacked `binaries/linux64/<id>.so`). `resources` is the unpacked
    /// `resources/` directory handed to instances as a `file:` URI.
    pub fn load(path: &Path, guid: &str, resources: &Path) -> Result<Self, ImportError> {
        let bad = |message: String| ImportError::Library {
            path: path.to_owned(),
            message,
        };
        // SAFETY: loading a shared library runs its initialisers; an FMU is code the user chose
        // to run, as any FMI tool does.
        let library = unsafe { libloading::Library::new(path) }
            .map_err(|e| bad(format!("cannot load: {e}")))?;
        macro_rules! required {
            ($name:literal) => {
                // SAFETY: the symbol is an FMI 2.0 function with the standard's signature.
                *unsafe { library.get(concat!($name, "\0").as_bytes()) }
                    .map_err(|e| bad(format!("missing function {}: {e}", $name)))?
            };
        }
        macro_rules! optional {
            ($name:literal) => {
                // SAFETY: as above.
                unsafe { library.get(concat!($name, "\0").as_bytes()) }
                    .ok()
                    .map(|s| *s)
            };
        }
        let api = Api {
            instantiate: required!("fmi2Instantiate"),
            free_instance: required!("fmi2FreeInstance"),
            setup_experiment: required!("fmi2SetupExperiment"),
            enter_initialization_mode: required!("fmi2EnterInitializationMode"),
            exit_initialization_mode: required!("fmi2ExitInitializationMode"),
            terminate: required!("fmi2Terminate"),
            reset: required!("fmi2Reset"),
            get_real: required!("fmi2GetReal"),
            set_real: required!("fmi2SetReal"),
            get_integer: required!("fmi2GetInteger"),
            set_integer: required!("fmi2SetInteger"),
            get_boolean: required!("fmi2GetBoolean"),
            set_boolean: required!("fmi2SetBoolean"),
            get_string: required!("fmi2GetString"),
            set_string: required!("fmi2SetString"),
            get_boolean_status: optional!("fmi2GetBooleanStatus"),
            get_real_status: optional!("fmi2GetRealStatus"),
            do_step: required!("fmi2DoStep"),
            set_real_input_derivatives: optional!("fmi2SetRealInputDerivatives"),
            get_fmu_state: optional!("fmi2GetFMUstate"),
            set_fmu_state: optional!("fmi2SetFMUstate"),
            free_fmu_state: optional!("fmi2FreeFMUstate"),
            serialized_fmu_state_size: optional!("fmi2SerializedFMUstateSize"),
            serialize_fmu_state: optional!("fmi2SerializeFMUstate"),
            deserialize_fmu_state: optional!("fmi2DeSerializeFMUstate"),
            _library: library,
        };
        let resource_uri = file_uri(resources);
        Ok(Library {
            api: Arc::new(api),
            path: path.to_owned(),
            source: path.to_owned(),
            guid: guid.to_owned(),
            resource_uri,
            interpolates: false,
            state_capabilities: StateCapabilities::default(),
        })
    }

    /// Declare what the FMU says about its states (`canGetAndSetFMUstate`,
    /// `canSerializeFMUstate`).
    pub fn with_state_capabilities(mut self, capabilities: StateCapabilities) -> Self {
        self.state_capabilities = capabilities;
        self
    }

    /// Name `fmu` (the archive the library was unpacked from) in every message of its instances.
    pub fn with_source(mut self, fmu: &Path) -> Self {
        self.source = fmu.to_owned();
        self
    }

    /// The URI handed to instances as `fmuResourceLocation`.
    pub fn resource_uri(&self) -> &str {
        &self.resource_uri
    }

    /// Declare whether the FMU can interpolate inputs (its `canInterpolateInputs`).
    pub fn with_input_interpolation(mut self, interpolates: bool) -> Self {
        self.interpolates = interpolates;
        self
    }

    pub fn instantiate(&self, instance_name: &str) -> Result<Instance, ImportError> {
        // SAFETY: the sink is a plain function; setting it more than once is harmless.
        unsafe { twin_set_log_sink(log_sink) };
        let log = Box::new(MessageLog {
            instance: instance_name.to_owned(),
            messages: Mutex::new(Vec::new()),
        });
        // SAFETY: the shim has the FMI logger's C-variadic signature; the transmute only names
        // its type as the ABI module declares it.
        let logger: fmi2CallbackLogger = Some(unsafe {
            std::mem::transmute::<
                unsafe extern "C" fn(
                    *mut c_void,
                    *const c_char,
                    c_int,
                    *const c_char,
                    *const c_char,
                    ...
                ),
                unsafe extern "C" fn(
                    fmi2ComponentEnvironment,
                    fmi2String,
                    fmi2Status,
                    fmi2String,
                    fmi2String,
                    ...
                ),
            >(twin_fmi2_logger)
        });
        let callbacks = Box::new(fmi2CallbackFunctions {
            logger,
            allocate_memory: Some(alloc_zeroed),
            free_memory: Some(free_memory),
            step_finished: None,
            component_environment: &*log as *const MessageLog as *mut c_void,
        });
        let name = CString::new(instance_name).map_err(|_| ImportError::Library {
            path: self.path.clone(),
            message: format!("instance name '{instance_name}' contains a NUL byte"),
        })?;
        let guid = CString::new(self.guid.as_str()).unwrap_or_default();
        let uri = CString::new(self.resource_uri.as_str()).unwrap_or_default();
        // SAFETY: all strings are NUL-terminated and outlive the call; `callbacks` and `log` are
        // boxed and owned by the returned Instance, so they outlive the FMU instance.
        let component = unsafe {
            (self.api.instantiate)(
                name.as_ptr(),
                fmi2CoSimulation,
                guid.as_ptr(),
                uri.as_ptr(),
                &*callbacks,
                fmi2False,
                fmi2False,
            )
        };
        let instance = Instance {
            api: self.api.clone(),
            interpolates: self.interpolates && self.api.set_real_input_derivatives.is_some(),
            state_capabilities: self.state_capabilities,
            component,
            states: Vec::new(),
            name: instance_name.to_owned(),
            source: self.source.display().to_string(),
            log,
            _callbacks: callbacks,
        };
        if component.is_null() {
            return Err(ImportError::Call {
                instance: instance_name.to_owned(),
                fmu: instance.source.clone(),
                call: "fmi2Instantiate",
                status: "returned NULL".into(),
                messages: instance.take_messages_text(),
            });
        }
        Ok(instance)
    }
}

unsafe extern "C" fn alloc_zeroed(n: usize, size: usize) -> *mut c_void {
    // SAFETY: calloc has exactly this contract.
    unsafe { libc_calloc(n, size) }
}
unsafe extern "C" fn free_memory(p: *mut c_void) {
    // SAFETY: p came from alloc_zeroed (calloc) or is null.
    unsafe { libc_free(p) }
}
extern "C" {
    #[link_name = "calloc"]
    fn libc_calloc(n: usize, size: usize) -> *mut c_void;
    #[link_name = "free"]
    fn libc_free(p: *mut c_void);
}

/// How a communication step ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepEnd {
    Completed,
    /// The FMU ended the simulation itself; `at` is its last successful time.
    Terminated {
        at: f64,
    },
}

/// `path` as a `file:` URI, every byte outside RFC 3986's unreserved set and `/`
/// percent-encoded (spaces, `%`, `#`, `?`, non-ASCII…), as Python's `Path.as_uri` writes it.
pub fn file_uri(path: &Path) -> String {
    use std::os::unix::ffi::OsStrExt;
    let mut uri = String::from("file://");
    for &b in path.as_os_str().as_bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~' | b'/') {
            uri.push(b as char);
        } else {
            uri.push_str(&format!("%{b:02X}"));
        }
    }
    uri
}

/// A saved FMU state, owned by the instance that made it (freed with it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateHandle(usize);

/// One instance of an FMU. Not `Sync`: FMI allows one call at a time per instance.
pub struct Instance {
    api: Arc<Api>,
    interpolates: bool,
    state_capabilities: StateCapabilities,
    component: fmi2Component,
    states: Vec<fmi2FMUstate>,
    name: String,
    /// The `.fmu` it came from, for messages.
    source: String,
    log: Box<MessageLog>,
    _callbacks: Box<fmi2CallbackFunctions>,
}

// SAFETY: an FMI 2.0 instance may be used from any thread, one call at a time; `&mut self` on
// every call enforces that.
unsafe impl Send for Instance {}

impl Instance {
    pub fn name(&self) -> &str {
        &self.name
    }

    fn take_messages_text(&self) -> String {
        let messages = self
            .log
            .messages
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default();
        messages
            .iter()
            .map(|m| m.text.as_str())
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// Messages the FMU logged so far (and clears them).
    pub fn take_messages(&self) -> Vec<FmuMessage> {
        self.log
            .messages
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default()
    }

    /// FMI status → Result, in one place. Warnings pass (their text stays in the log).
    fn check(&self, call: &'static str, status: fmi2Status) -> Result<(), ImportError> {
        match status {
            fmi2OK | fmi2Warning => Ok(()),
            other => Err(ImportError::Call {
                instance: self.name.clone(),
                fmu: self.source.clone(),
                call,
                status: match other {
                    fmi2Discard => "fmi2Discard",
                    fmi2Error => "fmi2Error",
                    fmi2Fatal => "fmi2Fatal",
                    fmi2Pending => "fmi2Pending",
                    _ => "an unknown status",
                }
                .into(),
                messages: self.take_messages_text(),
            }),
        }
    }

    pub fn setup_experiment(
        &mut self,
        start_time: f64,
        stop_time: Option<f64>,
    ) -> Result<(), ImportError> {
        // SAFETY: `component` is a live instance of this library.
        let status = unsafe {
            (self.api.setup_experiment)(
                self.component,
                fmi2False,
                0.0,
                start_time,
                stop_time.is_some() as fmi2Boolean,
                stop_time.unwrap_or(0.0),
            )
        };
        self.check("fmi2SetupExperiment", status)
    }

    pub fn enter_initialization_mode(&mut self) -> Result<(), ImportError> {
        // SAFETY: as above.
        let status = unsafe { (self.api.enter_initialization_mode)(self.component) };
        self.check("fmi2EnterInitializationMode", status)
    }

    pub fn exit_initialization_mode(&mut self) -> Result<(), ImportError> {
        // SAFETY: as above.
        let status = unsafe { (self.api.exit_initialization_mode)(self.component) };
        self.check("fmi2ExitInitializationMode", status)
    }

    pub fn terminate(&mut self) -> Result<(), ImportError> {
        // SAFETY: as above.
        let status = unsafe { (self.api.terminate)(self.component) };
        self.check("fmi2Terminate", status)
    }

    pub fn reset(&mut self) -> Result<(), ImportError> {
        // SAFETY: as above.
        let status = unsafe { (self.api.reset)(self.component) };
        self.check("fmi2Reset", status)
    }

    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "set_real: one value per value reference"
        );
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.set_real)(self.component, vrs.as_ptr(), vrs.len(), values.as_ptr())
        };
        self.check("fmi2SetReal", status)
    }

    pub fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "get_real: one slot per value reference"
        );
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.get_real)(self.component, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        };
        self.check("fmi2GetReal", status)
    }

    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "set_integer: one value per value reference"
        );
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.set_integer)(self.component, vrs.as_ptr(), vrs.len(), values.as_ptr())
        };
        self.check("fmi2SetInteger", status)
    }

    pub fn get_integer(&mut self, vrs: &[u32], values: &mut [i32]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "get_integer: one slot per value reference"
        );
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.get_integer)(self.component, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        };
        self.check("fmi2GetInteger", status)
    }

    pub fn set_boolean(&mut self, vrs: &[u32], values: &[bool]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "set_boolean: one value per value reference"
        );
        let ints: Vec<fmi2Boolean> = values.iter().map(|&b| b as fmi2Boolean).collect();
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.set_boolean)(self.component, vrs.as_ptr(), vrs.len(), ints.as_ptr())
        };
        self.check("fmi2SetBoolean", status)
    }

    pub fn get_boolean(&mut self, vrs: &[u32], values: &mut [bool]) -> Result<(), ImportError> {
        let mut ints = vec![0 as fmi2Boolean; vrs.len()];
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.get_boolean)(self.component, vrs.as_ptr(), vrs.len(), ints.as_mut_ptr())
        };
        self.check("fmi2GetBoolean", status)?;
        for (slot, i) in values.iter_mut().zip(ints) {
            *slot = i != 0;
        }
        Ok(())
    }

    pub fn can_interpolate_inputs(&self) -> bool {
        self.interpolates
    }

    /// First-order input derivatives for the next step.
    pub fn set_real_input_derivatives(
        &mut self,
        vrs: &[u32],
        slopes: &[f64],
    ) -> Result<(), ImportError> {
        assert_eq!(vrs.len(), slopes.len(), "one slope per value reference");
        let Some(f) = self.api.set_real_input_derivatives else {
            return Err(ImportError::Unsupported {
                instance: self.name.clone(),
                what: "fmi2SetRealInputDerivatives",
            });
        };
        let orders = vec![1 as fmi2Integer; vrs.len()];
        // SAFETY: all slices have vrs.len() elements.
        let status = unsafe {
            f(
                self.component,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                slopes.as_ptr(),
            )
        };
        self.check("fmi2SetRealInputDerivatives", status)
    }

    pub fn do_step(&mut self, time: f64, step_size: f64) -> Result<(), ImportError> {
        match self.step(time, step_size)? {
            StepEnd::Completed => Ok(()),
            StepEnd::Terminated { .. } => Err(ImportError::Call {
                instance: self.name.clone(),
                fmu: self.source.clone(),
                call: "fmi2DoStep",
                status: "fmi2Discard (the FMU ended the simulation)".into(),
                messages: self.take_messages_text(),
            }),
        }
    }

    /// One communication step. An FMU that ends the simulation itself (`fmi2Discard`, then
    /// `fmi2GetBooleanStatus(fmi2Terminated)` true) gives `Terminated` at its last successful
    /// time, as fmpy treats it; any other refusal is an error carrying the FMU's messages.
    pub fn step(&mut self, time: f64, step_size: f64) -> Result<StepEnd, ImportError> {
        // SAFETY: as above.
        let status = unsafe { (self.api.do_step)(self.component, time, step_size, fmi2True) };
        if status == fmi2Discard && self.boolean_status(fmi2Terminated) == Some(true) {
            let at = self
                .real_status(fmi2LastSuccessfulTime)
                .unwrap_or(time + step_size);
            return Ok(StepEnd::Terminated { at });
        }
        self.check("fmi2DoStep", status)?;
        Ok(StepEnd::Completed)
    }

    /// `fmi2GetBooleanStatus`; None when the FMU lacks it or refuses.
    fn boolean_status(&mut self, kind: fmi2StatusKind) -> Option<bool> {
        let f = self.api.get_boolean_status?;
        let mut value: fmi2Boolean = fmi2False;
        // SAFETY: `value` is a valid slot for one fmi2Boolean.
        let status = unsafe { f(self.component, kind, &mut value) };
        matches!(status, fmi2OK | fmi2Warning).then_some(value != fmi2False)
    }

    /// `fmi2GetRealStatus`; None when the FMU lacks it or refuses.
    fn real_status(&mut self, kind: fmi2StatusKind) -> Option<f64> {
        let f = self.api.get_real_status?;
        let mut value: fmi2Real = 0.0;
        // SAFETY: `value` is a valid slot for one fmi2Real.
        let status = unsafe { f(self.component, kind, &mut value) };
        matches!(status, fmi2OK | fmi2Warning).then_some(value)
    }

    pub fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), ImportError> {
        assert_eq!(
            vrs.len(),
            values.len(),
            "set_string: one value per value reference"
        );
        let owned = values
            .iter()
            .map(|v| CString::new(*v))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|_| ImportError::Call {
                instance: self.name.clone(),
                fmu: self.source.clone(),
                call: "fmi2SetString",
                status: "not called: a value contains a NUL byte".into(),
                messages: String::new(),
            })?;
        let pointers: Vec<fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: both slices have vrs.len() elements; the strings outlive the call (the FMU
        // copies what it keeps, as the standard requires).
        let status = unsafe {
            (self.api.set_string)(self.component, vrs.as_ptr(), vrs.len(), pointers.as_ptr())
        };
        self.check("fmi2SetString", status)
    }

    /// The strings are copied out at once: the FMU's buffers are only valid until its next call.
    pub fn get_string(&mut self, vrs: &[u32]) -> Result<Vec<String>, ImportError> {
        let mut pointers: Vec<fmi2String> = vec![std::ptr::null(); vrs.len()];
        // SAFETY: both slices have vrs.len() elements.
        let status = unsafe {
            (self.api.get_string)(
                self.component,
                vrs.as_ptr(),
                vrs.len(),
                pointers.as_mut_ptr(),
            )
        };
        self.check("fmi2GetString", status)?;
        Ok(pointers
            .iter()
            .map(|&p| {
                if p.is_null() {
                    String::new()
                } else {
                    // SAFETY: a non-null fmi2String is NUL-terminated and valid until the next
                    // call into the FMU; it is copied here.
                    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
                }
            })
            .collect())
    }

    /// Save the FMU state (for rollback); the handle stays valid until the instance drops.
    pub fn save_state(&mut self) -> Result<StateHandle, ImportError> {
        let f = self.required(self.api.get_fmu_state, "fmi2GetFMUstate")?;
        let mut state: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `state` is a valid slot; the FMU allocates the state.
        let status = unsafe { f(self.component, &mut state) };
        self.check("fmi2GetFMUstate", status)?;
        self.states.push(state);
        Ok(StateHandle(self.states.len() - 1))
    }

    /// Overwrite a saved state with the current one.
    pub fn update_state(&mut self, handle: StateHandle) -> Result<(), ImportError> {
        let f = self.required(self.api.get_fmu_state, "fmi2GetFMUstate")?;
        let slot = &mut self.states[handle.0];
        // SAFETY: the slot holds a state of this instance; the FMU updates it in place.
        let status = unsafe { f(self.component, slot) };
        self.check("fmi2GetFMUstate", status)
    }

    pub fn restore_state(&mut self, handle: StateHandle) -> Result<(), ImportError> {
        let f = self.required(self.api.set_fmu_state, "fmi2SetFMUstate")?;
        // SAFETY: the handle indexes a state this instance made.
        let status = unsafe { f(self.component, self.states[handle.0]) };
        self.check("fmi2SetFMUstate", status)
    }

    /// The FMU's function `f`, or an error naming the call `what` when the library lacks it.
    fn required<F>(&self, f: Option<F>, what: &'static str) -> Result<F, ImportError> {
        f.ok_or_else(|| ImportError::Unsupported {
            instance: self.name.clone(),
            what,
        })
    }

    /// Refuse a state call the modelDescription does not declare (`what` names the capability).
    fn require_state(&self, serialize: bool) -> Result<(), ImportError> {
        let declared = self.state_capabilities.get_and_set
            && (!serialize || self.state_capabilities.serialize);
        if declared {
            Ok(())
        } else {
            Err(ImportError::Unsupported {
                instance: self.name.clone(),
                what: if serialize {
                    "serialisable FMU states (its modelDescription does not declare \
                     canGetAndSetFMUstate=\"true\" and canSerializeFMUstate=\"true\")"
                } else {
                    "FMU states (its modelDescription does not declare \
                     canGetAndSetFMUstate=\"true\")"
                },
            })
        }
    }

    /// A free slot in `states` (reused after [`Instance::free_state`]), or a new one.
    fn state_slot(&mut self) -> usize {
        match self.states.iter().position(|s| s.is_null()) {
            Some(i) => i,
            None => {
                self.states.push(std::ptr::null_mut());
                self.states.len() - 1
            }
        }
    }

    fn live_state(&self, handle: StateHandle) -> Result<fmi2FMUstate, ImportError> {
        match self.states.get(handle.0) {
            Some(s) if !s.is_null() => Ok(*s),
            _ => Err(ImportError::Call {
                instance: self.name.clone(),
                fmu: self.source.clone(),
                call: "FMU state",
                status: "not called: the state handle was freed or is not this instance's".into(),
                messages: String::new(),
            }),
        }
    }

    /// `fmi2GetFMUstate` into a new state, checked against the modelDescription.
    pub fn get_fmu_state(&mut self) -> Result<StateHandle, ImportError> {
        self.require_state(false)?;
        let f = self.required(self.api.get_fmu_state, "fmi2GetFMUstate")?;
        let slot = self.state_slot();
        let mut state: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `state` is a valid slot holding null; the FMU allocates the state.
        let status = unsafe { f(self.component, &mut state) };
        self.check("fmi2GetFMUstate", status)?;
        self.states[slot] = state;
        Ok(StateHandle(slot))
    }

    /// `fmi2SetFMUstate`, checked against the modelDescription.
    pub fn set_fmu_state(&mut self, handle: StateHandle) -> Result<(), ImportError> {
        self.require_state(false)?;
        let state = self.live_state(handle)?;
        let f = self.required(self.api.set_fmu_state, "fmi2SetFMUstate")?;
        // SAFETY: a live state this instance made.
        let status = unsafe { f(self.component, state) };
        self.check("fmi2SetFMUstate", status)
    }

    /// `fmi2FreeFMUstate`; the handle is invalid afterwards (its slot is reused).
    pub fn free_fmu_state(&mut self, handle: StateHandle) -> Result<(), ImportError> {
        let _ = self.live_state(handle)?;
        let f = self.required(self.api.free_fmu_state, "fmi2FreeFMUstate")?;
        // SAFETY: the slot holds a live state of this instance; the FMU frees it and nulls it.
        let status = unsafe { f(self.component, &mut self.states[handle.0]) };
        self.states[handle.0] = std::ptr::null_mut();
        self.check("fmi2FreeFMUstate", status)
    }

    /// `fmi2SerializedFMUstateSize` then `fmi2SerializeFMUstate`: the state's bytes.
    pub fn serialize_fmu_state(&mut self, handle: StateHandle) -> Result<Vec<u8>, ImportError> {
        self.require_state(true)?;
        let state = self.live_state(handle)?;
        let unsupported = |what| ImportError::Unsupported {
            instance: self.name.clone(),
            what,
        };
        let size_of = self
            .api
            .serialized_fmu_state_size
            .ok_or_else(|| unsupported("fmi2SerializedFMUstateSize"))?;
        let serialize = self
            .api
            .serialize_fmu_state
            .ok_or_else(|| unsupported("fmi2SerializeFMUstate"))?;
        let mut size = 0usize;
        // SAFETY: a live state of this instance; `size` is writable.
        let status = unsafe { size_of(self.component, state, &mut size) };
        self.check("fmi2SerializedFMUstateSize", status)?;
        let mut bytes = vec![0u8; size];
        // SAFETY: `bytes` has `size` writable bytes.
        let status = unsafe {
            serialize(
                self.component,
                state,
                bytes.as_mut_ptr() as *mut fmi2Byte,
                size,
            )
        };
        self.check("fmi2SerializeFMUstate", status)?;
        Ok(bytes)
    }

    /// `fmi2DeSerializeFMUstate`: a new state from bytes [`Instance::serialize_fmu_state`] gave
    /// (of an instance of the same FMU).
    pub fn deserialize_fmu_state(&mut self, bytes: &[u8]) -> Result<StateHandle, ImportError> {
        self.require_state(true)?;
        let f = self.required(self.api.deserialize_fmu_state, "fmi2DeSerializeFMUstate")?;
        let slot = self.state_slot();
        let mut state: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `bytes` has bytes.len() readable bytes; `state` is a valid slot.
        let status = unsafe {
            f(
                self.component,
                bytes.as_ptr() as *const fmi2Byte,
                bytes.len(),
                &mut state,
            )
        };
        self.check("fmi2DeSerializeFMUstate", status)?;
        self.states[slot] = state;
        Ok(StateHandle(slot))
    }

    /// The instance's current state as bytes (get, serialise, free).
    pub fn state_bytes(&mut self) -> Result<Vec<u8>, ImportError> {
        let handle = self.get_fmu_state()?;
        let bytes = self.serialize_fmu_state(handle);
        let freed = self.free_fmu_state(handle);
        let bytes = bytes?;
        freed?;
        Ok(bytes)
    }

    /// Put the instance in the state `bytes` hold (deserialise, set, free).
    pub fn restore_state_bytes(&mut self, bytes: &[u8]) -> Result<(), ImportError> {
        let handle = self.deserialize_fmu_state(bytes)?;
        let set = self.set_fmu_state(handle);
        let freed = self.free_fmu_state(handle);
        set?;
        freed
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        if self.component.is_null() {
            return;
        }
        if let Some(free_state) = self.api.free_fmu_state {
            for state in self.states.iter_mut().filter(|s| !s.is_null()) {
                // SAFETY: each state came from this instance and is freed once.
                unsafe { free_state(self.component, state) };
            }
        }
        // SAFETY: the component is live and freed exactly once; the log and callbacks outlive it.
        unsafe { (self.api.free_instance)(self.component) };
    }
}

#[cfg(test)]
mod tests {
    use super::file_uri;
    use std::path::Path;

    #[test]
    fn resource_uris_are_percent_encoded_per_rfc_3986() {
        assert_eq!(
            file_uri(Path::new("/tmp/a/resources")),
            "file:///tmp/a/resources"
        );
        assert_eq!(
            file_uri(Path::new("/tmp/my dir/100%/#1?/résumé/resources")),
            "file:///tmp/my%20dir/100%25/%231%3F/r%C3%A9sum%C3%A9/resources"
        );
        assert_eq!(file_uri(Path::new("/a~b_c-d.e")), "file:///a~b_c-d.e");
    }
}
