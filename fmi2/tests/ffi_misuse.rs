//! The export layer driven through its C functions by a host that makes mistakes: calls in the
//! wrong state, null pointers, unknown value references, non-finite values, bad step arguments,
//! a diverging model, FMU states (also broken ones) and debug logging. A refused call returns
//! fmi2Error, says why through the logger and changes nothing.

// Calls FMUs through their C functions, as a host does.
#![allow(unsafe_code)]

mod common;
#[path = "common/probe.rs"]
mod probe;

fmi2::export_fmu!(crate::probe::ProbeModel);

use std::ffi::CString;

use common::{cstring, instantiate_raw, Host, Slave};
use fmi2::abi::*;
use probe::*;

fn guid() -> &'static str {
    &info().guid
}

/// Every variable of the probe, read through the C API (needs a state that allows getting).
#[derive(Debug, PartialEq)]
struct Observed {
    reals: Vec<u64>,
    multiplier: i32,
    booleans: Vec<fmi2Boolean>,
    label: Option<String>,
}

fn observe(s: &Slave) -> Observed {
    let (status, reals) = s.get_reals(&[U, Y, X, GAIN, OFFSET]);
    assert_eq!(status, fmi2OK, "{:#?}", s.host.records());
    let (status, ints) = s.get_integers(&[MULTIPLIER]);
    assert_eq!(status, fmi2OK);
    let (status, booleans) = s.get_booleans(&[DIVERGE, FLAG]);
    assert_eq!(status, fmi2OK);
    let (status, strings) = s.get_strings(&[LABEL]);
    assert_eq!(status, fmi2OK);
    Observed {
        // Bit patterns, so "unchanged" means exactly unchanged (and NaN compares).
        reals: reals.iter().map(|x| x.to_bits()).collect(),
        multiplier: ints[0],
        booleans,
        label: strings.into_iter().next().flatten(),
    }
}

/// The call was refused: fmi2Error, and an error message containing every needle was logged for it.
#[track_caller]
fn assert_refused(s: &Slave, status: fmi2Status, needles: &[&str]) {
    assert_eq!(
        status,
        fmi2Error,
        "expected fmi2Error; logged: {:#?}",
        s.host.records()
    );
    let record = s.host.expect(fmi2Error, needles);
    assert_eq!(record.category, "logStatusError");
    assert_eq!(record.instance, "slave");
    s.host.clear();
}

// ---------------------------------------------------------------------------------------------
// Call order

#[test]
fn do_step_before_exit_initialization_mode_is_refused_and_changes_nothing() {
    let s = Slave::new(guid());
    assert_refused(
        &s,
        s.step(0.0, 0.1),
        &[
            "fmi2DoStep",
            "not allowed in state Instantiated",
            "expected state StepComplete",
        ],
    );
    assert_eq!(s.setup(0.0, None), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    let before = observe(&s);
    assert_refused(
        &s,
        s.step(0.0, 0.1),
        &[
            "fmi2DoStep",
            "not allowed in state InitializationMode",
            "expected state StepComplete",
        ],
    );
    assert_eq!(observe(&s), before);
    // Still in initialization mode: leaving it works, and then the step does.
    assert_eq!(s.exit(), fmi2OK);
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

#[test]
fn entering_initialization_mode_twice_is_refused() {
    let s = Slave::new(guid());
    assert_eq!(s.enter(), fmi2OK);
    assert_refused(
        &s,
        s.enter(),
        &[
            "fmi2EnterInitializationMode",
            "not allowed in state InitializationMode",
            "expected state Instantiated",
        ],
    );
    assert_eq!(s.exit(), fmi2OK);
    assert_refused(
        &s,
        s.enter(),
        &[
            "not allowed in state StepComplete",
            "expected state Instantiated",
        ],
    );
    assert_refused(
        &s,
        s.exit(),
        &[
            "fmi2ExitInitializationMode",
            "not allowed in state StepComplete",
            "expected state InitializationMode",
        ],
    );
}

#[test]
fn setup_experiment_after_initialization_is_refused_and_keeps_the_time() {
    let s = Slave::new(guid());
    assert_eq!(s.setup(1.0, None), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_refused(
        &s,
        s.setup(5.0, None),
        &[
            "fmi2SetupExperiment",
            "not allowed in state InitializationMode",
            "expected state Instantiated",
        ],
    );
    assert_eq!(s.exit(), fmi2OK);
    assert_refused(
        &s,
        s.setup(5.0, None),
        &[
            "not allowed in state StepComplete",
            "expected state Instantiated",
        ],
    );
    // The start time is still 1.0.
    assert_eq!(s.step(1.0, 0.5), fmi2OK);
}

#[test]
fn getting_values_in_the_instantiated_state_is_refused() {
    let s = Slave::new(guid());
    let (status, out) = s.get_reals(&[Y]);
    assert_refused(
        &s,
        status,
        &[
            "fmi2GetReal",
            "not allowed in state Instantiated",
            "expected state InitializationMode | StepComplete | Terminated | Error",
        ],
    );
    assert_eq!(out, vec![-12345.678], "nothing written");
    assert_refused(
        &s,
        s.get_integers(&[MULTIPLIER]).0,
        &["fmi2GetInteger", "not allowed in state Instantiated"],
    );
    assert_refused(
        &s,
        s.get_booleans(&[FLAG]).0,
        &["fmi2GetBoolean", "not allowed in state Instantiated"],
    );
    assert_refused(
        &s,
        s.get_strings(&[LABEL]).0,
        &["fmi2GetString", "not allowed in state Instantiated"],
    );
}

#[test]
fn stepping_or_setting_after_terminate_is_refused() {
    let s = Slave::initialized(guid());
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    assert_eq!(s.terminate(), fmi2OK);
    let before = observe(&s);
    assert_refused(
        &s,
        s.step(0.1, 0.1),
        &[
            "fmi2DoStep",
            "not allowed in state Terminated",
            "expected state StepComplete",
        ],
    );
    assert_refused(
        &s,
        s.set_reals(&[U], &[1.0]),
        &["fmi2SetReal", "not allowed in state Terminated"],
    );
    assert_refused(
        &s,
        s.terminate(),
        &[
            "fmi2Terminate",
            "not allowed in state Terminated",
            "expected state StepComplete | Error",
        ],
    );
    assert_eq!(
        observe(&s),
        before,
        "getting values is still allowed and they did not change"
    );
    let mut terminated = fmi2False;
    // SAFETY: valid instance and out pointer.
    assert_eq!(
        unsafe { fmi2GetBooleanStatus(s.c, fmi2Terminated, &mut terminated) },
        fmi2OK
    );
    assert_eq!(terminated, fmi2True);
    // A reset starts over.
    assert_eq!(s.reset(), fmi2OK);
    s.initialize();
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

#[test]
fn terminate_before_initialization_is_refused() {
    let s = Slave::new(guid());
    assert_refused(
        &s,
        s.terminate(),
        &["fmi2Terminate", "not allowed in state Instantiated"],
    );
    assert_refused(
        &s,
        s.exit(),
        &[
            "fmi2ExitInitializationMode",
            "not allowed in state Instantiated",
        ],
    );
}

// ---------------------------------------------------------------------------------------------
// Null pointers

#[test]
fn a_null_component_is_refused_by_every_function() {
    let null: fmi2Component = std::ptr::null_mut();
    let vr = [U];
    let mut real = [0.0];
    let mut int = [0];
    let mut boolean = [0];
    let mut string: [fmi2String; 1] = [std::ptr::null()];
    let mut state: fmi2FMUstate = std::ptr::null_mut();
    let mut size = 0usize;
    let mut bytes = [0 as fmi2Byte; 8];
    let mut status = fmi2OK;
    let order = [1];
    // SAFETY: all pointers other than the component are valid; the layer must not touch any.
    let results = unsafe {
        [
            (
                "fmi2SetDebugLogging",
                fmi2SetDebugLogging(null, fmi2True, 0, std::ptr::null()),
            ),
            (
                "fmi2SetupExperiment",
                fmi2SetupExperiment(null, fmi2False, 0.0, 0.0, fmi2False, 0.0),
            ),
            (
                "fmi2EnterInitializationMode",
                fmi2EnterInitializationMode(null),
            ),
            (
                "fmi2ExitInitializationMode",
                fmi2ExitInitializationMode(null),
            ),
            ("fmi2Terminate", fmi2Terminate(null)),
            ("fmi2Reset", fmi2Reset(null)),
            (
                "fmi2GetReal",
                fmi2GetReal(null, vr.as_ptr(), 1, real.as_mut_ptr()),
            ),
            (
                "fmi2GetInteger",
                fmi2GetInteger(null, vr.as_ptr(), 1, int.as_mut_ptr()),
            ),
            (
                "fmi2GetBoolean",
                fmi2GetBoolean(null, vr.as_ptr(), 1, boolean.as_mut_ptr()),
            ),
            (
                "fmi2GetString",
                fmi2GetString(null, vr.as_ptr(), 1, string.as_mut_ptr()),
            ),
            (
                "fmi2SetReal",
                fmi2SetReal(null, vr.as_ptr(), 1, real.as_ptr()),
            ),
            (
                "fmi2SetInteger",
                fmi2SetInteger(null, vr.as_ptr(), 1, int.as_ptr()),
            ),
            (
                "fmi2SetBoolean",
                fmi2SetBoolean(null, vr.as_ptr(), 1, boolean.as_ptr()),
            ),
            (
                "fmi2SetString",
                fmi2SetString(null, vr.as_ptr(), 1, string.as_ptr()),
            ),
            ("fmi2GetFMUstate", fmi2GetFMUstate(null, &mut state)),
            ("fmi2SetFMUstate", fmi2SetFMUstate(null, state)),
            ("fmi2FreeFMUstate", fmi2FreeFMUstate(null, &mut state)),
            (
                "fmi2SerializedFMUstateSize",
                fmi2SerializedFMUstateSize(null, state, &mut size),
            ),
            (
                "fmi2SerializeFMUstate",
                fmi2SerializeFMUstate(null, state, bytes.as_mut_ptr(), bytes.len()),
            ),
            (
                "fmi2DeSerializeFMUstate",
                fmi2DeSerializeFMUstate(null, bytes.as_ptr(), bytes.len(), &mut state),
            ),
            (
                "fmi2GetDirectionalDerivative",
                fmi2GetDirectionalDerivative(
                    null,
                    vr.as_ptr(),
                    1,
                    vr.as_ptr(),
                    1,
                    real.as_ptr(),
                    real.as_mut_ptr(),
                ),
            ),
            (
                "fmi2SetRealInputDerivatives",
                fmi2SetRealInputDerivatives(null, vr.as_ptr(), 1, order.as_ptr(), real.as_ptr()),
            ),
            (
                "fmi2GetRealOutputDerivatives",
                fmi2GetRealOutputDerivatives(
                    null,
                    vr.as_ptr(),
                    1,
                    order.as_ptr(),
                    real.as_mut_ptr(),
                ),
            ),
            ("fmi2DoStep", fmi2DoStep(null, 0.0, 0.1, fmi2True)),
            ("fmi2CancelStep", fmi2CancelStep(null)),
            (
                "fmi2GetStatus",
                fmi2GetStatus(null, fmi2DoStepStatus, &mut status),
            ),
            (
                "fmi2GetRealStatus",
                fmi2GetRealStatus(null, fmi2LastSuccessfulTime, real.as_mut_ptr()),
            ),
            (
                "fmi2GetIntegerStatus",
                fmi2GetIntegerStatus(null, fmi2DoStepStatus, int.as_mut_ptr()),
            ),
            (
                "fmi2GetBooleanStatus",
                fmi2GetBooleanStatus(null, fmi2Terminated, boolean.as_mut_ptr()),
            ),
            (
                "fmi2GetStringStatus",
                fmi2GetStringStatus(null, fmi2PendingStatus, string.as_mut_ptr()),
            ),
        ]
    };
    for (name, result) in results {
        assert_eq!(result, fmi2Error, "{name} with a null component");
    }
    assert!(state.is_null(), "no state was made");
    assert_eq!(real, [0.0], "nothing was written");
    // SAFETY: freeing null is a no-op the standard allows.
    unsafe { fmi2FreeInstance(null) };
}

#[test]
fn null_value_reference_or_value_arrays_are_refused() {
    let s = Slave::initialized(guid());
    let before = observe(&s);
    let vr = [U];
    let mut real = [1.0];
    let mut int = [1];
    let mut boolean = [fmi2True];
    let mut string: [fmi2String; 1] = [c"x".as_ptr()];
    let null_vr: *const fmi2ValueReference = std::ptr::null();
    // SAFETY: the non-null pointers are valid for one element; the layer must check the null ones.
    unsafe {
        assert_refused(
            &s,
            fmi2GetReal(s.c, null_vr, 1, real.as_mut_ptr()),
            &["fmi2GetReal", "null"],
        );
        assert_refused(
            &s,
            fmi2GetReal(s.c, vr.as_ptr(), 1, std::ptr::null_mut()),
            &["fmi2GetReal", "null"],
        );
        assert_refused(
            &s,
            fmi2GetInteger(s.c, null_vr, 1, int.as_mut_ptr()),
            &["fmi2GetInteger", "null"],
        );
        assert_refused(
            &s,
            fmi2GetInteger(s.c, vr.as_ptr(), 1, std::ptr::null_mut()),
            &["fmi2GetInteger", "null"],
        );
        assert_refused(
            &s,
            fmi2GetBoolean(s.c, null_vr, 1, boolean.as_mut_ptr()),
            &["fmi2GetBoolean", "null"],
        );
        assert_refused(
            &s,
            fmi2GetBoolean(s.c, vr.as_ptr(), 1, std::ptr::null_mut()),
            &["fmi2GetBoolean", "null"],
        );
        assert_refused(
            &s,
            fmi2GetString(s.c, null_vr, 1, string.as_mut_ptr()),
            &["fmi2GetString", "null"],
        );
        assert_refused(
            &s,
            fmi2GetString(s.c, vr.as_ptr(), 1, std::ptr::null_mut()),
            &["fmi2GetString", "null"],
        );
        assert_refused(
            &s,
            fmi2SetReal(s.c, null_vr, 1, real.as_ptr()),
            &["fmi2SetReal", "null"],
        );
        assert_refused(
            &s,
            fmi2SetReal(s.c, vr.as_ptr(), 1, std::ptr::null()),
            &["fmi2SetReal", "null"],
        );
        assert_refused(
            &s,
            fmi2SetInteger(s.c, null_vr, 1, int.as_ptr()),
            &["fmi2SetInteger", "null"],
        );
        assert_refused(
            &s,
            fmi2SetInteger(s.c, vr.as_ptr(), 1, std::ptr::null()),
            &["fmi2SetInteger", "null"],
        );
        assert_refused(
            &s,
            fmi2SetBoolean(s.c, null_vr, 1, boolean.as_ptr()),
            &["fmi2SetBoolean", "null"],
        );
        assert_refused(
            &s,
            fmi2SetBoolean(s.c, vr.as_ptr(), 1, std::ptr::null()),
            &["fmi2SetBoolean", "null"],
        );
        assert_refused(
            &s,
            fmi2SetString(s.c, null_vr, 1, string.as_ptr()),
            &["fmi2SetString", "null"],
        );
        assert_refused(
            &s,
            fmi2SetString(s.c, vr.as_ptr(), 1, std::ptr::null()),
            &["fmi2SetString", "null"],
        );
        let order = [1];
        assert_refused(
            &s,
            fmi2SetRealInputDerivatives(s.c, vr.as_ptr(), 1, std::ptr::null(), real.as_ptr()),
            &["fmi2SetRealInputDerivatives", "null"],
        );
        assert_refused(
            &s,
            fmi2SetRealInputDerivatives(s.c, vr.as_ptr(), 1, order.as_ptr(), std::ptr::null()),
            &["fmi2SetRealInputDerivatives", "null"],
        );
        // A null string inside the value array (label is settable before initialization).
        let fresh = Slave::new(guid());
        let label = [LABEL];
        let null_string: [fmi2String; 1] = [std::ptr::null()];
        assert_refused(
            &fresh,
            fmi2SetString(fresh.c, label.as_ptr(), 1, null_string.as_ptr()),
            &["fmi2SetString", "a string value is null"],
        );
        // Null output pointers of the status queries.
        assert_refused(
            &s,
            fmi2GetStatus(s.c, fmi2DoStepStatus, std::ptr::null_mut()),
            &["fmi2GetStatus", "null"],
        );
        assert_refused(
            &s,
            fmi2GetRealStatus(s.c, fmi2LastSuccessfulTime, std::ptr::null_mut()),
            &["fmi2GetRealStatus", "null"],
        );
        assert_refused(
            &s,
            fmi2SetDebugLogging(s.c, fmi2True, 2, std::ptr::null()),
            &["fmi2SetDebugLogging", "null"],
        );
        // With n = 0 the arrays are not read; null is fine.
        assert_eq!(fmi2GetReal(s.c, null_vr, 0, std::ptr::null_mut()), fmi2OK);
        assert_eq!(fmi2SetReal(s.c, null_vr, 0, std::ptr::null()), fmi2OK);
    }
    assert_eq!(observe(&s), before);
    assert_eq!(s.step(0.0, 0.1), fmi2OK, "the instance still works");
}

#[test]
fn null_fmu_state_pointers_are_refused() {
    let s = Slave::initialized(guid());
    let mut size = 0usize;
    let mut bytes = [0 as fmi2Byte; 16];
    let null_slot: *mut fmi2FMUstate = std::ptr::null_mut();
    // SAFETY: the layer must check every null pointer before use.
    unsafe {
        assert_refused(
            &s,
            fmi2GetFMUstate(s.c, null_slot),
            &["fmi2GetFMUstate", "null"],
        );
        assert_refused(
            &s,
            fmi2SetFMUstate(s.c, std::ptr::null_mut()),
            &["fmi2SetFMUstate", "null"],
        );
        assert_refused(
            &s,
            fmi2FreeFMUstate(s.c, null_slot),
            &["fmi2FreeFMUstate", "null"],
        );
        assert_refused(
            &s,
            fmi2SerializedFMUstateSize(s.c, std::ptr::null_mut(), &mut size),
            &["fmi2SerializedFMUstateSize", "null"],
        );
        assert_refused(
            &s,
            fmi2SerializeFMUstate(s.c, std::ptr::null_mut(), bytes.as_mut_ptr(), bytes.len()),
            &["fmi2SerializeFMUstate", "null"],
        );
        assert_refused(
            &s,
            fmi2DeSerializeFMUstate(s.c, bytes.as_ptr(), bytes.len(), null_slot),
            &["fmi2DeSerializeFMUstate", "null"],
        );
        assert_refused(
            &s,
            fmi2DeSerializeFMUstate(s.c, std::ptr::null(), 16, &mut std::ptr::null_mut()),
            &["fmi2DeSerializeFMUstate", "null"],
        );
        // A real state, then null size / buffer pointers.
        let state = s.get_state();
        assert_refused(
            &s,
            fmi2SerializedFMUstateSize(s.c, state, std::ptr::null_mut()),
            &["size is null"],
        );
        assert_refused(
            &s,
            fmi2SerializeFMUstate(s.c, state, std::ptr::null_mut(), 4096),
            &["null"],
        );
        s.free_state(state);
    }
    // Freeing a slot that holds null is allowed and does nothing.
    let mut empty: fmi2FMUstate = std::ptr::null_mut();
    // SAFETY: a valid slot.
    assert_eq!(unsafe { fmi2FreeFMUstate(s.c, &mut empty) }, fmi2OK);
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

#[test]
fn instantiate_without_callbacks_returns_null() {
    let c = instantiate_raw(Some("slave"), fmi2CoSimulation, Some(guid()), None, true);
    assert!(c.is_null());
}

/// Instance name, fmuType, GUID (null where `None`), and what the log must say.
type InstantiateCase<'a> = (Option<&'a str>, fmi2Type, Option<&'a str>, &'a [&'a str]);

#[test]
fn instantiate_refuses_a_bad_guid_type_or_name_and_says_why() {
    let host = Host::new();
    let callbacks = host.callbacks();
    let cases: [InstantiateCase; 6] = [
        (
            Some("slave"),
            fmi2CoSimulation,
            Some("{not-the-guid}"),
            &["GUID mismatch", guid(), "but was {not-the-guid}"],
        ),
        (
            Some("slave"),
            fmi2CoSimulation,
            Some(""),
            &["GUID mismatch"],
        ),
        (
            Some("slave"),
            fmi2CoSimulation,
            None,
            &["GUID mismatch", "but was null"],
        ),
        (
            Some("slave"),
            fmi2ModelExchange,
            Some(guid()),
            &["co-simulation only", "fmuType was 0"],
        ),
        (
            Some(""),
            fmi2CoSimulation,
            Some(guid()),
            &["instanceName is null or empty"],
        ),
        (
            None,
            fmi2CoSimulation,
            Some(guid()),
            &["instanceName is null or empty"],
        ),
    ];
    for (name, fmu_type, guid_text, needles) in cases {
        host.clear();
        for logging_on in [false, true] {
            let c = instantiate_raw(name, fmu_type, guid_text, Some(&callbacks), logging_on);
            assert!(
                c.is_null(),
                "{name:?} {fmu_type} {guid_text:?} must be refused"
            );
            let record = host.expect(fmi2Error, needles);
            assert!(record.message.starts_with("fmi2Instantiate"), "{record:?}");
        }
    }
    // The right arguments work with the same callbacks.
    let c = instantiate_raw(
        Some("slave"),
        fmi2CoSimulation,
        Some(guid()),
        Some(&callbacks),
        false,
    );
    assert!(!c.is_null());
    // SAFETY: from fmi2Instantiate, freed once.
    unsafe { fmi2FreeInstance(c) };
}

// ---------------------------------------------------------------------------------------------
// Unknown value references and variables that cannot be set

#[test]
fn unknown_value_references_are_refused_for_every_type_naming_the_reference() {
    let s = Slave::initialized(guid());
    let before = observe(&s);
    assert_refused(
        &s,
        s.get_reals(&[Y, 999]).0,
        &[
            "fmi2GetReal",
            "unknown value reference 999 for a Real variable",
        ],
    );
    assert_refused(
        &s,
        s.set_reals(&[U, 999], &[1.0, 1.0]),
        &[
            "fmi2SetReal",
            "unknown value reference 999 for a Real variable",
        ],
    );
    assert_refused(
        &s,
        s.get_integers(&[999]).0,
        &[
            "fmi2GetInteger",
            "unknown value reference 999 for a Integer variable",
        ],
    );
    assert_refused(
        &s,
        s.set_integers(&[999], &[1]),
        &[
            "fmi2SetInteger",
            "unknown value reference 999 for a Integer variable",
        ],
    );
    assert_refused(
        &s,
        s.get_booleans(&[999]).0,
        &[
            "fmi2GetBoolean",
            "unknown value reference 999 for a Boolean variable",
        ],
    );
    assert_refused(
        &s,
        s.set_booleans(&[DIVERGE, 999], &[fmi2True, fmi2True]),
        &["fmi2SetBoolean", "unknown value reference 999"],
    );
    assert_refused(
        &s,
        s.get_strings(&[999]).0,
        &[
            "fmi2GetString",
            "unknown value reference 999 for a String variable",
        ],
    );
    assert_refused(
        &s,
        s.set_strings(&[999], &["x"]),
        &[
            "fmi2SetString",
            "unknown value reference 999 for a String variable",
        ],
    );
    // A reference that exists, but for another type.
    assert_refused(
        &s,
        s.get_integers(&[GAIN]).0,
        &["unknown value reference 4 for a Integer variable"],
    );
    assert_refused(
        &s,
        s.set_booleans(&[U], &[fmi2True]),
        &["unknown value reference 1 for a Boolean variable"],
    );
    assert_refused(
        &s,
        s.get_strings(&[U]).0,
        &["unknown value reference 1 for a String variable"],
    );
    assert_refused(
        &s,
        s.set_input_derivatives(&[999], &[1], &[1.0]),
        &["fmi2SetRealInputDerivatives", "unknown value reference 999"],
    );
    assert_eq!(
        observe(&s),
        before,
        "the valid references of the refused batches were not set"
    );
}

#[test]
fn fixed_parameters_after_initialization_and_outputs_cannot_be_set() {
    let s = Slave::new(guid());
    // Outputs never.
    assert_refused(
        &s,
        s.set_reals(&[Y], &[1.0]),
        &["fmi2SetReal", "'y' has causality output and cannot be set"],
    );
    assert_refused(
        &s,
        s.set_reals(&[U, X], &[3.0, 1.0]),
        &["'x' has causality output"],
    );
    // Fixed parameters before the end of initialization: yes.
    assert_eq!(s.set_reals(&[GAIN], &[3.0]), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_eq!(s.set_reals(&[GAIN], &[4.0]), fmi2OK);
    assert_eq!(s.set_integers(&[MULTIPLIER], &[2]), fmi2OK);
    assert_eq!(s.exit(), fmi2OK);
    let before = observe(&s);
    assert_eq!(
        s.real(U),
        0.0,
        "the refused batch with an output did not set u"
    );
    let fixed = "is a fixed parameter: it can be set only before fmi2ExitInitializationMode";
    assert_refused(
        &s,
        s.set_reals(&[GAIN], &[5.0]),
        &["fmi2SetReal", "'gain'", fixed],
    );
    assert_refused(&s, s.set_reals(&[U, GAIN], &[1.0, 5.0]), &["'gain'", fixed]);
    assert_refused(
        &s,
        s.set_integers(&[MULTIPLIER], &[3]),
        &["fmi2SetInteger", "'multiplier'", fixed],
    );
    assert_refused(
        &s,
        s.set_booleans(&[FLAG], &[fmi2True]),
        &["fmi2SetBoolean", "'flag'", fixed],
    );
    assert_refused(
        &s,
        s.set_strings(&[LABEL], &["other"]),
        &["fmi2SetString", "'label'", fixed],
    );
    assert_refused(&s, s.set_reals(&[Y], &[1.0]), &["'y' has causality output"]);
    assert_refused(
        &s,
        s.set_input_derivatives(&[GAIN], &[1], &[1.0]),
        &[
            "fmi2SetRealInputDerivatives",
            "'gain' (vr 4) is not an input",
        ],
    );
    assert_eq!(observe(&s), before);
    assert_eq!(s.real(GAIN), 4.0);
    // A tunable parameter and inputs stay settable.
    assert_eq!(s.set_reals(&[OFFSET, U], &[0.5, 1.0]), fmi2OK);
    assert_eq!(s.real(Y), 0.0 + 4.0 * 1.0 + 0.5);
}

#[test]
fn a_batch_the_model_refuses_part_of_is_set_whole_or_not_at_all() {
    let s = Slave::new(guid());
    assert_eq!(s.enter(), fmi2OK);
    let before = observe(&s);
    // gain must be > 0: the model itself refuses the second value after the layer let it through.
    assert_refused(
        &s,
        s.set_reals(&[U, GAIN], &[3.0, -1.0]),
        &["fmi2SetReal", "invalid value for 'gain'", "-1 must be > 0"],
    );
    assert_eq!(observe(&s), before, "u was not set by the refused batch");
    assert_refused(
        &s,
        s.set_reals(&[GAIN, OFFSET, GAIN], &[7.0, 2.0, 0.0]),
        &["invalid value for 'gain'"],
    );
    assert_eq!(observe(&s), before, "gain and offset were put back");
    assert_refused(
        &s,
        s.set_integers(&[MULTIPLIER, MULTIPLIER], &[5, 11]),
        &["invalid value for 'multiplier'", "11 is outside [1, 10]"],
    );
    assert_eq!(observe(&s), before, "the multiplier was put back");
}

// ---------------------------------------------------------------------------------------------
// Non-finite values

#[test]
fn non_finite_inputs_and_parameters_are_refused_and_change_nothing() {
    let s = Slave::new(guid());
    assert_eq!(s.enter(), fmi2OK);
    assert_eq!(s.set_reals(&[U], &[0.25]), fmi2OK);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let before = observe(&s);
        assert_refused(
            &s,
            s.set_reals(&[U], &[bad]),
            &["fmi2SetReal", "'u' (vr 1)", "only finite reals"],
        );
        assert_refused(
            &s,
            s.set_reals(&[GAIN], &[bad]),
            &["'gain' (vr 4)", "only finite reals"],
        );
        // One bad value in a batch: none of the batch is set.
        assert_refused(
            &s,
            s.set_reals(&[U, OFFSET, GAIN], &[1.5, 0.5, bad]),
            &["'gain'", "only finite reals"],
        );
        assert_refused(
            &s,
            s.set_reals(&[U, OFFSET], &[bad, 0.5]),
            &["'u'", "only finite reals"],
        );
        assert_eq!(observe(&s), before, "{bad} changed something");
    }
    assert_eq!(s.exit(), fmi2OK);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let before = observe(&s);
        assert_refused(&s, s.set_reals(&[U], &[bad]), &["only finite reals"]);
        assert_refused(
            &s,
            s.set_reals(&[OFFSET, U], &[1.0, bad]),
            &["only finite reals"],
        );
        assert_refused(
            &s,
            s.set_input_derivatives(&[U], &[1], &[bad]),
            &[
                "fmi2SetRealInputDerivatives",
                "derivative of 'u'",
                "only finite reals",
            ],
        );
        assert_eq!(observe(&s), before);
    }
    // The refused derivative was not kept: a step with u = 0.25 and no slope gives x = 0.025.
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    assert_eq!(s.real(X), 0.25 * 0.1);
    assert_eq!(s.real(U), 0.25);
}

#[test]
fn non_finite_experiment_times_are_refused() {
    let s = Slave::new(guid());
    assert_refused(
        &s,
        s.setup(f64::NAN, None),
        &["fmi2SetupExperiment", "startTime must be finite"],
    );
    assert_refused(
        &s,
        s.setup(f64::INFINITY, None),
        &["startTime must be finite"],
    );
    assert_refused(
        &s,
        s.setup(0.0, Some(f64::NAN)),
        &["stopTime must be finite"],
    );
    assert_refused(
        &s,
        s.setup(1.0, Some(0.5)),
        &["stopTime must be finite and ≥ startTime"],
    );
    s.initialize();
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

#[test]
fn input_derivatives_of_order_other_than_one_are_refused() {
    let s = Slave::initialized(guid());
    for order in [0, 2, -1] {
        assert_refused(
            &s,
            s.set_input_derivatives(&[U], &[order], &[1.0]),
            &[
                "fmi2SetRealInputDerivatives",
                &format!("derivative order {order} for 'u'"),
                "only order 1",
            ],
        );
    }
    // Order 1 works and ramps u inside the next step.
    assert_eq!(s.set_input_derivatives(&[U], &[1], &[2.0]), fmi2OK);
    assert_eq!(s.step(0.0, 0.5), fmi2OK);
    assert_eq!(s.real(U), 1.0);
    assert_eq!(s.real(X), 0.5 * 2.0 * 0.25);
}

#[test]
fn services_the_fmu_does_not_provide_are_refused() {
    let s = Slave::initialized(guid());
    let vr = [Y];
    let known = [U];
    let dv = [1.0];
    let mut out = [0.0];
    let order = [1];
    // SAFETY: valid arrays of one element.
    unsafe {
        assert_refused(
            &s,
            fmi2GetDirectionalDerivative(
                s.c,
                vr.as_ptr(),
                1,
                known.as_ptr(),
                1,
                dv.as_ptr(),
                out.as_mut_ptr(),
            ),
            &["fmi2GetDirectionalDerivative", "not provided"],
        );
        assert_refused(
            &s,
            fmi2GetRealOutputDerivatives(s.c, vr.as_ptr(), 1, order.as_ptr(), out.as_mut_ptr()),
            &["fmi2GetRealOutputDerivatives", "not provided"],
        );
    }
    assert_refused(
        &s,
        fmi2CancelStep(s.c),
        &["fmi2CancelStep", "no pending step"],
    );
}

// ---------------------------------------------------------------------------------------------
// fmi2DoStep arguments

#[test]
fn do_step_refuses_non_positive_or_non_finite_step_sizes() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_reals(&[U], &[1.0]), fmi2OK);
    for h in [0.0, -0.0, -0.1, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let before = observe(&s);
        assert_refused(
            &s,
            s.step(0.0, h),
            &[
                "fmi2DoStep",
                "communicationStepSize must be > 0 and finite",
                &format!("was {h}"),
            ],
        );
        assert_eq!(observe(&s), before);
    }
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    assert_eq!(s.real(X), 0.1);
}

#[test]
fn do_step_refuses_a_communication_point_that_is_not_the_end_of_the_last_step() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_reals(&[U], &[1.0]), fmi2OK);
    assert_eq!(s.step(0.0, 0.25), fmi2OK);
    for t in [0.5, 0.0, 0.2, 0.25 + 1e-6, f64::NAN, f64::INFINITY] {
        let before = observe(&s);
        assert_refused(
            &s,
            s.step(t, 0.25),
            &[
                "fmi2DoStep",
                &format!("expected currentCommunicationPoint = 0.25 but was {t}"),
            ],
        );
        assert_eq!(
            observe(&s),
            before,
            "a refused step at {t} changed the state"
        );
    }
    assert_eq!(s.step(0.25, 0.25), fmi2OK);
    assert_eq!(s.real(X), 0.5);
    let mut last = 0.0;
    // SAFETY: valid instance and out pointer.
    assert_eq!(
        unsafe { fmi2GetRealStatus(s.c, fmi2LastSuccessfulTime, &mut last) },
        fmi2OK
    );
    assert_eq!(last, 0.5);
}

#[test]
fn do_step_accepts_a_host_time_that_differs_only_by_rounding() {
    let s = Slave::initialized(guid());
    let h = 0.1;
    // The host computes k·h; the FMU's time is the sum of (t + h) — they differ in the last bits.
    let mut differed = 0;
    let mut fmu_time = 0.0f64;
    for k in 0..2048 {
        let t = f64::from(k) * h;
        if t != fmu_time {
            differed += 1;
        }
        assert_eq!(
            s.step(t, h),
            fmi2OK,
            "step {k} at {t}: {:#?}",
            s.host.records()
        );
        fmu_time = t + h;
    }
    assert!(differed > 0, "the test must exercise rounding differences");
    // A last-bits difference the other way, explicitly.
    let t = 2048.0 * h;
    assert_eq!(s.step(t * (1.0 + 1e-13), h), fmi2OK);
    assert!(s.host.records().is_empty(), "{:#?}", s.host.records());
}

#[test]
fn do_step_refuses_to_go_past_the_stop_time() {
    let s = Slave::new(guid());
    assert_eq!(s.setup(0.0, Some(1.0)), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_eq!(s.exit(), fmi2OK);
    assert_eq!(s.step(0.0, 0.75), fmi2OK);
    assert_refused(&s, s.step(0.75, 0.5), &["fmi2DoStep", "past stopTime = 1"]);
    assert_eq!(
        s.step(0.75, 0.25),
        fmi2OK,
        "landing exactly on the stop time is fine"
    );
}

// ---------------------------------------------------------------------------------------------
// A diverging model

#[test]
fn a_diverging_step_is_an_error_that_an_earlier_fmu_state_recovers() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_reals(&[U], &[1.0]), fmi2OK);
    assert_eq!(s.step(0.0, 0.5), fmi2OK);
    let state = s.get_state();
    let good = observe(&s);

    assert_eq!(s.set_booleans(&[DIVERGE], &[fmi2True]), fmi2OK);
    assert_refused(
        &s,
        s.step(0.5, 0.5),
        &[
            "fmi2DoStep",
            "the state diverged at t = 1",
            "the diverge input is set",
        ],
    );
    // The instance is now in the Error state: no more steps, but values can be read.
    assert_refused(
        &s,
        s.step(0.5, 0.5),
        &[
            "fmi2DoStep",
            "not allowed in state Error",
            "expected state StepComplete",
        ],
    );
    assert_refused(
        &s,
        s.set_reals(&[U], &[2.0]),
        &["fmi2SetReal", "not allowed in state Error"],
    );
    assert!(
        s.real(X).is_nan(),
        "the model's state is what the failed step left"
    );
    let mut last = 0.0;
    // SAFETY: valid instance and out pointer.
    assert_eq!(
        unsafe { fmi2GetRealStatus(s.c, fmi2LastSuccessfulTime, &mut last) },
        fmi2OK
    );
    assert_eq!(last, 0.5, "the failed step did not advance the time");

    // Recover to the snapshot: the values are those of the snapshot and stepping works again.
    assert_eq!(s.set_state(state), fmi2OK);
    assert_eq!(observe(&s), good);
    assert_eq!(s.step(0.5, 0.5), fmi2OK, "{:#?}", s.host.records());
    assert_eq!(s.real(X), 1.0);
    s.free_state(state);
}

#[test]
fn a_diverged_instance_can_be_reset_or_terminated() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_booleans(&[DIVERGE], &[fmi2True]), fmi2OK);
    assert_eq!(s.step(0.0, 0.1), fmi2Error);
    assert_eq!(s.terminate(), fmi2OK, "terminate is allowed from Error");
    assert_eq!(s.reset(), fmi2OK);
    s.initialize();
    assert_eq!(s.real(X), 0.0);
    let (status, diverge) = s.get_booleans(&[DIVERGE]);
    assert_eq!((status, diverge), (fmi2OK, vec![fmi2False]));
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

// ---------------------------------------------------------------------------------------------
// FMU state

fn run(s: &Slave, t0: f64, steps: usize, h: f64) -> Vec<u64> {
    let mut out = Vec::new();
    for k in 0..steps {
        let t = t0 + k as f64 * h;
        assert_eq!(s.set_reals(&[U], &[(t * 3.0).sin()]), fmi2OK);
        assert_eq!(
            s.set_input_derivatives(&[U], &[1], &[3.0 * (t * 3.0).cos()]),
            fmi2OK
        );
        assert_eq!(s.step(t, h), fmi2OK, "{:#?}", s.host.records());
        out.extend(s.get_reals(&[Y, X, U]).1.iter().map(|x| x.to_bits()));
    }
    out
}

#[test]
fn get_and_set_fmu_state_restore_the_outputs_exactly() {
    let s = Slave::initialized(guid());
    run(&s, 0.0, 10, 0.1);
    let state = s.get_state();
    let at_snapshot = observe(&s);
    let continued = run(&s, 1.0, 10, 0.1);
    assert_ne!(observe(&s), at_snapshot);
    assert_eq!(s.set_state(state), fmi2OK);
    assert_eq!(observe(&s), at_snapshot);
    assert_eq!(run(&s, 1.0, 10, 0.1), continued, "the same continuation");
    // The time went back too: the step after the snapshot's end is refused now at t = 2.
    assert_eq!(s.set_state(state), fmi2OK);
    assert_refused(
        &s,
        s.step(2.0, 0.1),
        &["expected currentCommunicationPoint = 1"],
    );
    // Overwriting an existing state in its slot updates it in place.
    let mut slot = state;
    run(&s, 1.0, 5, 0.1);
    // SAFETY: the slot holds a state of this library.
    assert_eq!(unsafe { fmi2GetFMUstate(s.c, &mut slot) }, fmi2OK);
    assert_eq!(slot, state);
    let at_update = observe(&s);
    run(&s, 1.5, 3, 0.1);
    assert_eq!(s.set_state(slot), fmi2OK);
    assert_eq!(observe(&s), at_update);
    s.free_state(slot);
}

#[test]
fn a_serialized_fmu_state_continues_bit_identically_in_this_and_another_instance() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_reals(&[OFFSET], &[0.125]), fmi2OK);
    run(&s, 0.0, 7, 0.1);
    let state = s.get_state();
    let bytes = s.serialize(state);
    s.free_state(state);
    let reference = run(&s, 0.7, 20, 0.1);

    let (status, restored) = s.deserialize(&bytes);
    assert_eq!(status, fmi2OK, "{:#?}", s.host.records());
    assert_eq!(s.set_state(restored), fmi2OK);
    assert_eq!(run(&s, 0.7, 20, 0.1), reference);
    s.free_state(restored);

    // Another instance, still in Instantiated, takes the state over whole (including its state machine).
    let other = Slave::new(guid());
    let (status, restored) = other.deserialize(&bytes);
    assert_eq!(status, fmi2OK);
    assert_eq!(other.set_state(restored), fmi2OK);
    assert_eq!(run(&other, 0.7, 20, 0.1), reference);
    other.free_state(restored);

    // Serializing into a buffer that is too small is refused.
    let state = s.get_state();
    let mut small = vec![0 as fmi2Byte; bytes.len() - 1];
    // SAFETY: `small` has its length in writable bytes.
    let status = unsafe { fmi2SerializeFMUstate(s.c, state, small.as_mut_ptr(), small.len()) };
    assert_refused(
        &s,
        status,
        &[
            "fmi2SerializeFMUstate",
            "the buffer has",
            "bytes but the state needs",
        ],
    );
    s.free_state(state);
}

#[test]
fn deserializing_garbage_or_a_truncated_state_is_refused() {
    let s = Slave::initialized(guid());
    run(&s, 0.0, 3, 0.1);
    let state = s.get_state();
    let bytes = s.serialize(state);
    s.free_state(state);
    let before = observe(&s);

    let garbage: Vec<u8> = (0..bytes.len()).map(|i| (i * 131 % 251) as u8).collect();
    let mut header_only = bytes.clone();
    header_only.truncate(bytes.len() / 2);
    let mut wrong_magic = bytes.clone();
    let header_len = b"STWIN-FMUSTATE-1 ".len() + guid().len();
    wrong_magic[header_len] ^= 0x55;
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("garbage", garbage),
        ("empty", Vec::new()),
        ("truncated to the half", header_only),
        ("truncated by one byte", bytes[..bytes.len() - 1].to_vec()),
        ("header only", bytes[..header_len].to_vec()),
        ("another model's header", {
            let mut b = bytes.clone();
            b[header_len - 2] ^= 0x01;
            b
        }),
        ("a flipped magic", wrong_magic),
    ];
    for (what, data) in cases {
        let (status, restored) = s.deserialize(&data);
        assert_eq!(status, fmi2Error, "{what}: {:#?}", s.host.records());
        assert!(restored.is_null(), "{what}: no state handed out");
        let record = s.host.expect(
            fmi2Error,
            &["fmi2DeSerializeFMUstate", "serialized FMU state"],
        );
        assert!(
            record.message.contains("corrupt") || record.message.contains("not made by this model"),
            "{what}: {record:?}"
        );
        s.host.clear();
    }
    assert_eq!(observe(&s), before);
    // The intact bytes still work.
    let (status, restored) = s.deserialize(&bytes);
    assert_eq!(status, fmi2OK);
    s.free_state(restored);
}

#[test]
fn a_state_from_the_wrong_place_is_refused() {
    let s = Slave::initialized(guid());
    // An fmi2FMUstate that points at something that is not a state of this library.
    let mut not_a_state = [0u64; 64];
    let bogus = not_a_state.as_mut_ptr().cast::<std::ffi::c_void>();
    assert_refused(
        &s,
        s.set_state(bogus),
        &["fmi2SetFMUstate", "not a state of this FMU"],
    );
    let mut slot = bogus;
    // SAFETY: the slot holds a pointer the layer must recognise as foreign.
    assert_refused(
        &s,
        unsafe { fmi2GetFMUstate(s.c, &mut slot) },
        &["fmi2GetFMUstate", "does not point to a state of this FMU"],
    );
    assert_eq!(slot, bogus);
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

// ---------------------------------------------------------------------------------------------
// Debug logging

#[test]
fn an_unknown_log_category_is_refused_and_changes_nothing() {
    let s = Slave::initialized(guid());
    assert_refused(
        &s,
        s.debug_logging(true, &["logCalls", "logEverything"]),
        &[
            "fmi2SetDebugLogging",
            "unknown log category 'logEverything'",
            "logStatusError",
            "logCalls",
        ],
    );
    // Debug logging is still off: a call is not logged.
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    assert!(s.host.records().is_empty(), "{:#?}", s.host.records());
}

#[test]
fn with_log_calls_on_each_call_is_logged_and_with_debug_logging_off_none_is() {
    let s = Slave::initialized(guid());
    assert_eq!(s.debug_logging(true, &["logCalls"]), fmi2OK);
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    let _ = s.get_reals(&[Y]);
    let records = s.host.records();
    let calls: Vec<&str> = records
        .iter()
        .filter(|r| r.category == "logCalls")
        .map(|r| r.message.as_str())
        .collect();
    assert_eq!(calls, ["fmi2DoStep", "fmi2GetReal"], "{records:#?}");
    assert!(records
        .iter()
        .all(|r| r.status == fmi2OK && r.format == "%s" && r.instance == "slave"));
    s.host.clear();

    assert_eq!(s.debug_logging(false, &[]), fmi2OK);
    s.host.expect(fmi2OK, &["fmi2SetDebugLogging"]);
    s.host.clear();
    assert_eq!(s.step(0.1, 0.1), fmi2OK);
    let _ = s.get_reals(&[Y]);
    assert!(
        s.host.records().is_empty(),
        "debug logging off: {:#?}",
        s.host.records()
    );
    // Errors are still reported with debug logging off.
    assert_refused(
        &s,
        s.step(0.0, 0.1),
        &["expected currentCommunicationPoint"],
    );

    // On with no categories: all of them.
    assert_eq!(s.debug_logging(true, &[]), fmi2OK);
    assert_eq!(s.step(0.2, 0.1), fmi2OK);
    s.host.expect(fmi2OK, &["fmi2DoStep"]);
}

#[test]
fn instantiating_with_logging_on_logs_calls_from_the_start() {
    let s = Slave::with_host(Host::new(), guid(), true);
    assert_eq!(s.enter(), fmi2OK);
    let record = s.host.expect(fmi2OK, &["fmi2EnterInitializationMode"]);
    assert_eq!(record.category, "logCalls");
}

#[test]
fn percent_signs_in_messages_reach_a_real_c_variadic_logger_literally() {
    // fmi-sys's `callback_logger_handler` is a C function with a real `...`: it runs
    // `vsnprintf(format, args)`. Were the message itself passed as the format, the "%s" and "%n"
    // below would read and write through garbage pointers; with the format "%s" they are text.
    let callbacks = fmi2CallbackFunctions {
        logger: Some(fmi_sys::fmi2::logger::callback_logger_handler),
        allocate_memory: None,
        free_memory: None,
        step_finished: None,
        component_environment: std::ptr::null_mut(),
    };
    let name: CString = cstring("%s%n%s%n%s%n");
    let guid_text = cstring(guid());
    // SAFETY: valid strings and callbacks.
    let c = unsafe {
        fmi2Instantiate(
            name.as_ptr(),
            fmi2CoSimulation,
            guid_text.as_ptr(),
            std::ptr::null(),
            &callbacks,
            fmi2False,
            fmi2True,
        )
    };
    assert!(!c.is_null());
    let categories = [c"%s%s%s%n%n%n".as_ptr()];
    // SAFETY: one valid category string.
    assert_eq!(
        unsafe { fmi2SetDebugLogging(c, fmi2True, 1, categories.as_ptr()) },
        fmi2Error
    );
    assert_eq!(fmi2EnterInitializationMode(c), fmi2OK, "logged as a call");
    assert_eq!(
        fmi2DoStep(c, 0.0, 0.1, fmi2True),
        fmi2Error,
        "refused, and logged"
    );
    // SAFETY: from fmi2Instantiate, freed once.
    unsafe { fmi2FreeInstance(c) };
    // A refused instantiation logs through it too.
    let bad_guid = cstring("%s%n{bad}");
    // SAFETY: as above.
    let c = unsafe {
        fmi2Instantiate(
            name.as_ptr(),
            fmi2CoSimulation,
            bad_guid.as_ptr(),
            std::ptr::null(),
            &callbacks,
            fmi2False,
            fmi2True,
        )
    };
    assert!(c.is_null());
}
