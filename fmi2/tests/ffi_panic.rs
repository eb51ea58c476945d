//! A model that panics on demand, driven through the C exports: every panic becomes fmi2Fatal
//! (or a null instance from fmi2Instantiate) and a log message with the panic's text, the host
//! process carries on, the instance refuses everything afterwards and can still be freed.

mod common;

fmi2::export_fmu!(crate::PanickingModel);

use std::sync::OnceLock;

use common::{instantiate_raw, Host, Slave};
use fmi2::abi::*;
use fmi2::{CoSimModel, InstantiateContext, ModelError, ModelInfo, Unit, Variable};
use serde::{Deserialize, Serialize};

const PANIC_IN_STEP: u32 = 1;
const PANIC_IN_GET: u32 = 2;
const PANIC_IN_EXIT: u32 = 3;
const PANIC_ON_DROP: u32 = 4;
/// Real input; setting it to `PANIC_VALUE` panics, to `PANIC_ANY_VALUE` panics with a non-text payload.
const U: u32 = 5;
const Y: u32 = 6;
const PANIC_VALUE: f64 = 666.0;
const PANIC_ANY_VALUE: f64 = 42.0;
const PANICKING_INSTANCE_NAME: &str = "panic in instantiate";

fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "Panicking",
            "panicking",
            "test model that panics on demand",
            "1",
            vec![
                Variable::boolean_input("panic_in_step", PANIC_IN_STEP, false),
                Variable::boolean_input("panic_in_get", PANIC_IN_GET, false),
                Variable::boolean_parameter("panic_in_exit", PANIC_IN_EXIT, false),
                Variable::boolean_input("panic_on_drop", PANIC_ON_DROP, false),
                Variable::real_input("u", U, "1", 0.0),
                Variable::real_output("y", Y, "1").depends_on(&[U]),
            ],
            vec![Unit {
                name: "1",
                kg: 0,
                m: 0,
                s: 0,
            }],
            false,
            None,
        )
        .expect("consistent table")
    })
}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PanickingModel {
    flags: [bool; 4],
    u: f64,
    y: f64,
}

impl Drop for PanickingModel {
    fn drop(&mut self) {
        if self.flags[(PANIC_ON_DROP - 1) as usize] && !std::thread::panicking() {
            panic!("model exploded in drop (on purpose)");
        }
    }
}

impl CoSimModel for PanickingModel {
    fn info() -> &'static ModelInfo {
        info()
    }

    fn instantiate(context: &InstantiateContext) -> Result<Self, ModelError> {
        if context.instance_name == PANICKING_INSTANCE_NAME {
            panic!("model exploded in instantiate (on purpose)");
        }
        Ok(PanickingModel::default())
    }

    fn get_real(&mut self, vr: u32) -> Result<f64, ModelError> {
        if self.flags[(PANIC_IN_GET - 1) as usize] {
            panic!("model exploded in get_real (on purpose)");
        }
        match vr {
            U => Ok(self.u),
            Y => Ok(self.y),
            _ => Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        }
    }

    fn set_real(&mut self, vr: u32, value: f64) -> Result<(), ModelError> {
        if value == PANIC_VALUE {
            panic!("model exploded in set_real (on purpose)");
        }
        if value == PANIC_ANY_VALUE {
            std::panic::panic_any(42_i32);
        }
        match vr {
            U => self.u = value,
            _ => return Err(ModelError::UnknownVariable { vr, kind: "Real" }),
        }
        Ok(())
    }

    fn get_boolean(&mut self, vr: u32) -> Result<bool, ModelError> {
        match vr {
            1..=4 => Ok(self.flags[(vr - 1) as usize]),
            _ => Err(ModelError::UnknownVariable {
                vr,
                kind: "Boolean",
            }),
        }
    }

    fn set_boolean(&mut self, vr: u32, value: bool) -> Result<(), ModelError> {
        match vr {
            1..=4 => self.flags[(vr - 1) as usize] = value,
            _ => {
                return Err(ModelError::UnknownVariable {
                    vr,
                    kind: "Boolean",
                })
            }
        }
        Ok(())
    }

    fn exit_initialization(&mut self) -> Result<(), ModelError> {
        if self.flags[(PANIC_IN_EXIT - 1) as usize] {
            panic!("model exploded in exit_initialization (on purpose)");
        }
        Ok(())
    }

    fn do_step(&mut self, _time: f64, step_size: f64) -> Result<(), ModelError> {
        if self.flags[(PANIC_IN_STEP - 1) as usize] {
            panic!("model exploded in do_step (on purpose)");
        }
        self.y += self.u * step_size;
        Ok(())
    }
}

fn guid() -> &'static str {
    &info().guid
}

/// The call panicked: fmi2Fatal, and a fatal log record with the panic's text.
#[track_caller]
fn assert_fatal(s: &Slave, status: fmi2Status, call: &str, text: &str) {
    assert_eq!(status, fmi2Fatal, "logged: {:#?}", s.host.records());
    let record = s
        .host
        .expect(fmi2Fatal, &[call, "the model panicked", text]);
    assert_eq!(record.category, "logStatusError");
    s.host.clear();
}

/// After a fatal error every call but fmi2FreeInstance is refused, and says so.
#[track_caller]
fn assert_everything_refused(s: &Slave) {
    let checks: [(&str, &dyn Fn() -> fmi2Status); 8] = [
        ("fmi2DoStep", &|| s.step(0.0, 0.1)),
        ("fmi2GetReal", &|| s.get_reals(&[Y]).0),
        ("fmi2SetReal", &|| s.set_reals(&[U], &[1.0])),
        ("fmi2GetBoolean", &|| s.get_booleans(&[PANIC_IN_STEP]).0),
        ("fmi2Terminate", &|| s.terminate()),
        ("fmi2Reset", &|| s.reset()),
        ("fmi2SetFMUstate", &|| s.set_state(std::ptr::null_mut())),
        ("fmi2SetDebugLogging", &|| s.debug_logging(true, &[])),
    ];
    for (call, check) in checks {
        s.host.clear();
        assert_eq!(check(), fmi2Error, "{call} after a fatal error");
        s.host.expect(
            fmi2Fatal,
            &[
                call,
                "the instance had a fatal error; only fmi2FreeInstance is allowed",
            ],
        );
    }
    s.host.clear();
}

#[test]
fn a_panic_in_do_step_is_fatal_logged_and_contained() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_reals(&[U], &[1.0]), fmi2OK);
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
    assert_eq!(s.set_booleans(&[PANIC_IN_STEP], &[fmi2True]), fmi2OK);
    assert_fatal(
        &s,
        s.step(0.1, 0.1),
        "fmi2DoStep",
        "model exploded in do_step (on purpose)",
    );
    assert_everything_refused(&s);
    // Dropping `s` frees the instance: fmi2FreeInstance still works.
}

#[test]
fn a_panic_in_get_real_is_fatal() {
    let s = Slave::initialized(guid());
    assert_eq!(s.set_booleans(&[PANIC_IN_GET], &[fmi2True]), fmi2OK);
    let (status, _) = s.get_reals(&[Y]);
    assert_fatal(
        &s,
        status,
        "fmi2GetReal",
        "model exploded in get_real (on purpose)",
    );
    assert_everything_refused(&s);
}

#[test]
fn a_panic_in_set_real_is_fatal_also_with_a_non_text_payload() {
    let s = Slave::initialized(guid());
    assert_fatal(
        &s,
        s.set_reals(&[U], &[PANIC_VALUE]),
        "fmi2SetReal",
        "model exploded in set_real (on purpose)",
    );
    assert_everything_refused(&s);

    let s = Slave::initialized(guid());
    assert_fatal(
        &s,
        s.set_reals(&[U], &[PANIC_ANY_VALUE]),
        "fmi2SetReal",
        "a panic with a non-text payload",
    );
    assert_everything_refused(&s);
}

#[test]
fn a_panic_in_exit_initialization_mode_is_fatal() {
    let s = Slave::new(guid());
    assert_eq!(s.set_booleans(&[PANIC_IN_EXIT], &[fmi2True]), fmi2OK);
    assert_eq!(s.enter(), fmi2OK);
    assert_fatal(
        &s,
        s.exit(),
        "fmi2ExitInitializationMode",
        "model exploded in exit_initialization (on purpose)",
    );
    assert_everything_refused(&s);
}

#[test]
fn a_panic_in_instantiate_gives_a_null_instance_and_a_log_message() {
    let host = Host::new();
    let c = instantiate_raw(
        Some(PANICKING_INSTANCE_NAME),
        fmi2CoSimulation,
        Some(guid()),
        Some(&host.callbacks()),
        false,
    );
    assert!(c.is_null());
    let record = host.expect(
        fmi2Fatal,
        &[
            "fmi2Instantiate",
            "the model panicked",
            "model exploded in instantiate (on purpose)",
        ],
    );
    assert_eq!(record.instance, PANICKING_INSTANCE_NAME);
    // The library is still usable.
    let s = Slave::initialized(guid());
    assert_eq!(s.step(0.0, 0.1), fmi2OK);
}

#[test]
fn a_panic_in_the_models_drop_stays_inside_free_instance() {
    let s = Slave::initialized(guid());
    let state = s.get_state();
    assert_eq!(s.set_booleans(&[PANIC_ON_DROP], &[fmi2True]), fmi2OK);
    // Restoring a state drops the current model, which panics: fatal, not an unwind.
    assert_fatal(
        &s,
        s.set_state(state),
        "fmi2SetFMUstate",
        "model exploded in drop (on purpose)",
    );
    assert_everything_refused(&s);
    // Another whose model panics while fmi2FreeInstance drops it: the process carries on.
    let t = Slave::initialized(guid());
    assert_eq!(t.set_booleans(&[PANIC_ON_DROP], &[fmi2True]), fmi2OK);
    drop(t);
    let u = Slave::initialized(guid());
    assert_eq!(u.step(0.0, 0.1), fmi2OK);
}
