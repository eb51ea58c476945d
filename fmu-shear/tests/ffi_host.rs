//! The shear FMU driven through its C exports as a host drives it: the model's own checks
//! (masses, sub-steps, fixed parameters), direct feedthrough from force to acceleration, a
//! diverging parameter set reported as an error rather than as non-finite outputs, and FMU
//! states that continue bit-identically.

// The test host (recording logger, thin wrappers over the C functions) is the one the export
// layer's own tests use; it calls the `fmi2*` functions at this crate's root.
#[path = "../../fmi2/tests/common/mod.rs"]
mod common;

use fmu_shear::{
    fmi2DeSerializeFMUstate, fmi2DoStep, fmi2EnterInitializationMode, fmi2ExitInitializationMode,
    fmi2FreeFMUstate, fmi2FreeInstance, fmi2GetBoolean, fmi2GetFMUstate, fmi2GetInteger,
    fmi2GetReal, fmi2GetString, fmi2Instantiate, fmi2Reset, fmi2SerializeFMUstate,
    fmi2SerializedFMUstateSize, fmi2SetBoolean, fmi2SetDebugLogging, fmi2SetFMUstate,
    fmi2SetInteger, fmi2SetReal, fmi2SetRealInputDerivatives, fmi2SetString, fmi2SetupExperiment,
    fmi2Terminate,
};

use common::{instantiate_raw, Host, Slave};
use fmi2::abi::*;
use fmu_shear::variables::{
    ACC, CONTROL_FORCE, DAMPING, DISP, DISP_START, DRIFT, FORCE, MASS, STIFFNESS, SUBSTEPS, VEL,
    VEL_START,
};

/// contact23_enabled: a fixed Boolean parameter of the effect library.
const CONTACT23_ENABLED: u32 = 120;
/// The examples' sampling interval.
const H: f64 = 1.0 / 51.2;

fn guid() -> &'static str {
    &fmu_shear::variables::info().guid
}

fn outputs() -> Vec<u32> {
    (0..3)
        .flat_map(|i| [ACC + i, DISP + i, VEL + i, DRIFT + i])
        .collect()
}

/// Parameters and outputs, as bit patterns.
fn observe(s: &Slave) -> (Vec<u64>, Vec<i32>, Vec<fmi2Boolean>) {
    let mut vrs = outputs();
    vrs.extend((0..3).flat_map(|i| [MASS + i, DAMPING + i, STIFFNESS + i]));
    vrs.extend([FORCE, CONTROL_FORCE]);
    let (status, reals) = s.get_reals(&vrs);
    assert_eq!(status, fmi2OK, "{:#?}", s.host.records());
    let (status, ints) = s.get_integers(&[SUBSTEPS]);
    assert_eq!(status, fmi2OK);
    let (status, bools) = s.get_booleans(&[CONTACT23_ENABLED]);
    assert_eq!(status, fmi2OK);
    (reals.iter().map(|x| x.to_bits()).collect(), ints, bools)
}

#[track_caller]
fn assert_refused(s: &Slave, status: fmi2Status, needles: &[&str]) {
    assert_eq!(
        status,
        fmi2Error,
        "expected fmi2Error; logged: {:#?}",
        s.host.records()
    );
    s.host.expect(fmi2Error, needles);
    s.host.clear();
}

/// Shake floor 1 with a smooth force, as ramps between the points; return the outputs after each step.
fn shake(s: &Slave, first_step: usize, steps: usize) -> Vec<u64> {
    let force = |t: f64| 3.0 * (2.0 * std::f64::consts::PI * 4.1 * t).sin();
    let mut out = Vec::new();
    for k in first_step..first_step + steps {
        let t = k as f64 * H;
        assert_eq!(s.set_reals(&[FORCE], &[force(t)]), fmi2OK);
        assert_eq!(
            s.set_input_derivatives(&[FORCE], &[1], &[(force(t + H) - force(t)) / H]),
            fmi2OK
        );
        assert_eq!(s.step(t, H), fmi2OK, "step {k}: {:#?}", s.host.records());
        let (status, values) = s.get_reals(&outputs());
        assert_eq!(status, fmi2OK);
        out.extend(values.iter().map(|x| x.to_bits()));
    }
    out
}

#[test]
fn non_positive_masses_and_negative_damping_or_stiffness_are_refused() {
    let s = Slave::new(guid());
    assert_eq!(s.enter(), fmi2OK);
    let before = observe(&s);
    assert_refused(
        &s,
        s.set_reals(&[MASS], &[-1.0]),
        &["fmi2SetReal", "invalid value for 'm1'", "-1 must be > 0"],
    );
    assert_refused(
        &s,
        s.set_reals(&[MASS + 2], &[0.0]),
        &["invalid value for 'm3'", "0 must be > 0"],
    );
    assert_refused(
        &s,
        s.set_reals(&[DAMPING + 1], &[-0.1]),
        &["invalid value for 'c2'", "must be ≥ 0"],
    );
    assert_refused(
        &s,
        s.set_reals(&[STIFFNESS], &[-4021.0]),
        &["invalid value for 'k1'", "must be ≥ 0"],
    );
    // A batch with one bad mass sets none of its values.
    assert_refused(
        &s,
        s.set_reals(&[MASS, MASS + 1, FORCE], &[6.0, -2.0, 1.0]),
        &["invalid value for 'm2'"],
    );
    assert_eq!(observe(&s), before);
    assert_eq!(s.real(MASS), 5.2);
    // Valid values are taken.
    assert_eq!(
        s.set_reals(&[MASS, DAMPING + 1, STIFFNESS], &[6.0, 0.0, 0.0]),
        fmi2OK
    );
    assert_eq!(
        s.get_reals(&[MASS, DAMPING + 1, STIFFNESS]).1,
        vec![6.0, 0.0, 0.0]
    );
}

#[test]
fn substeps_outside_their_range_are_refused_and_fixed_after_initialization() {
    let s = Slave::new(guid());
    assert_eq!(s.enter(), fmi2OK);
    let before = observe(&s);
    for bad in [0, -1, 10_001, i32::MIN] {
        assert_refused(
            &s,
            s.set_integers(&[SUBSTEPS], &[bad]),
            &[
                "fmi2SetInteger",
                "invalid value for 'substeps'",
                &format!("{bad} is outside [1, 10000]"),
            ],
        );
    }
    assert_eq!(observe(&s), before);
    assert_eq!(
        s.get_integers(&[SUBSTEPS]).1,
        vec![fmu_shear::DEFAULT_SUBSTEPS as i32]
    );
    assert_eq!(s.set_integers(&[SUBSTEPS], &[1]), fmi2OK);
    assert_eq!(s.exit(), fmi2OK);
    assert_refused(
        &s,
        s.set_integers(&[SUBSTEPS], &[4]),
        &["'substeps' is a fixed parameter"],
    );
    assert_refused(
        &s,
        s.set_reals(&[MASS], &[6.0]),
        &["'m1' is a fixed parameter"],
    );
    assert_refused(
        &s,
        s.set_booleans(&[CONTACT23_ENABLED], &[fmi2True]),
        &["'contact23_enabled' is a fixed parameter"],
    );
    assert_refused(
        &s,
        s.set_reals(&[ACC], &[1.0]),
        &["'acc1' has causality output and cannot be set"],
    );
    assert_eq!(s.get_integers(&[SUBSTEPS]).1, vec![1]);
}

#[test]
fn unknown_value_references_of_every_type_are_refused() {
    let s = Slave::initialized(guid());
    let before = observe(&s);
    assert_refused(
        &s,
        s.get_reals(&[ACC, 9999]).0,
        &["unknown value reference 9999 for a Real variable"],
    );
    assert_refused(
        &s,
        s.set_reals(&[FORCE, 9999], &[1.0, 1.0]),
        &["unknown value reference 9999 for a Real variable"],
    );
    assert_refused(
        &s,
        s.get_integers(&[9999]).0,
        &["unknown value reference 9999 for a Integer variable"],
    );
    assert_refused(
        &s,
        s.set_integers(&[9999], &[1]),
        &["unknown value reference 9999 for a Integer variable"],
    );
    assert_refused(
        &s,
        s.get_booleans(&[9999]).0,
        &["unknown value reference 9999 for a Boolean variable"],
    );
    assert_refused(
        &s,
        s.set_booleans(&[9999], &[fmi2True]),
        &["unknown value reference 9999 for a Boolean variable"],
    );
    assert_refused(
        &s,
        s.get_strings(&[1]).0,
        &["unknown value reference 1 for a String variable"],
    );
    assert_refused(
        &s,
        s.set_strings(&[1], &["x"]),
        &["unknown value reference 1 for a String variable"],
    );
    assert_eq!(observe(&s), before);
}

#[test]
fn non_finite_forces_are_refused_and_change_nothing() {
    let s = Slave::initialized(guid());
    shake(&s, 0, 10);
    let before = observe(&s);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_refused(
            &s,
            s.set_reals(&[FORCE, CONTROL_FORCE], &[1.0, bad]),
            &["'control_force'", "only finite reals"],
        );
        assert_refused(
            &s,
            s.set_input_derivatives(&[FORCE], &[1], &[bad]),
            &["derivative of 'force'"],
        );
    }
    assert_eq!(observe(&s), before);
}

#[test]
fn accelerations_reflect_a_force_set_after_the_last_step() {
    let s = Slave::initialized(guid());
    shake(&s, 0, 25);
    let acc = [ACC, ACC + 1, ACC + 2];
    let (_, before) = s.get_reals(&acc);
    let force = s.real(FORCE);
    let control = s.real(CONTROL_FORCE);
    // No step in between: only the direct feedthrough φ (force − control_force) / m1 can move acc1.
    assert_eq!(s.set_reals(&[FORCE], &[force + 2.6]), fmi2OK);
    let (_, after) = s.get_reals(&acc);
    let expected = 2.6 / 5.2;
    assert!(
        ((after[0] - before[0]) - expected).abs() < 1e-12,
        "acc1 {} → {}",
        before[0],
        after[0]
    );
    assert_eq!(
        after[1].to_bits(),
        before[1].to_bits(),
        "acc2 has no direct dependency"
    );
    assert_eq!(
        after[2].to_bits(),
        before[2].to_bits(),
        "acc3 has no direct dependency"
    );
    assert_eq!(s.set_reals(&[CONTROL_FORCE], &[control + 5.2]), fmi2OK);
    let (_, countered) = s.get_reals(&acc);
    assert!(
        ((countered[0] - after[0]) + 1.0).abs() < 1e-12,
        "the control force acts against the excitation"
    );
}

/// A batch of reads mixing accelerations with other variables (their state checked once for
/// the call) gives each value a read of its own gives, after steps and after an input set
/// between steps.
#[test]
fn a_batch_read_equals_the_reads_one_by_one() {
    let s = Slave::initialized(guid());
    shake(&s, 0, 25);
    let mut vrs = vec![
        ACC + 2,
        FORCE,
        DISP + 1,
        ACC,
        CONTROL_FORCE,
        ACC + 1,
        VEL + 2,
        ACC,
    ];
    vrs.extend((0..3).map(|i| DRIFT + i));
    let bits = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
    for change in [None, Some(1.7)] {
        if let Some(df) = change {
            let force = s.real(FORCE);
            assert_eq!(s.set_reals(&[FORCE], &[force + df]), fmi2OK);
        }
        let (status, batch) = s.get_reals(&vrs);
        assert_eq!(status, fmi2OK);
        let single: Vec<f64> = vrs.iter().map(|&vr| s.real(vr)).collect();
        assert_eq!(
            bits(batch),
            bits(single),
            "after a force change: {change:?}"
        );
    }
}

/// Steps from rest under a constant force with every storey stiffness `k` and one RK4 step per
/// sample, until a step fails; asserts that every step reporting fmi2OK left finite outputs.
/// Returns the index of the failed step, if one failed within `max_steps`.
fn run_until_failure(s: &Slave, k: f64, max_steps: usize) -> Option<usize> {
    assert_eq!(s.setup(0.0, None), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_eq!(
        s.set_reals(&[STIFFNESS, STIFFNESS + 1, STIFFNESS + 2], &[k, k, k]),
        fmi2OK
    );
    assert_eq!(s.set_integers(&[SUBSTEPS], &[1]), fmi2OK);
    assert_eq!(s.exit(), fmi2OK);
    assert_eq!(s.set_reals(&[FORCE], &[1.0]), fmi2OK);
    for step in 0..max_steps {
        let status = s.step(step as f64 * H, H);
        if status != fmi2OK {
            assert_eq!(status, fmi2Error);
            return Some(step);
        }
        let (status, values) = s.get_reals(&outputs());
        assert_eq!(status, fmi2OK);
        assert!(
            values.iter().all(|x| x.is_finite()),
            "k = {k:e}: step {step} returned fmi2OK with outputs (acc, disp, vel, drift per floor) {values:?}"
        );
    }
    None
}

#[test]
fn a_diverging_parameter_set_is_an_error_not_non_finite_outputs() {
    let s = Slave::new(guid());
    // Absurd: storeys a billion times too stiff, one RK4 step per sample (ω·h ≈ 17,000, far
    // beyond RK4's stability limit of about 2.8).
    let start = s.get_state();
    let failed =
        run_until_failure(&s, 4e12, 10_000).expect("the simulation diverges within 10,000 steps");
    s.host
        .expect(fmi2Error, &["fmi2DoStep", "the state diverged", "substeps"]);
    s.host.clear();
    // The instance is in the Error state: no further step.
    assert_refused(
        &s,
        s.step(failed as f64 * H, H),
        &["not allowed in state Error"],
    );
    // The state taken right after instantiation brings it back: set up again, the default
    // parameters run.
    assert_eq!(s.set_state(start), fmi2OK);
    s.initialize();
    shake(&s, 0, 100);
    s.free_state(start);
}

/// Outputs can overflow to ±inf one step before the state does: the accelerations (k·y/m)
/// overflow while displacement and velocity are still finite. `ShearModel::do_step` checks the
/// accelerations too, so no step that leaves non-finite outputs reports fmi2OK.
#[test]
fn no_diverging_stiffness_gets_a_successful_step_with_non_finite_outputs() {
    for k in [1.5e7, 1e8, 1e9, 1e10, 1e11, 4e12] {
        let s = Slave::new(guid());
        assert!(
            run_until_failure(&s, k, 10_000).is_some(),
            "k = {k:e} diverges"
        );
    }
}

#[test]
fn fmu_states_restore_exactly_and_serialized_ones_continue_bit_identically() {
    let s = Slave::new(guid());
    assert_eq!(s.setup(0.0, None), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_eq!(s.set_booleans(&[CONTACT23_ENABLED], &[fmi2True]), fmi2OK);
    assert_eq!(s.exit(), fmi2OK);
    shake(&s, 0, 200);
    let state = s.get_state();
    let at_snapshot = observe(&s);
    let bytes = s.serialize(state);
    let reference = shake(&s, 200, 300);
    assert_ne!(observe(&s), at_snapshot);

    assert_eq!(s.set_state(state), fmi2OK);
    assert_eq!(observe(&s), at_snapshot);
    assert_eq!(shake(&s, 200, 300), reference, "in-memory state");
    s.free_state(state);

    let (status, restored) = s.deserialize(&bytes);
    assert_eq!(status, fmi2OK);
    assert_eq!(s.set_state(restored), fmi2OK);
    assert_eq!(
        shake(&s, 200, 300),
        reference,
        "serialized state, same instance"
    );
    s.free_state(restored);

    let other = Slave::new(guid());
    let (status, restored) = other.deserialize(&bytes);
    assert_eq!(status, fmi2OK);
    assert_eq!(other.set_state(restored), fmi2OK);
    assert_eq!(
        observe(&other),
        at_snapshot,
        "parameters and effects came along"
    );
    assert_eq!(
        shake(&other, 200, 300),
        reference,
        "serialized state, another instance"
    );
    other.free_state(restored);

    for cut in [0, 10, bytes.len() / 2, bytes.len() - 1] {
        let (status, restored) = other.deserialize(&bytes[..cut]);
        assert_eq!(status, fmi2Error, "truncated to {cut} bytes");
        assert!(restored.is_null());
    }
}

/// A run started from the displacements and velocities another reached (`disp{i}_start`,
/// `vel{i}_start`) continues it bit for bit, with a contact on; a non-finite start value is
/// refused, and a reset starts at rest again.
#[test]
fn a_run_from_a_given_state_continues_the_run_that_reached_it() {
    let first = Slave::new(guid());
    assert_eq!(first.setup(0.0, None), fmi2OK);
    assert_eq!(first.enter(), fmi2OK);
    assert_eq!(
        first.set_booleans(&[CONTACT23_ENABLED], &[fmi2True]),
        fmi2OK
    );
    assert_eq!(first.exit(), fmi2OK);
    shake(&first, 0, 200);
    let state_vrs: Vec<u32> = (0..3)
        .map(|i| DISP + i)
        .chain((0..3).map(|i| VEL + i))
        .collect();
    let (status, state) = first.get_reals(&state_vrs);
    assert_eq!(status, fmi2OK);
    assert!(state.iter().any(|&x| x != 0.0));
    let reference = shake(&first, 200, 300);

    let second = Slave::new(guid());
    assert_eq!(second.setup(200.0 * H, None), fmi2OK);
    assert_eq!(second.enter(), fmi2OK);
    assert_eq!(
        second.set_booleans(&[CONTACT23_ENABLED], &[fmi2True]),
        fmi2OK
    );
    let start_vrs: Vec<u32> = (0..3)
        .map(|i| DISP_START + i)
        .chain((0..3).map(|i| VEL_START + i))
        .collect();
    assert_refused(
        &second,
        second.set_reals(&[DISP_START], &[f64::NAN]),
        &["disp1_start"],
    );
    assert_eq!(second.set_reals(&start_vrs, &state), fmi2OK);
    assert_eq!(second.get_reals(&start_vrs).1, state);
    assert_eq!(second.exit(), fmi2OK);
    assert_eq!(shake(&second, 200, 300), reference);

    assert_eq!(second.reset(), fmi2OK);
    assert_eq!(second.setup(0.0, None), fmi2OK);
    assert_eq!(second.enter(), fmi2OK);
    assert_eq!(second.get_reals(&state_vrs).1, vec![0.0; 6]);
    assert_eq!(second.get_reals(&start_vrs).1, vec![0.0; 6]);
}

#[test]
fn instantiate_checks_the_guid_of_the_shear_fmu() {
    let host = Host::new();
    let c = instantiate_raw(
        Some("shear"),
        fmi2CoSimulation,
        Some("{00000000-0000-0000-0000-000000000000}"),
        Some(&host.callbacks()),
        false,
    );
    assert!(c.is_null());
    host.expect(fmi2Error, &["GUID mismatch", guid()]);
    let c = instantiate_raw(
        Some("shear"),
        fmi2ModelExchange,
        Some(guid()),
        Some(&host.callbacks()),
        false,
    );
    assert!(c.is_null());
    host.expect(fmi2Error, &["co-simulation only"]);
}

#[test]
fn input_derivatives_are_first_order_on_inputs_only() {
    let s = Slave::initialized(guid());
    assert_refused(
        &s,
        s.set_input_derivatives(&[FORCE], &[2], &[1.0]),
        &["derivative order 2 for 'force'"],
    );
    assert_refused(
        &s,
        s.set_input_derivatives(&[ACC], &[1], &[1.0]),
        &[&format!("'acc1' (vr {ACC}) is not an input")],
    );
    assert_refused(
        &s,
        s.set_input_derivatives(&[MASS], &[1], &[1.0]),
        &[&format!("'m1' (vr {MASS}) is not an input")],
    );
    // A ramp of the force over one step ends at value + slope·h.
    assert_eq!(
        s.set_input_derivatives(&[FORCE, CONTROL_FORCE], &[1, 1], &[2.0, 0.5]),
        fmi2OK
    );
    assert_eq!(s.step(0.0, 0.5), fmi2OK);
    assert_eq!(s.get_reals(&[FORCE, CONTROL_FORCE]).1, vec![1.0, 0.25]);
}

#[test]
fn wrong_call_order_is_refused_by_the_shear_fmu_too() {
    let s = Slave::new(guid());
    assert_refused(
        &s,
        s.step(0.0, H),
        &[
            "fmi2DoStep",
            "not allowed in state Instantiated",
            "expected state StepComplete",
        ],
    );
    assert_refused(
        &s,
        s.get_reals(&[ACC]).0,
        &["fmi2GetReal", "not allowed in state Instantiated"],
    );
    s.initialize();
    assert_refused(
        &s,
        s.step(1.0, H),
        &["expected currentCommunicationPoint = 0 but was 1"],
    );
    assert_eq!(s.step(0.0, H), fmi2OK);
    assert_eq!(s.terminate(), fmi2OK);
    assert_refused(&s, s.step(H, H), &["not allowed in state Terminated"]);
}
