//! The paper's rig with contacts against its golden file, `tests/golden/rig_contacts.csv`.
//!
//! The golden holds the states (displacements and velocities of the three floors) after each of
//! 512 steps of 1/51.2 s of `ShearModel::advance` on the rig (three storeys, force and control
//! force on floor 1, damping 8.1 / 3.7 / 2.6 N·s/m, the default masses and stiffnesses), with
//! `integrator = 0` (the exact contact flows), under the band-limited force of `common` and a
//! slower control force, for four sets of bumpers: one in storey 1 (its gap half the linear
//! rig's largest drift there, 9000 N/m, both sides), one in storey 3 (0.5 mm), three of
//! different sides, and a stiff one (1e6 N/m). It was written by the rig's
//! former fixed-array contact stepper; the generic stepper (any N) now steps the rig and must
//! hold it: per case, max |Δ| / max |golden| of the displacements and of the velocities
//! ≤ 1e-12 (measured 0: the same sums in the same order, the regions' exponentials by
//! nalgebra's fixed-size kernel as before).
//!
//! Regenerate only on purpose, after a change of the model meant to change its output:
//! `UPDATE_GOLDEN=1 cargo test -p fmu-shear --test rig_contacts_golden`, then say why in the
//! commit.

use std::fmt::Write as _;
use std::path::PathBuf;

use fmu_shear::effects::{contact, Contact, Effects, Law};
use fmu_shear::{Integrator, ShearModel, ShearParameters};

mod common;

const STEP: f64 = 1.0 / 51.2;
const STEPS: usize = 512;
/// Allowed max |Δ| / max |golden| per case and kind (measured 0).
const TOLERANCE: f64 = 1e-12;

/// A bumper: storey (0-based), gap (m), stiffness (N/m), side.
type Bumper = (usize, f64, f64, i32);

fn cases() -> Vec<(&'static str, Vec<Bumper>)> {
    let half = 0.5 * largest_linear_drift();
    vec![
        ("storey1", vec![(0, half, 9000.0, contact::SIDE_BOTH)]),
        ("storey3", vec![(2, 5e-4, 9000.0, contact::SIDE_BOTH)]),
        (
            "three",
            vec![
                (0, 2e-3, 9000.0, contact::SIDE_POSITIVE),
                (1, 1e-3, 9000.0, contact::SIDE_NEGATIVE),
                (2, 3e-4, 9000.0, contact::SIDE_BOTH),
            ],
        ),
        ("stiff", vec![(2, 5e-4, 1e6, contact::SIDE_BOTH)]),
    ]
}

/// The largest |drift| of storey 1 of the linear rig under the run's inputs.
fn largest_linear_drift() -> f64 {
    run(&[])
        .iter()
        .fold(0.0f64, |largest, x| largest.max(x[0].abs()))
}

/// The states after each step of the rig with these bumpers: `[y1, y2, y3, v1, v2, v3]`.
fn run(bumpers: &[Bumper]) -> Vec<[f64; 6]> {
    let p = ShearParameters::default();
    assert!(
        structure::paper::is_paper_rig(&p.layout()),
        "the default parameters are the rig"
    );
    let mut model = ShearModel::new(p, Effects::new(3));
    model.params.damping = vec![8.1, 3.7, 2.6];
    model.integrator = Integrator::Exact;
    for &(s, gap, stiffness, side) in bumpers {
        model.effects.switch_on(
            s,
            Law::Contact(Contact {
                gap,
                stiffness,
                side,
            }),
        );
    }
    let force = common::band_limited_force(STEPS, STEP);
    let control: Vec<f64> = (0..=STEPS)
        .map(|k| 0.3 * (0.11 * k as f64).cos() + 0.2 * (0.53 * k as f64).sin())
        .collect();
    let mut states = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        model.force.value = force[k];
        model.force.slope = (force[k + 1] - force[k]) / STEP;
        model.control_force.value = control[k];
        model.control_force.slope = (control[k + 1] - control[k]) / STEP;
        model.advance(STEP);
        states.push(std::array::from_fn(|i| {
            if i < 3 {
                model.displacement[i]
            } else {
                model.velocity[i - 3]
            }
        }));
    }
    states
}

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests")
        .join("golden")
        .join("rig_contacts.csv")
}

fn write_golden(runs: &[(&str, Vec<[f64; 6]>)]) {
    let mut text = String::from("case,step,y1,y2,y3,v1,v2,v3\n");
    for (case, states) in runs {
        for (k, x) in states.iter().enumerate() {
            let _ = write!(text, "{case},{}", k + 1);
            for v in x {
                let _ = write!(text, ",{v:.17e}");
            }
            text.push('\n');
        }
    }
    let path = golden_path();
    std::fs::create_dir_all(path.parent().expect("a parent")).expect("the golden's folder");
    std::fs::write(&path, text).expect("the golden written");
}

/// The golden's states of one case, in step order.
fn read_golden(case: &str) -> Vec<[f64; 6]> {
    let path = golden_path();
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .enumerate()
        .skip(1)
        .filter(|(_, line)| line.split(',').next() == Some(case))
        .map(|(i, line)| {
            let values: Vec<f64> = line
                .split(',')
                .skip(2)
                .map(|v| {
                    v.parse()
                        .unwrap_or_else(|e| panic!("{}:{}: {v:?}: {e}", path.display(), i + 1))
                })
                .collect();
            values
                .try_into()
                .unwrap_or_else(|_| panic!("{}:{}: six values", path.display(), i + 1))
        })
        .collect()
}

/// Per kind (displacements, velocities): max |Δ| / max |golden|.
fn worst(states: &[[f64; 6]], golden: &[[f64; 6]]) -> [f64; 2] {
    std::array::from_fn(|kind| {
        let range = 3 * kind..3 * kind + 3;
        let (mut diff, mut peak) = (0.0f64, 0.0f64);
        for (x, g) in states.iter().zip(golden) {
            for i in range.clone() {
                diff = diff.max((x[i] - g[i]).abs());
                peak = peak.max(g[i].abs());
            }
        }
        assert!(peak > 0.0, "the run moves");
        diff / peak
    })
}

#[test]
fn the_rig_with_contacts_holds_its_golden_states() {
    let runs: Vec<(&str, Vec<[f64; 6]>)> = cases()
        .into_iter()
        .map(|(case, bumpers)| (case, run(&bumpers)))
        .collect();
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        write_golden(&runs);
    }
    for (case, states) in &runs {
        let golden = read_golden(case);
        assert_eq!(golden.len(), STEPS, "{case}: {STEPS} steps in the golden");
        let [dy, dv] = worst(states, &golden);
        println!("{case}: displacements {dy:.2e}, velocities {dv:.2e} of the golden's peak");
        assert!(
            dy <= TOLERANCE && dv <= TOLERANCE,
            "{case}: displacements {dy:e}, velocities {dv:e} of the peak (bound {TOLERANCE:e})"
        );
    }
}
