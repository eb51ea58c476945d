//! The forward sensitivities (`sensitivities` on) against central differences of the FMU's own
//! accelerations, on the examples' sampling (51.2 Hz, 20 s) under a band-limited random force
//! with first-order input interpolation; the calibrated twin's parameters of dataset1 (so the
//! damping is realistic). Print the errors with `cargo test --release -p fmu-shear --test
//! sensitivity -- --nocapture`.

use fmi2::CoSimModel;
use fmu_shear::variables::{info, sensitivity_vr, SENSITIVITIES, SENSITIVITY};
use fmu_shear::ShearModel;

mod common;

/// The paper's rig's parameters, in output order.
const PARAMETERS: [&str; 9] = ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"];

const STEP: f64 = 1.0 / 51.2;
const STEPS: usize = 1024;

fn vr(name: &str) -> u32 {
    info()
        .by_name(name)
        .unwrap_or_else(|| panic!("{name} is a variable"))
        .vr
}

/// dataset1's calibrated values.
const VALUES: [f64; 9] = [
    4.637, 5.284, 4.919, 8.143, 3.652, 2.556, 3850.3, 4099.6, 4680.9,
];

/// Accelerations and, when `sensitive`, the 27 sensitivity outputs per sample.
fn run(values: &[f64; 9], sensitive: bool, booleans: &[&str]) -> (Vec<[f64; 3]>, Vec<[f64; 27]>) {
    let mut model = ShearModel::instantiate(&Default::default()).expect("instantiate");
    for (p, v) in PARAMETERS.iter().zip(values) {
        model.set_real(vr(p), *v).expect(p);
    }
    for name in booleans {
        model.set_boolean(vr(name), true).expect(name);
    }
    model
        .set_boolean(SENSITIVITIES, sensitive)
        .expect("sensitivities");
    let force = common::band_limited_force(STEPS, STEP);
    let (mut acc, mut sens) = (Vec::new(), Vec::new());
    for n in 0..STEPS {
        acc.push(common::step_ramped(&mut model, &force, n, STEP));
        sens.push(std::array::from_fn(|k| {
            model
                .get_real(sensitivity_vr(k / 9, k % 9, 3))
                .expect("sensitivity")
        }));
    }
    (acc, sens)
}

/// Measured: the largest difference, relative to the largest |central difference| of the same
/// output, is 2.5e-8 over the 27 outputs (the differences' own truncation and rounding error
/// at a relative step of 1e-5); the bar is 1e-6.
#[test]
fn sensitivities_equal_central_differences_of_the_accelerations() {
    let (_, sens) = run(&VALUES, true, &[]);
    let mut worst = 0.0f64;
    for (j, p) in PARAMETERS.iter().enumerate() {
        let h = 1e-5 * VALUES[j];
        let (mut plus, mut minus) = (VALUES, VALUES);
        plus[j] += h;
        minus[j] -= h;
        let (ap, _) = run(&plus, false, &[]);
        let (am, _) = run(&minus, false, &[]);
        for f in 0..3 {
            let fd: Vec<f64> = (0..STEPS)
                .map(|n| (ap[n][f] - am[n][f]) / (2.0 * h))
                .collect();
            let scale = fd.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(scale > 0.0, "acc{} moves with {p}", f + 1);
            let error = (0..STEPS)
                .map(|n| (sens[n][9 * f + j] - fd[n]).abs())
                .fold(0.0f64, f64::max)
                / scale;
            println!(
                "d_acc{}_d_{p}: {error:.1e} of its largest value {scale:.3e}",
                f + 1
            );
            worst = worst.max(error);
        }
    }
    println!("worst: {worst:.1e}");
    assert!(worst < 1e-6, "{worst:e}");
}

#[test]
fn sensitivities_leave_the_run_alone_and_are_nan_when_off_or_with_an_effect() {
    let (plain, off) = run(&VALUES, false, &[]);
    let (sensitive, on) = run(&VALUES, true, &[]);
    assert_eq!(plain, sensitive);
    assert!(off.iter().flatten().all(|x| x.is_nan()));
    assert!(on.iter().flatten().all(|x| x.is_finite()));
    let (_, with_cubic) = run(&VALUES, true, &["cubic3_enabled"]);
    assert!(with_cubic.iter().flatten().all(|x| x.is_nan()));
    assert_eq!(
        PARAMETERS
            .iter()
            .map(|p| vr(&format!("d_acc2_d_{p}")))
            .collect::<Vec<_>>(),
        // Floor 2's block, m1..m3, c1..c3, k1..k3 each in its own block of MAX_STOREYS.
        [0, 1, 2, 50, 51, 52, 100, 101, 102]
            .map(|j| SENSITIVITY + 150 + j)
            .to_vec()
    );
}
