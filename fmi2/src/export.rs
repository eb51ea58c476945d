//! The 34 FMI 2.0 co-simulation functions, generic over the model. `export_fmu!` instantiates
//! them with `#[no_mangle]` names in the FMU's cdylib.
//!
//! Every function runs inside `catch_unwind`: a panic in a model becomes `fmi2Fatal` and a log
//! message, never an unwind into the host. A refused call (wrong state, null pointer, unknown
//! value reference, non-finite value) returns `fmi2Error`, says why through the logger and has
//! no effect: the instance stays in its state and loses nothing. A failure of the model itself
//! (a diverging step) returns `fmi2Error` and moves the instance to the Error state, from which
//! `fmi2SetFMUstate`, `fmi2Reset` or `fmi2FreeInstance` recover.
#![allow(non_upper_case_globals)]

use std::any::Any;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::abi::*;
use crate::instance::{
    from_c_str, mask, resource_dir_from_uri, FsmState, Instance, Logger, Snapshot,
};
use crate::model::{CoSimModel, InstantiateContext, ModelError};
use crate::variables::{Causality, VarType};

/// Outcome of a call body: `Refused` leaves the instance as it was; `Failed` puts it in Error.
pub(crate) enum CallError {
    Refused(String),
    Failed(String),
}

impl From<ModelError> for CallError {
    fn from(e: ModelError) -> Self {
        match e {
            ModelError::Diverged { .. } | ModelError::Other(_) => CallError::Failed(e.to_string()),
            ModelError::UnknownVariable { .. } | ModelError::InvalidValue { .. } => {
                CallError::Refused(e.to_string())
            }
        }
    }
}

type CallResult = Result<fmi2Status, CallError>;

fn refuse<T>(message: impl Into<String>) -> Result<T, CallError> {
    Err(CallError::Refused(message.into()))
}

fn panic_text(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic with a non-text payload".to_owned()
    }
}

/// Run `body` on the instance behind `c` if its state is in `allowed`; map errors and panics.
fn with_instance<M: CoSimModel>(
    c: fmi2Component,
    call: &'static str,
    allowed: u8,
    body: impl FnOnce(&mut Instance<M>) -> CallResult,
) -> fmi2Status {
    let outcome = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: the host passes what fmi2Instantiate returned; from_ptr checks null and magic.
        let Some(inst) = (unsafe { Instance::<M>::from_ptr(c) }) else {
            return fmi2Error;
        };
        if inst.state == FsmState::Fatal && call != "fmi2FreeFMUstate" {
            inst.log(
                fmi2Fatal,
                &format!(
                    "{call}: the instance had a fatal error; only fmi2FreeInstance is allowed"
                ),
            );
            return fmi2Error;
        }
        if allowed & inst.state.bit() == 0 {
            inst.log(
                fmi2Error,
                &format!(
                    "{call}: not allowed in state {}; expected state {}",
                    inst.state.name(),
                    FsmState::names_in(allowed)
                ),
            );
            return fmi2Error;
        }
        if inst.logger.logs_calls() {
            inst.log(fmi2OK, call);
        }
        match body(inst) {
            Ok(status) => status,
            Err(CallError::Refused(message)) => {
                inst.log(fmi2Error, &format!("{call}: {message}"));
                fmi2Error
            }
            Err(CallError::Failed(message)) => {
                inst.log(fmi2Error, &format!("{call}: {message}"));
                inst.state = FsmState::Error;
                fmi2Error
            }
        }
    }));
    outcome.unwrap_or_else(|payload| {
        let text = panic_text(payload.as_ref());
        // The body has unwound, so no borrow of the instance is alive any more.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            // SAFETY: as above.
            if let Some(inst) = unsafe { Instance::<M>::from_ptr(c) } {
                inst.state = FsmState::Fatal;
                inst.log(fmi2Fatal, &format!("{call}: the model panicked: {text}"));
            }
        }));
        fmi2Fatal
    })
}

/// A slice from a C array; `None` when the pointer is null but `n > 0`.
///
/// # Safety
/// A non-null `ptr` must point to `n` readable elements.
unsafe fn c_slice<'a, T>(ptr: *const T, n: usize) -> Option<&'a [T]> {
    if n == 0 {
        Some(&[])
    } else if ptr.is_null() {
        None
    } else {
        // SAFETY: promised by the caller.
        Some(unsafe { std::slice::from_raw_parts(ptr, n) })
    }
}

/// # Safety
/// As `c_slice`, writable.
unsafe fn c_slice_mut<'a, T>(ptr: *mut T, n: usize) -> Option<&'a mut [T]> {
    if n == 0 {
        Some(&mut [])
    } else if ptr.is_null() {
        None
    } else {
        // SAFETY: promised by the caller.
        Some(unsafe { std::slice::from_raw_parts_mut(ptr, n) })
    }
}

fn lookup<M: CoSimModel>(
    model: &M,
    var_type: VarType,
    vr: u32,
) -> Result<&'static crate::variables::Variable, CallError> {
    model.table().find(var_type, vr).ok_or_else(|| {
        CallError::Refused(format!(
            "unknown value reference {vr} for a {} variable",
            var_type.xml_name()
        ))
    })
}

/// Hand a batch of values to the model, whole or not at all. With more than one value, the
/// current values are read first; if the model refuses one, those already set are put back (in
/// reverse order, so a reference named twice ends at its value from before the call).
fn set_all<M: CoSimModel, T>(
    model: &mut M,
    vrs: &[u32],
    values: &[T],
    get: impl Fn(&mut M, u32) -> Result<T, ModelError>,
    set: impl Fn(&mut M, u32, &T) -> Result<(), ModelError>,
) -> Result<(), CallError> {
    let previous = if vrs.len() > 1 {
        vrs.iter()
            .map(|&vr| get(model, vr))
            .collect::<Result<Vec<T>, _>>()?
    } else {
        Vec::new()
    };
    for (i, (&vr, value)) in vrs.iter().zip(values).enumerate() {
        if let Err(e) = set(model, vr, value) {
            for (&vr, old) in vrs[..i].iter().zip(&previous).rev() {
                let _ = set(model, vr, old);
            }
            return Err(e.into());
        }
    }
    Ok(())
}

/// Check that every value reference may be set now, before any is: a batch is set whole or not at all.
fn check_settable<M: CoSimModel>(
    inst: &Instance<M>,
    var_type: VarType,
    vrs: &[u32],
) -> Result<(), CallError> {
    let initialized = matches!(inst.state, FsmState::StepComplete);
    for &vr in vrs {
        let var = lookup(&inst.model, var_type, vr)?;
        var.settable(initialized).map_err(CallError::Refused)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Functions without an instance

pub fn get_types_platform() -> fmi2String {
    TYPES_PLATFORM.as_ptr()
}

pub fn get_version() -> fmi2String {
    VERSION.as_ptr()
}

/// # Safety
/// Pointers as the FMI 2.0 standard defines them for `fmi2Instantiate`.
pub unsafe fn instantiate<M: CoSimModel>(
    instance_name: fmi2String,
    fmu_type: fmi2Type,
    guid: fmi2String,
    resource_location: fmi2String,
    functions: *const fmi2CallbackFunctions,
    _visible: fmi2Boolean,
    logging_on: fmi2Boolean,
) -> fmi2Component {
    catch_unwind(AssertUnwindSafe(|| {
        if functions.is_null() {
            return std::ptr::null_mut();
        }
        // SAFETY: non-null, and the host passes a valid callback structure; copied, not kept.
        let callbacks = unsafe { *functions };
        // SAFETY: NUL-terminated strings from the host, or null.
        let name = unsafe { from_c_str(instance_name) }.unwrap_or_default();
        let context = InstantiateContext {
            instance_name: if name.is_empty() {
                "(unnamed)".to_owned()
            } else {
                name.clone()
            },
            // SAFETY: as above.
            resource_dir: unsafe { from_c_str(resource_location) }
                .as_deref()
                .and_then(resource_dir_from_uri),
        };
        // A throw-away instance carries the logger for the messages before the model exists.
        let logger = Logger::new(&context.instance_name, callbacks, logging_on != 0);
        let logger_only = |message: &str| logger.log(fmi2Error, message);
        if name.is_empty() {
            logger_only("fmi2Instantiate: instanceName is null or empty");
            return std::ptr::null_mut();
        }
        if fmu_type != fmi2CoSimulation {
            logger_only(&format!(
                "fmi2Instantiate: this FMU supports co-simulation only (fmuType was {fmu_type})"
            ));
            return std::ptr::null_mut();
        }
        // The model first: its table (and so the GUID the host must pass) may depend on what
        // it reads from its resources.
        let model = match M::instantiate(&context) {
            Ok(model) => model,
            Err(e) => {
                logger_only(&format!("fmi2Instantiate: {e}"));
                return std::ptr::null_mut();
            }
        };
        let expected = &model.table().guid;
        // SAFETY: as above.
        match unsafe { from_c_str(guid) } {
            Some(g) if g == *expected => {}
            other => {
                logger_only(&format!(
                    "fmi2Instantiate: GUID mismatch: expected {expected} but was {}",
                    other.unwrap_or_else(|| "null".into())
                ));
                return std::ptr::null_mut();
            }
        }
        Instance::new(context, logger, model).into_ptr()
    }))
    .unwrap_or_else(|payload| {
        let text = panic_text(payload.as_ref());
        // The host still hears why there is no instance; a second panic stays here too.
        let _ = catch_unwind(AssertUnwindSafe(|| {
            if !functions.is_null() {
                // SAFETY: as above.
                let callbacks = unsafe { *functions };
                let name = unsafe { from_c_str(instance_name) }.unwrap_or_default();
                Logger::new(&name, callbacks, logging_on != 0).log(
                    fmi2Fatal,
                    &format!("fmi2Instantiate: the model panicked: {text}"),
                );
            }
        }));
        std::ptr::null_mut()
    })
}

/// # Safety
/// `c` is null or from `fmi2Instantiate`; it is dangling afterwards.
pub unsafe fn free_instance<M: CoSimModel>(c: fmi2Component) {
    // SAFETY: as documented; a panic in a model's Drop stays here.
    let _ = catch_unwind(AssertUnwindSafe(|| unsafe { Instance::<M>::free(c) }));
}

// ---------------------------------------------------------------------------------------------
// Life cycle

/// # Safety
/// `categories` points to `n` C strings (or is null when `n == 0`).
pub unsafe fn set_debug_logging<M: CoSimModel>(
    c: fmi2Component,
    logging_on: fmi2Boolean,
    n: usize,
    categories: *const fmi2String,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetDebugLogging", mask::ANY_LIVE, |inst| {
        // SAFETY: promised by the caller.
        let Some(list) = (unsafe { c_slice(categories, n) }) else {
            return refuse("categories is null but nCategories > 0");
        };
        let mut names = Vec::with_capacity(n);
        for &p in list {
            // SAFETY: each entry is a C string or null.
            match unsafe { from_c_str(p) } {
                Some(s) => names.push(s),
                None => return refuse("a category name is null"),
            }
        }
        inst.logger
            .set_debug_logging(logging_on != 0, &names)
            .map_err(CallError::Refused)?;
        Ok(fmi2OK)
    })
}

pub fn setup_experiment<M: CoSimModel>(
    c: fmi2Component,
    _tolerance_defined: fmi2Boolean,
    _tolerance: fmi2Real,
    start_time: fmi2Real,
    stop_time_defined: fmi2Boolean,
    stop_time: fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetupExperiment", mask::SETUP_EXPERIMENT, |inst| {
        if !start_time.is_finite() {
            return refuse(format!("startTime must be finite, was {start_time}"));
        }
        let stop = if stop_time_defined != 0 {
            if !(stop_time.is_finite() && stop_time >= start_time) {
                return refuse(format!(
                    "stopTime must be finite and ≥ startTime {start_time}, was {stop_time}"
                ));
            }
            Some(stop_time)
        } else {
            None
        };
        inst.time = start_time;
        inst.stop_time = stop;
        Ok(fmi2OK)
    })
}

pub fn enter_initialization_mode<M: CoSimModel>(c: fmi2Component) -> fmi2Status {
    with_instance::<M>(
        c,
        "fmi2EnterInitializationMode",
        mask::ENTER_INITIALIZATION,
        |inst| {
            inst.state = FsmState::InitializationMode;
            Ok(fmi2OK)
        },
    )
}

pub fn exit_initialization_mode<M: CoSimModel>(c: fmi2Component) -> fmi2Status {
    with_instance::<M>(
        c,
        "fmi2ExitInitializationMode",
        mask::EXIT_INITIALIZATION,
        |inst| {
            // Parameters that do not fit together are a refused call: the host may fix them and retry.
            inst.model
                .exit_initialization()
                .map_err(|e| CallError::Refused(e.to_string()))?;
            inst.state = FsmState::StepComplete;
            Ok(fmi2OK)
        },
    )
}

pub fn terminate<M: CoSimModel>(c: fmi2Component) -> fmi2Status {
    with_instance::<M>(c, "fmi2Terminate", mask::TERMINATE, |inst| {
        inst.state = FsmState::Terminated;
        Ok(fmi2OK)
    })
}

pub fn reset<M: CoSimModel>(c: fmi2Component) -> fmi2Status {
    with_instance::<M>(c, "fmi2Reset", mask::ANY_LIVE, |inst| {
        inst.model.reset(&inst.context)?;
        inst.time = 0.0;
        inst.stop_time = None;
        inst.state = FsmState::Instantiated;
        Ok(fmi2OK)
    })
}

// ---------------------------------------------------------------------------------------------
// Getting and setting values

macro_rules! getter {
    ($fn_name:ident, $c_name:literal, $ctype:ty, $var_type:expr, |$model:ident, $vr:ident| $get:expr) => {
        /// # Safety
        /// `vr` and `value` point to `n` elements (or are null when `n == 0`).
        pub unsafe fn $fn_name<M: CoSimModel>(
            c: fmi2Component,
            vr: *const fmi2ValueReference,
            n: usize,
            value: *mut $ctype,
        ) -> fmi2Status {
            with_instance::<M>(c, $c_name, mask::GET, |inst| {
                // SAFETY: promised by the caller.
                let (Some(vrs), Some(out)) =
                    (unsafe { c_slice(vr, n) }, unsafe { c_slice_mut(value, n) })
                else {
                    return refuse("vr or value is null but nvr > 0");
                };
                for &$vr in vrs {
                    lookup(&inst.model, $var_type, $vr)?;
                }
                let $model = &mut inst.model;
                for (slot, &$vr) in out.iter_mut().zip(vrs) {
                    *slot = $get;
                }
                Ok(fmi2OK)
            })
        }
    };
}

/// # Safety
/// `vr` and `value` point to `n` elements (or are null when `n == 0`).
pub unsafe fn get_real<M: CoSimModel>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *mut fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetReal", mask::GET, |inst| {
        // SAFETY: promised by the caller.
        let (Some(vrs), Some(out)) = (unsafe { c_slice(vr, n) }, unsafe { c_slice_mut(value, n) })
        else {
            return refuse("vr or value is null but nvr > 0");
        };
        for &vr in vrs {
            lookup(&inst.model, VarType::Real, vr)?;
        }
        inst.model.get_reals(vrs, out)?;
        Ok(fmi2OK)
    })
}
getter!(
    get_integer,
    "fmi2GetInteger",
    fmi2Integer,
    VarType::Integer,
    |model, vr| model.get_integer(vr)?
);
getter!(
    get_boolean,
    "fmi2GetBoolean",
    fmi2Boolean,
    VarType::Boolean,
    |model, vr| {
        if model.get_boolean(vr)? {
            fmi2True
        } else {
            fmi2False
        }
    }
);

/// # Safety
/// As the getters. The returned strings stay valid until the next call on this instance.
pub unsafe fn get_string<M: CoSimModel>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *mut fmi2String,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetString", mask::GET, |inst| {
        // SAFETY: promised by the caller.
        let (Some(vrs), Some(out)) = (unsafe { c_slice(vr, n) }, unsafe { c_slice_mut(value, n) })
        else {
            return refuse("vr or value is null but nvr > 0");
        };
        let mut strings = Vec::with_capacity(n);
        for &r in vrs {
            lookup(&inst.model, VarType::String, r)?;
            strings.push(crate::instance::to_c_string(&inst.model.get_string(r)?));
        }
        inst.string_buffer = strings;
        for (slot, s) in out.iter_mut().zip(&inst.string_buffer) {
            *slot = s.as_ptr();
        }
        Ok(fmi2OK)
    })
}

/// # Safety
/// `vr` and `value` point to `n` elements (or are null when `n == 0`).
pub unsafe fn set_real<M: CoSimModel>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *const fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetReal", mask::SET, |inst| {
        // SAFETY: promised by the caller.
        let (Some(vrs), Some(values)) = (unsafe { c_slice(vr, n) }, unsafe { c_slice(value, n) })
        else {
            return refuse("vr or value is null but nvr > 0");
        };
        check_settable(inst, VarType::Real, vrs)?;
        for (&r, &x) in vrs.iter().zip(values) {
            if !x.is_finite() {
                let name = &lookup(&inst.model, VarType::Real, r)?.name;
                return refuse(format!(
                    "value of '{name}' (vr {r}) is {x}; only finite reals are accepted"
                ));
            }
        }
        set_all(&mut inst.model, vrs, values, M::get_real, |m, r, &x| {
            m.set_real(r, x)
        })?;
        Ok(fmi2OK)
    })
}

macro_rules! setter {
    ($fn_name:ident, $c_name:literal, $ctype:ty, $var_type:expr, $convert:expr, $get:expr, $set:expr) => {
        /// # Safety
        /// `vr` and `value` point to `n` elements (or are null when `n == 0`).
        pub unsafe fn $fn_name<M: CoSimModel>(
            c: fmi2Component,
            vr: *const fmi2ValueReference,
            n: usize,
            value: *const $ctype,
        ) -> fmi2Status {
            with_instance::<M>(c, $c_name, mask::SET, |inst| {
                // SAFETY: promised by the caller.
                let (Some(vrs), Some(values)) =
                    (unsafe { c_slice(vr, n) }, unsafe { c_slice(value, n) })
                else {
                    return refuse("vr or value is null but nvr > 0");
                };
                check_settable(inst, $var_type, vrs)?;
                let values: Vec<_> = values.iter().map($convert).collect();
                set_all(&mut inst.model, vrs, &values, $get, $set)?;
                Ok(fmi2OK)
            })
        }
    };
}

setter!(
    set_integer,
    "fmi2SetInteger",
    fmi2Integer,
    VarType::Integer,
    |&x: &fmi2Integer| x,
    M::get_integer,
    |m: &mut M, vr, &x| m.set_integer(vr, x)
);
setter!(
    set_boolean,
    "fmi2SetBoolean",
    fmi2Boolean,
    VarType::Boolean,
    |&x: &fmi2Boolean| x != 0,
    M::get_boolean,
    |m: &mut M, vr, &x| m.set_boolean(vr, x)
);

/// # Safety
/// As the setters; each string is NUL-terminated.
pub unsafe fn set_string<M: CoSimModel>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *const fmi2String,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetString", mask::SET, |inst| {
        // SAFETY: promised by the caller.
        let (Some(vrs), Some(values)) = (unsafe { c_slice(vr, n) }, unsafe { c_slice(value, n) })
        else {
            return refuse("vr or value is null but nvr > 0");
        };
        check_settable(inst, VarType::String, vrs)?;
        let mut texts = Vec::with_capacity(n);
        for &p in values {
            // SAFETY: promised by the caller.
            match unsafe { from_c_str(p) } {
                Some(s) => texts.push(s),
                None => return refuse("a string value is null"),
            }
        }
        set_all(&mut inst.model, vrs, &texts, M::get_string, |m, r, text| {
            m.set_string(r, text)
        })?;
        Ok(fmi2OK)
    })
}

// ---------------------------------------------------------------------------------------------
// FMU state

/// # Safety
/// `state` points to an `fmi2FMUstate` slot: null, or a state from this instance's library.
pub unsafe fn get_fmu_state<M: CoSimModel>(
    c: fmi2Component,
    state: *mut fmi2FMUstate,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetFMUstate", mask::GET_STATE, |inst| {
        if state.is_null() {
            return refuse("FMUstate is null");
        }
        // SAFETY: non-null slot from the host.
        let slot = unsafe { &mut *state };
        if slot.is_null() {
            *slot = inst.snapshot().into_ptr();
        } else {
            // SAFETY: the host passes back a state it got from this library.
            match unsafe { Snapshot::<M>::from_ptr(*slot) } {
                Some(existing) => *existing = inst.snapshot(),
                None => return refuse("FMUstate does not point to a state of this FMU"),
            }
        }
        Ok(fmi2OK)
    })
}

/// # Safety
/// `state` is a state from `fmi2GetFMUstate` or `fmi2DeSerializeFMUstate` of this library.
pub unsafe fn set_fmu_state<M: CoSimModel>(c: fmi2Component, state: fmi2FMUstate) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetFMUstate", mask::SET_STATE, |inst| {
        // SAFETY: promised by the caller; from_ptr checks null and magic.
        match unsafe { Snapshot::<M>::from_ptr(state) } {
            Some(snapshot) if snapshot.guid() != inst.model.table().guid => refuse(format!(
                "FMUstate is of a model with GUID {} but this instance's is {}",
                snapshot.guid(),
                inst.model.table().guid
            )),
            Some(snapshot) => {
                inst.restore(snapshot);
                Ok(fmi2OK)
            }
            None => refuse("FMUstate is null or not a state of this FMU"),
        }
    })
}

/// # Safety
/// `state` points to a slot holding null or a state of this library; the slot is nulled.
pub unsafe fn free_fmu_state<M: CoSimModel>(
    c: fmi2Component,
    state: *mut fmi2FMUstate,
) -> fmi2Status {
    // Allowed after a fatal error too, so the host can release what it holds.
    with_instance::<M>(
        c,
        "fmi2FreeFMUstate",
        mask::ANY_LIVE | FsmState::Fatal.bit(),
        |_inst| {
            if state.is_null() {
                return refuse("FMUstate is null");
            }
            // SAFETY: non-null slot from the host; the state is freed once and the slot nulled.
            unsafe {
                Snapshot::<M>::free(*state);
                *state = std::ptr::null_mut();
            }
            Ok(fmi2OK)
        },
    )
}

/// # Safety
/// `state` is a state of this library; `size` is writable.
pub unsafe fn serialized_fmu_state_size<M: CoSimModel>(
    c: fmi2Component,
    state: fmi2FMUstate,
    size: *mut usize,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SerializedFMUstateSize", mask::ANY_LIVE, |_inst| {
        // SAFETY: promised by the caller.
        let Some(snapshot) = (unsafe { Snapshot::<M>::from_ptr(state) }) else {
            return refuse("FMUstate is null or not a state of this FMU");
        };
        if size.is_null() {
            return refuse("size is null");
        }
        let bytes = snapshot.to_bytes().map_err(CallError::Refused)?;
        // SAFETY: non-null, writable.
        unsafe { *size = bytes.len() };
        Ok(fmi2OK)
    })
}

/// # Safety
/// `bytes` points to `size` writable bytes.
pub unsafe fn serialize_fmu_state<M: CoSimModel>(
    c: fmi2Component,
    state: fmi2FMUstate,
    bytes: *mut fmi2Byte,
    size: usize,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SerializeFMUstate", mask::ANY_LIVE, |_inst| {
        // SAFETY: promised by the caller.
        let Some(snapshot) = (unsafe { Snapshot::<M>::from_ptr(state) }) else {
            return refuse("FMUstate is null or not a state of this FMU");
        };
        let data = snapshot.to_bytes().map_err(CallError::Refused)?;
        if data.len() > size {
            return refuse(format!(
                "the buffer has {size} bytes but the state needs {}",
                data.len()
            ));
        }
        // SAFETY: promised by the caller; data.len() ≤ size.
        let Some(out) = (unsafe { c_slice_mut(bytes as *mut u8, data.len()) }) else {
            return refuse("serializedState is null");
        };
        out.copy_from_slice(&data);
        Ok(fmi2OK)
    })
}

/// # Safety
/// `bytes` points to `size` readable bytes; `state` is a writable slot.
pub unsafe fn deserialize_fmu_state<M: CoSimModel>(
    c: fmi2Component,
    bytes: *const fmi2Byte,
    size: usize,
    state: *mut fmi2FMUstate,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2DeSerializeFMUstate", mask::ANY_LIVE, |inst| {
        // SAFETY: promised by the caller.
        let Some(data) = (unsafe { c_slice(bytes as *const u8, size) }) else {
            return refuse("serializedState is null but size > 0");
        };
        if state.is_null() {
            return refuse("FMUstate is null");
        }
        let snapshot = Snapshot::<M>::from_bytes(data, &inst.model.table().guid)
            .map_err(CallError::Refused)?;
        // SAFETY: non-null slot; an older state in it is replaced (and freed) as the standard allows.
        unsafe {
            Snapshot::<M>::free(*state);
            *state = snapshot.into_ptr();
        }
        Ok(fmi2OK)
    })
}

// ---------------------------------------------------------------------------------------------
// Co-simulation

/// # Safety
/// `vr`, `order` and `value` point to `n` elements.
pub unsafe fn set_real_input_derivatives<M: CoSimModel>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    order: *const fmi2Integer,
    value: *const fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2SetRealInputDerivatives", mask::SET, |inst| {
        if !inst.model.table().can_interpolate_inputs {
            return refuse("this FMU cannot interpolate inputs (canInterpolateInputs=\"false\")");
        }
        // SAFETY: promised by the caller.
        let (Some(vrs), Some(orders), Some(values)) = (
            unsafe { c_slice(vr, n) },
            unsafe { c_slice(order, n) },
            unsafe { c_slice(value, n) },
        ) else {
            return refuse("vr, order or value is null but nvr > 0");
        };
        for ((&r, &k), &x) in vrs.iter().zip(orders).zip(values) {
            let var = lookup(&inst.model, VarType::Real, r)?;
            if var.causality != Causality::Input {
                return refuse(format!("'{}' (vr {r}) is not an input", var.name));
            }
            if k != 1 {
                return refuse(format!(
                    "derivative order {k} for '{}': only order 1 is supported",
                    var.name
                ));
            }
            if !x.is_finite() {
                return refuse(format!(
                    "derivative of '{}' is {x}; only finite reals are accepted",
                    var.name
                ));
            }
        }
        for (&r, &x) in vrs.iter().zip(values) {
            inst.model.set_real_input_derivative(r, x)?;
        }
        Ok(fmi2OK)
    })
}

/// # Safety
/// As the getters.
pub unsafe fn get_real_output_derivatives<M: CoSimModel>(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    _n: usize,
    _order: *const fmi2Integer,
    _value: *mut fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetRealOutputDerivatives", mask::GET, |_inst| {
        refuse("output derivatives are not provided (maxOutputDerivativeOrder=\"0\")")
    })
}

/// Steps must follow each other: the tolerance on `currentCommunicationPoint` covers the rounding
/// of a host that accumulates its time, not a gap.
fn time_tolerance(time: f64, step: f64) -> f64 {
    1e-9 * time.abs().max(1.0) + 1e-6 * step
}

pub fn do_step<M: CoSimModel>(
    c: fmi2Component,
    current_communication_point: fmi2Real,
    communication_step_size: fmi2Real,
    _no_set_fmu_state_prior: fmi2Boolean,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2DoStep", mask::DO_STEP, |inst| {
        let (t, h) = (current_communication_point, communication_step_size);
        if !(h.is_finite() && h > 0.0) {
            return refuse(format!(
                "communicationStepSize must be > 0 and finite, was {h}"
            ));
        }
        if !t.is_finite() || (t - inst.time).abs() > time_tolerance(inst.time, h) {
            return refuse(format!(
                "expected currentCommunicationPoint = {} but was {t}",
                inst.time
            ));
        }
        if let Some(stop) = inst.stop_time {
            if t + h > stop + time_tolerance(stop, h) {
                return refuse(format!("the step to {} goes past stopTime = {stop}", t + h));
            }
        }
        inst.model.do_step(t, h)?;
        inst.time = t + h;
        Ok(fmi2OK)
    })
}

pub fn cancel_step<M: CoSimModel>(c: fmi2Component) -> fmi2Status {
    with_instance::<M>(c, "fmi2CancelStep", mask::STATUS, |_inst| {
        refuse("fmi2DoStep runs synchronously; there is no pending step to cancel")
    })
}

/// # Safety
/// `value` is writable.
pub unsafe fn get_status<M: CoSimModel>(
    c: fmi2Component,
    kind: fmi2StatusKind,
    value: *mut fmi2Status,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetStatus", mask::STATUS, |_inst| {
        if value.is_null() {
            return refuse("value is null");
        }
        match kind {
            fmi2DoStepStatus => {
                // SAFETY: non-null, writable.
                unsafe { *value = fmi2OK };
                Ok(fmi2OK)
            }
            _ => Ok(fmi2Discard),
        }
    })
}

/// # Safety
/// `value` is writable.
pub unsafe fn get_real_status<M: CoSimModel>(
    c: fmi2Component,
    kind: fmi2StatusKind,
    value: *mut fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetRealStatus", mask::STATUS, |inst| {
        if value.is_null() {
            return refuse("value is null");
        }
        match kind {
            fmi2LastSuccessfulTime => {
                // SAFETY: non-null, writable.
                unsafe { *value = inst.time };
                Ok(fmi2OK)
            }
            _ => Ok(fmi2Discard),
        }
    })
}

/// # Safety
/// `value` is writable.
pub unsafe fn get_integer_status<M: CoSimModel>(
    c: fmi2Component,
    _kind: fmi2StatusKind,
    _value: *mut fmi2Integer,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetIntegerStatus", mask::STATUS, |_inst| {
        Ok(fmi2Discard)
    })
}

/// # Safety
/// `value` is writable.
pub unsafe fn get_boolean_status<M: CoSimModel>(
    c: fmi2Component,
    kind: fmi2StatusKind,
    value: *mut fmi2Boolean,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetBooleanStatus", mask::STATUS, |inst| {
        if value.is_null() {
            return refuse("value is null");
        }
        match kind {
            fmi2Terminated => {
                // SAFETY: non-null, writable.
                unsafe {
                    *value = if inst.state == FsmState::Terminated {
                        fmi2True
                    } else {
                        fmi2False
                    }
                };
                Ok(fmi2OK)
            }
            _ => Ok(fmi2Discard),
        }
    })
}

/// # Safety
/// `value` is writable.
pub unsafe fn get_string_status<M: CoSimModel>(
    c: fmi2Component,
    _kind: fmi2StatusKind,
    _value: *mut fmi2String,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetStringStatus", mask::STATUS, |_inst| {
        Ok(fmi2Discard)
    })
}

/// # Safety
/// Arrays as the standard defines them.
pub unsafe fn get_directional_derivative<M: CoSimModel>(
    c: fmi2Component,
    _unknown: *const fmi2ValueReference,
    _n_unknown: usize,
    _known: *const fmi2ValueReference,
    _n_known: usize,
    _dv_known: *const fmi2Real,
    _dv_unknown: *mut fmi2Real,
) -> fmi2Status {
    with_instance::<M>(c, "fmi2GetDirectionalDerivative", mask::GET, |_inst| {
        refuse("directional derivatives are not provided (providesDirectionalDerivative=\"false\")")
    })
}
