//! The FMI 2.0 C ABI types, as `fmi2TypesPlatform.h` and `fmi2FunctionTypes.h` declare them.
//!
//! Written here (not taken from `fmi-sys`) so a normal build needs no libclang; a test checks
//! every exported signature against `fmi-sys`'s bindgen typedefs.
#![allow(non_camel_case_types, non_upper_case_globals)]

use std::ffi::{c_char, c_int, c_uint, c_void};

pub type fmi2Component = *mut c_void;
pub type fmi2ComponentEnvironment = *mut c_void;
pub type fmi2FMUstate = *mut c_void;
pub type fmi2ValueReference = c_uint;
pub type fmi2Real = f64;
pub type fmi2Integer = c_int;
pub type fmi2Boolean = c_int;
pub type fmi2Char = c_char;
pub type fmi2String = *const fmi2Char;
pub type fmi2Byte = c_char;

pub type fmi2Status = c_uint;
pub const fmi2OK: fmi2Status = 0;
pub const fmi2Warning: fmi2Status = 1;
pub const fmi2Discard: fmi2Status = 2;
pub const fmi2Error: fmi2Status = 3;
pub const fmi2Fatal: fmi2Status = 4;
pub const fmi2Pending: fmi2Status = 5;

pub type fmi2Type = c_uint;
pub const fmi2ModelExchange: fmi2Type = 0;
pub const fmi2CoSimulation: fmi2Type = 1;

pub type fmi2StatusKind = c_uint;
pub const fmi2DoStepStatus: fmi2StatusKind = 0;
pub const fmi2PendingStatus: fmi2StatusKind = 1;
pub const fmi2LastSuccessfulTime: fmi2StatusKind = 2;
pub const fmi2Terminated: fmi2StatusKind = 3;

pub const fmi2True: fmi2Boolean = 1;
pub const fmi2False: fmi2Boolean = 0;

/// The host's logger. C-variadic: the layer always calls it with the format `"%s"`.
pub type fmi2CallbackLogger = Option<
    unsafe extern "C" fn(
        component_environment: fmi2ComponentEnvironment,
        instance_name: fmi2String,
        status: fmi2Status,
        category: fmi2String,
        message: fmi2String,
        ...
    ),
>;
pub type fmi2CallbackAllocateMemory =
    Option<unsafe extern "C" fn(nobj: usize, size: usize) -> *mut c_void>;
pub type fmi2CallbackFreeMemory = Option<unsafe extern "C" fn(obj: *mut c_void)>;
pub type fmi2StepFinished = Option<
    unsafe extern "C" fn(component_environment: fmi2ComponentEnvironment, status: fmi2Status),
>;

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct fmi2CallbackFunctions {
    pub logger: fmi2CallbackLogger,
    pub allocate_memory: fmi2CallbackAllocateMemory,
    pub free_memory: fmi2CallbackFreeMemory,
    pub step_finished: fmi2StepFinished,
    pub component_environment: fmi2ComponentEnvironment,
}

pub const TYPES_PLATFORM: &std::ffi::CStr = c"default";
pub const VERSION: &std::ffi::CStr = c"2.0";
