//! A minimal FMI 2.0 host for driving the C exports of the test binary that includes this
//! module: a recording logger reached through `componentEnvironment`, and thin wrappers that
//! call the `fmi2*` functions with raw pointers, as a C host would.
//!
//! The including crate must have the 34 `fmi2*` functions at its root (from `export_fmu!`, or
//! re-exported from an FMU crate). `fmu-shear`'s host tests include this file by path, so the
//! host is written once.

// Calls FMUs through their C functions, as a host does.
#![allow(unsafe_code)]
#![allow(dead_code)]

use std::ffi::{c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use fmi2::abi::*;

use crate::{
    fmi2DeSerializeFMUstate, fmi2DoStep, fmi2EnterInitializationMode, fmi2ExitInitializationMode,
    fmi2FreeFMUstate, fmi2FreeInstance, fmi2GetBoolean, fmi2GetFMUstate, fmi2GetInteger,
    fmi2GetReal, fmi2GetString, fmi2Instantiate, fmi2Reset, fmi2SerializeFMUstate,
    fmi2SerializedFMUstateSize, fmi2SetBoolean, fmi2SetDebugLogging, fmi2SetFMUstate,
    fmi2SetInteger, fmi2SetReal, fmi2SetRealInputDerivatives, fmi2SetString, fmi2SetupExperiment,
    fmi2Terminate,
};

#[cfg(not(any(
    target_arch = "x86_64",
    all(target_arch = "aarch64", target_os = "linux")
)))]
compile_error!(
    "the test host's logger relies on variadic and fixed integer arguments being passed alike \
     (x86-64, AArch64 Linux); see `record_log`"
);

/// One call of the host's logger.
#[derive(Debug, Clone, PartialEq)]
pub struct LogRecord {
    pub instance: String,
    pub status: fmi2Status,
    pub category: String,
    /// The format argument; the layer promises it is always "%s".
    pub format: String,
    /// The single variadic argument: with the format "%s", the formatted message itself.
    pub message: String,
}

/// The host side of one or more instances: what their logger received.
pub struct Host {
    records: Mutex<Vec<LogRecord>>,
    /// Keep the records (tests that read them) or only count them (long loops).
    keep: bool,
    calls: AtomicUsize,
    bad_formats: AtomicUsize,
}

impl Host {
    /// Boxed, so the `componentEnvironment` pointer handed to the FMU stays put.
    pub fn new() -> Box<Host> {
        Box::new(Host {
            records: Mutex::new(Vec::new()),
            keep: true,
            calls: AtomicUsize::new(0),
            bad_formats: AtomicUsize::new(0),
        })
    }

    pub fn counting() -> Box<Host> {
        Box::new(Host {
            records: Mutex::new(Vec::new()),
            keep: false,
            calls: AtomicUsize::new(0),
            bad_formats: AtomicUsize::new(0),
        })
    }

    pub fn callbacks(&self) -> fmi2CallbackFunctions {
        fmi2CallbackFunctions {
            logger: logger(),
            allocate_memory: None,
            free_memory: None,
            step_finished: None,
            component_environment: self as *const Host as *mut c_void,
        }
    }

    pub fn records(&self) -> Vec<LogRecord> {
        self.records.lock().map(|r| r.clone()).unwrap_or_default()
    }

    pub fn clear(&self) {
        if let Ok(mut r) = self.records.lock() {
            r.clear();
        }
    }

    /// How many times the logger was called, kept or not.
    pub fn calls(&self) -> usize {
        self.calls.load(Ordering::SeqCst)
    }

    /// Logger calls whose format was not "%s".
    pub fn bad_formats(&self) -> usize {
        self.bad_formats.load(Ordering::SeqCst)
    }

    /// The record with `status` whose message contains every one of `needles`; panics, listing
    /// what was logged, if there is none. Also checks that every record had the format "%s".
    pub fn expect(&self, status: fmi2Status, needles: &[&str]) -> LogRecord {
        let records = self.records();
        assert_eq!(
            self.bad_formats(),
            0,
            "the logger got a format other than \"%s\": {records:#?}"
        );
        records
            .iter()
            .find(|r| r.status == status && needles.iter().all(|n| r.message.contains(n)))
            .cloned()
            .unwrap_or_else(|| panic!("no log record with status {status} containing {needles:?}; logged: {records:#?}"))
    }

    pub fn messages(&self) -> Vec<String> {
        self.records().into_iter().map(|r| r.message).collect()
    }
}

/// The host's logger, written as a plain six-argument C function.
///
/// `fmi2CallbackLogger` is C-variadic, and stable Rust cannot define a variadic function. The
/// layer always calls it as `logger(env, instanceName, status, category, "%s", message)`: six
/// arguments, each a pointer or a 32-bit unsigned integer. On x86-64 (System V and Windows) and
/// on AArch64 Linux, variadic arguments of integer class are passed exactly like named ones (on
/// System V: rdi, rsi, edx, rcx, r8, r9), and the one extra a variadic call does — loading `al`
/// with the number of vector registers used — is ignored by a non-variadic callee. So this
/// function, called through the variadic pointer type, reads the same six values a C logger would
/// get from `va_arg`; since the format is "%s", the sixth argument is the formatted message.
/// (Apple's AArch64 ABI puts variadic arguments on the stack; the `compile_error!` above keeps
/// this file off such targets.)
unsafe extern "C" fn record_log(
    env: fmi2ComponentEnvironment,
    instance: fmi2String,
    status: fmi2Status,
    category: fmi2String,
    format: fmi2String,
    message: fmi2String,
) {
    // Never unwind into the FMU (that would abort): everything below is also caught.
    let _ = catch_unwind(AssertUnwindSafe(|| {
        if env.is_null() {
            return;
        }
        // SAFETY: `env` is the `componentEnvironment` of `Host::callbacks`, a live boxed Host.
        let host = unsafe { &*(env as *const Host) };
        let text = |p: fmi2String| {
            if p.is_null() {
                "<null>".to_owned()
            } else {
                // SAFETY: the layer passes NUL-terminated strings that live across the call.
                unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
            }
        };
        host.calls.fetch_add(1, Ordering::SeqCst);
        let format = text(format);
        if format != "%s" {
            host.bad_formats.fetch_add(1, Ordering::SeqCst);
        }
        if host.keep {
            let record = LogRecord {
                instance: text(instance),
                status,
                category: text(category),
                format,
                message: text(message),
            };
            if let Ok(mut records) = host.records.lock() {
                records.push(record);
            }
        }
    }));
}

type FixedLogger = unsafe extern "C" fn(
    fmi2ComponentEnvironment,
    fmi2String,
    fmi2Status,
    fmi2String,
    fmi2String,
    fmi2String,
);

/// `record_log` in the variadic logger slot (see its comment for why the call is sound here).
pub fn logger() -> fmi2CallbackLogger {
    // SAFETY: function pointers have one size; the calling conventions agree for the argument
    // lists the layer uses, as explained at `record_log`.
    Some(unsafe {
        std::mem::transmute::<
            FixedLogger,
            unsafe extern "C" fn(
                fmi2ComponentEnvironment,
                fmi2String,
                fmi2Status,
                fmi2String,
                fmi2String,
                ...
            ),
        >(record_log)
    })
}

pub fn cstring(text: &str) -> CString {
    CString::new(text).expect("test strings have no NUL")
}

/// Raw `fmi2Instantiate` with owned strings; null arguments where `None`.
pub fn instantiate_raw(
    name: Option<&str>,
    fmu_type: fmi2Type,
    guid: Option<&str>,
    callbacks: Option<&fmi2CallbackFunctions>,
    logging_on: bool,
) -> fmi2Component {
    let name = name.map(cstring);
    let guid = guid.map(cstring);
    let resources = cstring("file:///tmp/resources");
    let ptr = |s: &Option<CString>| s.as_ref().map_or(std::ptr::null(), |s| s.as_ptr());
    // SAFETY: every pointer is null or valid for the call.
    unsafe {
        fmi2Instantiate(
            ptr(&name),
            fmu_type,
            ptr(&guid),
            resources.as_ptr(),
            callbacks.map_or(std::ptr::null(), |c| c as *const fmi2CallbackFunctions),
            fmi2False,
            fmi2Boolean::from(logging_on),
        )
    }
}

/// One instance and the host that receives its log. Freed on drop.
pub struct Slave {
    pub host: Box<Host>,
    pub c: fmi2Component,
}

impl Slave {
    /// Instantiated (state Instantiated), debug logging off.
    pub fn new(guid: &str) -> Slave {
        Self::with_host(Host::new(), guid, false)
    }

    pub fn with_host(host: Box<Host>, guid: &str, logging_on: bool) -> Slave {
        let c = instantiate_raw(
            Some("slave"),
            fmi2CoSimulation,
            Some(guid),
            Some(&host.callbacks()),
            logging_on,
        );
        assert!(
            !c.is_null(),
            "fmi2Instantiate failed: {:#?}",
            host.records()
        );
        Slave { host, c }
    }

    /// Set up at t = 0 without a stop time, through initialization mode into StepComplete.
    pub fn initialized(guid: &str) -> Slave {
        let s = Self::new(guid);
        s.initialize();
        s
    }

    pub fn initialize(&self) {
        assert_eq!(self.setup(0.0, None), fmi2OK, "{:#?}", self.host.records());
        assert_eq!(self.enter(), fmi2OK, "{:#?}", self.host.records());
        assert_eq!(self.exit(), fmi2OK, "{:#?}", self.host.records());
    }

    pub fn setup(&self, start: f64, stop: Option<f64>) -> fmi2Status {
        fmi2SetupExperiment(
            self.c,
            fmi2False,
            0.0,
            start,
            fmi2Boolean::from(stop.is_some()),
            stop.unwrap_or(0.0),
        )
    }
    pub fn enter(&self) -> fmi2Status {
        fmi2EnterInitializationMode(self.c)
    }
    pub fn exit(&self) -> fmi2Status {
        fmi2ExitInitializationMode(self.c)
    }
    pub fn step(&self, t: f64, h: f64) -> fmi2Status {
        fmi2DoStep(self.c, t, h, fmi2True)
    }
    pub fn terminate(&self) -> fmi2Status {
        fmi2Terminate(self.c)
    }
    pub fn reset(&self) -> fmi2Status {
        fmi2Reset(self.c)
    }

    pub fn debug_logging(&self, on: bool, categories: &[&str]) -> fmi2Status {
        let owned: Vec<CString> = categories.iter().map(|c| cstring(c)).collect();
        let ptrs: Vec<fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `ptrs` holds `len` valid C strings.
        unsafe { fmi2SetDebugLogging(self.c, fmi2Boolean::from(on), ptrs.len(), ptrs.as_ptr()) }
    }

    pub fn get_reals(&self, vrs: &[u32]) -> (fmi2Status, Vec<f64>) {
        // A sentinel shows values the call did not write.
        let mut out = vec![-12345.678; vrs.len()];
        // SAFETY: both arrays have vrs.len() elements.
        let status = unsafe { fmi2GetReal(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) };
        (status, out)
    }

    /// The value, asserting the call succeeded.
    pub fn real(&self, vr: u32) -> f64 {
        let (status, v) = self.get_reals(&[vr]);
        assert_eq!(
            status,
            fmi2OK,
            "fmi2GetReal({vr}): {:#?}",
            self.host.records()
        );
        v[0]
    }

    pub fn set_reals(&self, vrs: &[u32], values: &[f64]) -> fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: both arrays have vrs.len() elements.
        unsafe { fmi2SetReal(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    pub fn get_integers(&self, vrs: &[u32]) -> (fmi2Status, Vec<i32>) {
        let mut out = vec![-12345; vrs.len()];
        // SAFETY: both arrays have vrs.len() elements.
        let status = unsafe { fmi2GetInteger(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) };
        (status, out)
    }

    pub fn set_integers(&self, vrs: &[u32], values: &[i32]) -> fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: both arrays have vrs.len() elements.
        unsafe { fmi2SetInteger(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    pub fn get_booleans(&self, vrs: &[u32]) -> (fmi2Status, Vec<fmi2Boolean>) {
        let mut out = vec![-7; vrs.len()];
        // SAFETY: both arrays have vrs.len() elements.
        let status = unsafe { fmi2GetBoolean(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) };
        (status, out)
    }

    pub fn set_booleans(&self, vrs: &[u32], values: &[fmi2Boolean]) -> fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: both arrays have vrs.len() elements.
        unsafe { fmi2SetBoolean(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    /// The strings are copied out before anything else is called on the instance.
    pub fn get_strings(&self, vrs: &[u32]) -> (fmi2Status, Vec<Option<String>>) {
        let mut out: Vec<fmi2String> = vec![std::ptr::null(); vrs.len()];
        // SAFETY: both arrays have vrs.len() elements.
        let status = unsafe { fmi2GetString(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) };
        let texts = out
            .iter()
            .map(|&p| {
                (!p.is_null()).then(|| unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
            })
            .collect();
        (status, texts)
    }

    pub fn set_strings(&self, vrs: &[u32], values: &[&str]) -> fmi2Status {
        assert_eq!(vrs.len(), values.len());
        let owned: Vec<CString> = values.iter().map(|v| cstring(v)).collect();
        let ptrs: Vec<fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: both arrays have vrs.len() elements.
        unsafe { fmi2SetString(self.c, vrs.as_ptr(), vrs.len(), ptrs.as_ptr()) }
    }

    pub fn set_input_derivatives(&self, vrs: &[u32], orders: &[i32], values: &[f64]) -> fmi2Status {
        assert!(vrs.len() == orders.len() && vrs.len() == values.len());
        // SAFETY: all arrays have vrs.len() elements.
        unsafe {
            fmi2SetRealInputDerivatives(
                self.c,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                values.as_ptr(),
            )
        }
    }

    /// A new FMU state (asserting success).
    pub fn get_state(&self) -> fmi2FMUstate {
        let mut state: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: a valid slot holding null.
        let status = unsafe { fmi2GetFMUstate(self.c, &mut state) };
        assert_eq!(
            status,
            fmi2OK,
            "fmi2GetFMUstate: {:#?}",
            self.host.records()
        );
        assert!(!state.is_null());
        state
    }

    pub fn set_state(&self, state: fmi2FMUstate) -> fmi2Status {
        // SAFETY: `state` is null or from this library.
        unsafe { fmi2SetFMUstate(self.c, state) }
    }

    pub fn free_state(&self, mut state: fmi2FMUstate) {
        // SAFETY: a slot holding a state of this library.
        let status = unsafe { fmi2FreeFMUstate(self.c, &mut state) };
        assert_eq!(
            status,
            fmi2OK,
            "fmi2FreeFMUstate: {:#?}",
            self.host.records()
        );
        assert!(state.is_null(), "fmi2FreeFMUstate nulls the slot");
    }

    /// The serialized form of `state` (asserting success).
    pub fn serialize(&self, state: fmi2FMUstate) -> Vec<u8> {
        let mut size = 0usize;
        // SAFETY: a state of this library and a writable size.
        let status = unsafe { fmi2SerializedFMUstateSize(self.c, state, &mut size) };
        assert_eq!(
            status,
            fmi2OK,
            "fmi2SerializedFMUstateSize: {:#?}",
            self.host.records()
        );
        let mut bytes = vec![0u8; size];
        // SAFETY: `bytes` has `size` writable bytes.
        let status =
            unsafe { fmi2SerializeFMUstate(self.c, state, bytes.as_mut_ptr().cast(), size) };
        assert_eq!(
            status,
            fmi2OK,
            "fmi2SerializeFMUstate: {:#?}",
            self.host.records()
        );
        bytes
    }

    /// `fmi2DeSerializeFMUstate` into a fresh (null) slot.
    pub fn deserialize(&self, bytes: &[u8]) -> (fmi2Status, fmi2FMUstate) {
        let mut state: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `bytes` is readable for its length; the slot is valid.
        let status = unsafe {
            fmi2DeSerializeFMUstate(self.c, bytes.as_ptr().cast(), bytes.len(), &mut state)
        };
        (status, state)
    }
}

impl Drop for Slave {
    fn drop(&mut self) {
        // SAFETY: `c` came from fmi2Instantiate and is freed once.
        unsafe { fmi2FreeInstance(self.c) };
    }
}

/// The resident set size of this process, from /proc/self/status, in bytes.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
