//! The host side of the FMU's benchmarks, shared by the criterion bench `do_step` and the
//! instruction-counting example `contact23_steps`: a deterministic band-limited force and one
//! instance driven through the C functions (`fmi2SetReal` → `fmi2SetRealInputDerivatives` →
//! `fmi2DoStep` → `fmi2GetReal`), as a host does. Each user takes part of it.
#![allow(dead_code)]

use std::ffi::CString;

use fmi2::abi::*;
use fmu_shear::variables::{info, ACC, FORCE};

pub const STEP: f64 = 1.0 / 51.2;
pub const STEPS: usize = 1024;

#[path = "../../tests/common/mod.rs"]
mod common;

/// A deterministic band-limited force: 200 sines from 0.125 Hz to 25 Hz, about 1 N RMS.
pub fn record_force() -> Vec<f64> {
    common::sines(STEPS, STEP, 200, 0.125)
}

/// One co-simulation instance, initialized, with the host's clock and the floors' acceleration
/// outputs of the structure it was instantiated for (the FMU's default table, the paper's rig).
pub struct Slave {
    component: fmi2Component,
    time: f64,
    outputs: Vec<fmi2ValueReference>,
    acc: Vec<f64>,
}

fn ok(status: fmi2Status, call: &str) {
    assert_eq!(status, fmi2OK, "{call}");
}

impl Slave {
    pub fn new(booleans: &[(&str, bool)]) -> Slave {
        Slave::with(booleans, &[])
    }

    pub fn with(booleans: &[(&str, bool)], integers: &[(&str, i32)]) -> Slave {
        // A C-variadic logger cannot be written in stable Rust; the FMU accepts none.
        let callbacks = fmi2CallbackFunctions {
            logger: None,
            allocate_memory: None,
            free_memory: None,
            step_finished: None,
            component_environment: std::ptr::null_mut(),
        };
        let guid = CString::new(info().guid.as_str()).expect("the GUID has no NUL");
        // SAFETY: NUL-terminated strings and a callback structure valid for the call.
        let component = unsafe {
            fmu_shear::fmi2Instantiate(
                c"bench".as_ptr(),
                fmi2CoSimulation,
                guid.as_ptr(),
                std::ptr::null(),
                &callbacks,
                0,
                0,
            )
        };
        assert!(!component.is_null(), "fmi2Instantiate");
        ok(
            fmu_shear::fmi2SetupExperiment(component, 0, 0.0, 0.0, 0, 0.0),
            "fmi2SetupExperiment",
        );
        ok(
            fmu_shear::fmi2EnterInitializationMode(component),
            "fmi2EnterInitializationMode",
        );
        for &(name, on) in booleans {
            let vr = info()
                .by_name(name)
                .unwrap_or_else(|| panic!("{name} is a variable"))
                .vr;
            let value = if on { fmi2True } else { fmi2False };
            // SAFETY: one value reference and one value.
            ok(
                unsafe { fmu_shear::fmi2SetBoolean(component, &vr, 1, &value) },
                "fmi2SetBoolean",
            );
        }
        for &(name, value) in integers {
            let vr = info()
                .by_name(name)
                .unwrap_or_else(|| panic!("{name} is a variable"))
                .vr;
            // SAFETY: one value reference and one value.
            ok(
                unsafe { fmu_shear::fmi2SetInteger(component, &vr, 1, &value) },
                "fmi2SetInteger",
            );
        }
        ok(
            fmu_shear::fmi2ExitInitializationMode(component),
            "fmi2ExitInitializationMode",
        );
        let storeys = fmu_shear::ShearParameters::default().storeys();
        Slave {
            component,
            time: 0.0,
            outputs: (0..storeys as u32).map(|i| ACC + i).collect(),
            acc: vec![0.0; storeys],
        }
    }

    /// Apply the force over the step → step → read the accelerations.
    #[inline]
    pub fn step(&mut self, force: f64, slope: f64) -> &[f64] {
        let order: fmi2Integer = 1;
        // SAFETY: arrays of the lengths passed, alive for the calls.
        unsafe {
            ok(
                fmu_shear::fmi2SetReal(self.component, &FORCE, 1, &force),
                "fmi2SetReal",
            );
            ok(
                fmu_shear::fmi2SetRealInputDerivatives(self.component, &FORCE, 1, &order, &slope),
                "fmi2SetRealInputDerivatives",
            );
        }
        ok(
            fmu_shear::fmi2DoStep(self.component, self.time, STEP, fmi2True),
            "fmi2DoStep",
        );
        self.time += STEP;
        // SAFETY: as above.
        ok(
            unsafe {
                fmu_shear::fmi2GetReal(
                    self.component,
                    self.outputs.as_ptr(),
                    self.outputs.len(),
                    self.acc.as_mut_ptr(),
                )
            },
            "fmi2GetReal",
        );
        &self.acc
    }

    /// One record of `STEPS` steps under `force` (`STEPS + 1` samples: the last one's slope),
    /// `each` given every step's accelerations.
    pub fn record(&mut self, force: &[f64], mut each: impl FnMut(&[f64])) {
        for n in 0..STEPS {
            each(self.step(force[n], (force[n + 1] - force[n]) / STEP));
        }
    }
}

impl Drop for Slave {
    fn drop(&mut self) {
        // SAFETY: the instance from fmi2Instantiate, freed once.
        unsafe { fmu_shear::fmi2FreeInstance(self.component) };
    }
}
