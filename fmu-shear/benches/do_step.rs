//! `fmi2DoStep` through the C ABI, as a host drives the FMU: for each communication step of
//! h = 1/51.2 s, `fmi2SetReal` (force) → `fmi2SetRealInputDerivatives` (its slope) → `fmi2DoStep`
//! → `fmi2GetReal` (acc1..3). Default parameters and sub-steps.
//!
//! `cargo bench -p fmu-shear --bench do_step`. Ids in group "fmi2DoStep":
//! - `record_1024_steps`: one 20 s record of 1024 steps (throughput in steps);
//! - `single_step`: one step;
//! - `record_1024_steps_contact23`: the record with the bumper between floors 2 and 3 switched on
//!   (0.5 mm gap, 9000 N/m): the exact flows of the contact regions, split at the gap;
//! - `record_1024_steps_contact23_fixed64`: the same with `integrator = 1`, 64 RK4 sub-steps split
//!   at the gap (the former path);
//! - `record_1024_steps_cubic3` / `_cubic3_fixed64`: cubic stiffness on storey 3 (1e9 N/m³),
//!   error-controlled Dormand–Prince 5(4) / 64 RK4 sub-steps;
//! - `record_1024_steps_friction1` / `_friction1_fixed64`: friction on floor 1 (0.1 N, 1 mm/s),
//!   likewise.

// Drives the FMU through its C functions, as a host does.
#![allow(unsafe_code)]

use std::ffi::CString;
use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
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
}

fn ok(status: fmi2Status, call: &str) {
    assert_eq!(status, fmi2OK, "{call}");
}

impl Slave {
    fn new(booleans: &[(&str, bool)]) -> Slave {
        Slave::with(booleans, &[])
    }

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
            black_box(self.step(force[n], (force[n + 1] - force[n]) / STEP));
        }
    }
}

impl Drop for Slave {
    fn drop(&mut self) {
        // SAFETY: the instance from fmi2Instantiate, freed once.
        unsafe { fmu_shear::fmi2FreeInstance(self.component) };
    }
}

fn do_step(c: &mut Criterion) {
    let force = record_force();
    let mut group = c.benchmark_group("fmi2DoStep");
    group
        .sample_size(30)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));

    group.throughput(Throughput::Elements(STEPS as u64));
    let mut linear = Slave::new(&[]);
    group.bench_function("record_1024_steps", |b| {
        b.iter(|| linear.record(black_box(&force)))
    });
    for (id, enabled) in [
        ("contact23", "contact23_enabled"),
        ("cubic3", "cubic3_enabled"),
        ("friction1", "friction1_enabled"),
    ] {
        for (suffix, integrator, samples) in [("", 0, 30), ("_fixed64", 1, 20)] {
            group.sample_size(samples);
            let mut slave = Slave::with(&[(enabled, true)], &[("integrator", integrator)]);
            group.bench_function(format!("record_1024_steps_{id}{suffix}"), |b| {
                b.iter(|| slave.record(black_box(&force)))
            });
        }
    }
    group.sample_size(30);

    group.throughput(Throughput::Elements(1));
    let mut single = Slave::new(&[]);
    let mut n = 0;
    group.bench_function("single_step", |b| {
        b.iter(|| {
            let acc = single.step(
                black_box(force[n]),
                black_box((force[n + 1] - force[n]) / STEP),
            );
            n = (n + 1) % STEPS;
            acc
        })
    });
    group.finish();
}

criterion_group!(benches, do_step);
criterion_main!(benches);
