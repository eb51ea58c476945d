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

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

mod host;
use host::{record_force, Slave, STEP, STEPS};

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
        b.iter(|| {
            linear.record(black_box(&force), |acc| {
                black_box(acc);
            })
        })
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
                b.iter(|| {
                    slave.record(black_box(&force), |acc| {
                        black_box(acc);
                    })
                })
            });
        }
    }
    group.sample_size(30);

    group.throughput(Throughput::Elements(1));
    let mut single = Slave::new(&[]);
    let mut n = 0;
    group.bench_function("single_step", |b| {
        b.iter(|| {
            black_box(single.step(
                black_box(force[n]),
                black_box((force[n + 1] - force[n]) / STEP),
            ));
            n = (n + 1) % STEPS;
        })
    });
    group.finish();
}

criterion_group!(benches, do_step);
criterion_main!(benches);
