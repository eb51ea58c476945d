//! Instances, FMU states and log messages are all given back: 10,000 full life cycles through
//! the C exports do not make the process grow. Alone in its test binary, so no other test's
//! allocations move the resident set size it reads.

// Calls FMUs through their C functions, as a host does.
#![allow(unsafe_code)]

mod common;
#[path = "common/probe.rs"]
mod probe;

fmi2::export_fmu!(crate::probe::ProbeModel);

use common::{instantiate_raw, resident_bytes, Host};
use fmi2::abi::*;
use probe::*;

const WARM_UP_CYCLES: usize = 1_000;
const MEASURED_CYCLES: usize = 10_000;
/// Measured growth over the 10,000 cycles after the warm-up: 0 KiB in each of four runs (debug
/// build, glibc; VmRSS about 3 MiB). Leaking one FMU state per cycle (about 160 bytes) measured
/// 1.5 MiB and failed; the margin leaves room for allocator noise only.
const ALLOWED_GROWTH_BYTES: u64 = 1 << 20;

/// One host's whole use of an instance: instantiate, set up, initialize, set, step, read, take and
/// serialize and restore a state, hit a refused call (which logs), free everything.
fn life_cycle(host: &Host, guid: &str) {
    let callbacks = host.callbacks();
    let c = instantiate_raw(
        Some("cycle"),
        fmi2CoSimulation,
        Some(guid),
        Some(&callbacks),
        true,
    );
    assert!(!c.is_null());
    let vr = [U, Y];
    let mut out = [0.0; 2];
    let mut state: fmi2FMUstate = std::ptr::null_mut();
    let mut restored: fmi2FMUstate = std::ptr::null_mut();
    let mut size = 0usize;
    let label = [LABEL];
    let mut text: [fmi2String; 1] = [std::ptr::null()];
    // SAFETY: `c` is a live instance; every array has the length passed with it.
    unsafe {
        assert_eq!(
            fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0),
            fmi2OK
        );
        assert_eq!(fmi2EnterInitializationMode(c), fmi2OK);
        assert_eq!(fmi2ExitInitializationMode(c), fmi2OK);
        assert_eq!(fmi2SetReal(c, vr.as_ptr(), 1, [1.0].as_ptr()), fmi2OK);
        assert_eq!(fmi2DoStep(c, 0.0, 0.1, fmi2True), fmi2OK);
        assert_eq!(fmi2GetReal(c, vr.as_ptr(), 2, out.as_mut_ptr()), fmi2OK);
        assert_eq!(
            fmi2GetString(c, label.as_ptr(), 1, text.as_mut_ptr()),
            fmi2OK
        );
        assert_eq!(fmi2GetFMUstate(c, &mut state), fmi2OK);
        assert_eq!(fmi2SerializedFMUstateSize(c, state, &mut size), fmi2OK);
        let mut bytes = vec![0 as fmi2Byte; size];
        assert_eq!(
            fmi2SerializeFMUstate(c, state, bytes.as_mut_ptr(), size),
            fmi2OK
        );
        assert_eq!(
            fmi2DeSerializeFMUstate(c, bytes.as_ptr(), size, &mut restored),
            fmi2OK
        );
        assert_eq!(fmi2DoStep(c, 0.1, 0.1, fmi2True), fmi2OK);
        assert_eq!(fmi2SetFMUstate(c, restored), fmi2OK);
        assert_eq!(
            fmi2DoStep(c, 0.5, 0.1, fmi2True),
            fmi2Error,
            "refused, and logged"
        );
        assert_eq!(fmi2FreeFMUstate(c, &mut state), fmi2OK);
        assert_eq!(fmi2FreeFMUstate(c, &mut restored), fmi2OK);
        fmi2FreeInstance(c);
    }
    assert_eq!(out[0], 1.0);
}

#[test]
fn ten_thousand_life_cycles_do_not_grow_the_process() {
    let Some(_) = resident_bytes() else {
        panic!("this test reads VmRSS from /proc/self/status, which is not available here");
    };
    // Counting, not keeping, what the logger receives: the host itself must not grow either.
    let host = Host::counting();
    let guid = info().guid.clone();
    for _ in 0..WARM_UP_CYCLES {
        life_cycle(&host, &guid);
    }
    let before = resident_bytes().expect("VmRSS");
    for _ in 0..MEASURED_CYCLES {
        life_cycle(&host, &guid);
    }
    let after = resident_bytes().expect("VmRSS");
    let growth = after.saturating_sub(before);
    eprintln!(
        "VmRSS before {} KiB, after {} KiB, growth {} KiB over {MEASURED_CYCLES} cycles",
        before / 1024,
        after / 1024,
        growth / 1024
    );
    assert!(
        growth < ALLOWED_GROWTH_BYTES,
        "the process grew by {growth} bytes over {MEASURED_CYCLES} cycles"
    );
    // Each cycle logged (every call, debug logging being on, and the refused step), always with "%s".
    let calls = host.calls();
    assert!(
        calls >= (WARM_UP_CYCLES + MEASURED_CYCLES) * 15,
        "{calls} logger calls"
    );
    assert_eq!(host.bad_formats(), 0);
}
