//! The criterion bench `do_step`'s `record_1024_steps_contact23` workload (the paper's rig at
//! its prior means, the bumper between floors 2 and 3 switched on, the exact contact stepper)
//! for counting instructions: `cargo run --release -p fmu-shear --example contact23_steps --
//! RECORDS` runs RECORDS records of 1024 steps through the C functions, as a host does, and
//! prints a checksum of the accelerations. The difference of `valgrind --tool=callgrind`
//! totals at two record counts, over their steps, is the instructions of one step (the set-up
//! cancels; docs/src/benchmarks.md has the figures).

// Drives the FMU through its C functions, as a host does.
#![allow(unsafe_code)]

#[path = "../benches/host/mod.rs"]
mod host;
use host::{record_force, Slave, STEPS};

fn main() {
    let records: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1);
    let force = record_force();
    let mut slave = Slave::with(&[("contact23_enabled", true)], &[("integrator", 0)]);
    let mut sum = 0.0;
    for _ in 0..records {
        slave.record(&force, |acc| sum += acc.iter().sum::<f64>());
    }
    println!("{records} records of {STEPS} steps: checksum {sum:.17e}");
}
