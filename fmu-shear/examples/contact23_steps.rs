//! The criterion bench `do_step`'s `record_1024_steps_contact23` workload (the paper's rig at
//! its prior means, the bumper between floors 2 and 3 switched on, the exact contact stepper)
//! for counting instructions: `cargo run --release -p fmu-shear --example contact23_steps --
//! RECORDS` runs RECORDS records of 1024 steps through the C functions, as a host does, and
//! prints a checksum of the accelerations. The difference of `valgrind --tool=callgrind`
//! totals at two record counts, over their steps, is the instructions of one step (the set-up
//! cancels; docs/src/benchmarks.md has the figures).

// Drives the FMU through its C functions, as a host does.
#![allow(unsafe_code)]

use std::ffi::CString;

use fmi2::abi::*;
use fmu_shear::variables::{info, ACC, FORCE};

const STEP: f64 = 1.0 / 51.2;
const STEPS: usize = 1024;

/// A deterministic band-limited force: sines from 0.125 Hz to 25 Hz, about 1 N RMS.
fn record_force() -> Vec<f64> {
    const COMPONENTS: usize = 200;
    let amplitude = (2.0 / COMPONENTS as f64).sqrt();
    (0..=STEPS)
        .map(|n| {
            let t = n as f64 * STEP;
            (1..=COMPONENTS)
                .map(|j| {
                    let phase = std::f64::consts::TAU * (j as f64 * 0.618_033_988_749_895).fract();
                    amplitude * (std::f64::consts::TAU * 0.125 * j as f64 * t + phase).sin()
                })
                .sum()
        })
        .collect()
}

/// One co-simulation instance, initialized, with the host's clock.
struct Slave {
    component: fmi2Component,
    time: f64,
    sum: f64,
}

fn ok(status: fmi2Status, call: &str) {
    assert_eq!(status, fmi2OK, "{call}");
}

impl Slave {
    fn with(booleans: &[(&str, bool)], integers: &[(&str, i32)]) -> Slave {
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
        Slave {
            component,
            time: 0.0,
            sum: 0.0,
        }
    }

    /// Apply the force over the step → step → read the accelerations.
    #[inline]
    fn step(&mut self, force: f64, slope: f64) -> [f64; 3] {
        let order: fmi2Integer = 1;
        let outputs = [ACC, ACC + 1, ACC + 2];
        let mut acc = [0.0; 3];
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
                fmu_shear::fmi2GetReal(self.component, outputs.as_ptr(), 3, acc.as_mut_ptr())
            },
            "fmi2GetReal",
        );
        acc
    }

    fn record(&mut self, force: &[f64]) {
        for n in 0..STEPS {
            let acc = self.step(force[n], (force[n + 1] - force[n]) / STEP);
            self.sum += acc[0] + acc[1] + acc[2];
        }
    }
}

impl Drop for Slave {
    fn drop(&mut self) {
        // SAFETY: the instance from fmi2Instantiate, freed once.
        unsafe { fmu_shear::fmi2FreeInstance(self.component) };
    }
}

fn main() {
    let records: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1);
    let force = record_force();
    let mut slave = Slave::with(&[("contact23_enabled", true)], &[("integrator", 0)]);
    for _ in 0..records {
        slave.record(&force);
    }
    println!(
        "{records} records of {STEPS} steps: checksum {:.17e}",
        slave.sum
    );
}
