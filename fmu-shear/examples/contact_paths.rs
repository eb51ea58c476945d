//! The exact contact stepping of the paper's rig (three storeys, force at floor 1, a bumper in
//! storey 1 at half the linear response's largest drift, 9000 N/m, both sides), one 20 s record
//! (1024 steps of 1/51.2 s) repeated, by `piecewise_any` on each kind of state: `array` (the
//! rig's `[f64; 6]`, the path `ShearModel::advance` takes on the rig) and `inline` (a small
//! vector, the path of every other structure). Prints steps per second of each, the median over
//! interleaved rounds of the inline path's rate to the array one's, and the largest difference
//! of their states, relative to the largest |state| component.
//!
//! `cargo run --release -p fmu-shear --example contact_paths -- [all|array|inline] [RECORDS]`
//! One path alone is for counting instructions, robust to the load of a shared machine: the
//! difference of `valgrind --tool=cachegrind --cache-sim=no` totals at 13 and 3 records, over
//! 10 × 1024 steps (`scripts/bench-contact-paths.sh`).

use std::time::Instant;

use fmu_shear::effects::{contact, Contact, Effects, Law};
use fmu_shear::linear::StepInputs;
use fmu_shear::piecewise_any::{AnyContactMaps, Inline};
use fmu_shear::{ShearModel, ShearParameters};
use structure::{Excitation, Structure};

const STEP: f64 = 1.0 / 51.2;
const STEPS: usize = 1024;
/// Interleaved rounds of the two paths (`all`).
const ROUNDS: usize = 9;

fn force() -> Vec<f64> {
    (0..=STEPS)
        .map(|n| (0.37 * n as f64).sin() + 0.5 * (1.3 * n as f64).cos())
        .collect()
}

fn rig(force: &[f64]) -> ShearModel {
    let p = ShearParameters::from_structure(&Structure::uniform(
        3,
        5.2,
        0.5,
        4021.0,
        Excitation::Force { floor: 1 },
    ));
    let mut linear = ShearModel::new(p.clone(), Effects::new(3));
    let mut largest = 0.0f64;
    for n in 0..STEPS {
        linear.force.value = force[n];
        linear.force.slope = (force[n + 1] - force[n]) / STEP;
        linear.advance(STEP);
        largest = largest.max(linear.displacement[0].abs());
    }
    let mut model = ShearModel::new(p, Effects::new(3));
    model.effects.switch_on(
        0,
        Law::Contact(Contact {
            gap: 0.5 * largest,
            stiffness: 9000.0,
            side: contact::SIDE_BOTH,
        }),
    );
    model
}

fn inputs(force: &[f64], k: usize) -> StepInputs {
    StepInputs {
        excitation: force[k],
        excitation_slope: (force[k + 1] - force[k]) / STEP,
        ..Default::default()
    }
}

/// The states of `records` runs of the record from rest, by `step`; its steps per second.
fn run(
    records: usize,
    force: &[f64],
    step: &mut impl FnMut(&[f64; 6], &StepInputs) -> [f64; 6],
) -> (Vec<[f64; 6]>, f64) {
    let start = Instant::now();
    let mut states = Vec::with_capacity(STEPS);
    for r in 0..records {
        let mut x = [0.0; 6];
        for k in 0..STEPS {
            x = step(&x, &inputs(force, k));
            if r == 0 {
                states.push(x);
            }
        }
    }
    let rate = (records * STEPS) as f64 / start.elapsed().as_secs_f64();
    (states, rate)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let which = args.next().unwrap_or_else(|| "all".into());
    let records: usize = args.next().map_or(50, |r| r.parse().expect("RECORDS"));
    let force = force();
    let model = rig(&force);
    let mut array = AnyContactMaps::new(&model, STEP);
    let mut inline = AnyContactMaps::new(&model, STEP);
    let mut by_array = |x: &[f64; 6], i: &StepInputs| array.advance_in(x, i).expect("finite");
    let mut by_inline = |x: &[f64; 6], i: &StepInputs| {
        let x: Inline = Inline::from_slice(x);
        let y = inline.advance_in(&x, i).expect("finite");
        std::array::from_fn(|j| y[j])
    };
    let mut results = Vec::new();
    if which == "all" || which == "array" {
        results.push(("array", run(records, &force, &mut by_array)));
    }
    if which == "all" || which == "inline" {
        results.push(("inline", run(records, &force, &mut by_inline)));
    }
    if which == "all" {
        // Interleaved rounds, the rate ratio of each round (robust to a load that changes).
        let mut ratios: Vec<f64> = (0..ROUNDS)
            .map(|_| {
                let a = run(records, &force, &mut by_array).1;
                let v = run(records, &force, &mut by_inline).1;
                v / a
            })
            .collect();
        ratios.sort_by(f64::total_cmp);
        let r: Vec<String> = ratios.iter().map(|r| format!("{r:.2}")).collect();
        println!(
            "inline / array over {ROUNDS} interleaved rounds: median {:.2} (sorted: {})",
            ratios[ROUNDS / 2],
            r.join(" ")
        );
    }
    let reference = results[0].1 .0.clone();
    let scale = reference
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for (name, (states, rate)) in &results {
        let diff = states
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| (p - q).abs()))
            .fold(0.0f64, f64::max);
        println!(
            "{name}: {:.0} steps/s, max |Δ| / max |x| against {}: {:.2e}",
            rate,
            results[0].0,
            diff / scale
        );
    }
}
