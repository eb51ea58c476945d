//! Criterion bench of numerics::control::solve_care (group "riccati") on the 3-storey shear
//! model, n = 6 states, one input (the first floor's actuator):
//!
//! - `shear_n6_q1e3_light`: m = 5.2 kg, k = 4021 N/m, c = 0.01 Ns/m per storey (lightly damped),
//!   states in metres, Q = 10³·diag(0, 0, 0, 1, 1, 1), R = 0.1 — the problem that
//!   scripts/bench_riccati.py also times with scipy and python-control;
//! - `shear_n6_q1e6_mm`: the same structure, states in millimetres, q = 10⁶.
//!
//!   cargo bench -p numerics --bench riccati [-- FILTER]

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use numerics::control::{solve_care, DMatrix};

/// A, B, Q, R of the shear model (see the module doc); `unit` is 1 for metres, 1000 for mm.
fn shear(damping: f64, unit: f64, q: f64) -> [DMatrix<f64>; 4] {
    let (mass, stiffness) = (5.2, 4021.0);
    let k = DMatrix::from_row_slice(
        3,
        3,
        &[
            2.0 * stiffness,
            -stiffness,
            0.0,
            -stiffness,
            2.0 * stiffness,
            -stiffness,
            0.0,
            -stiffness,
            stiffness,
        ],
    );
    let c = &k * (damping / stiffness);
    let mut a = DMatrix::zeros(6, 6);
    a.view_mut((0, 3), (3, 3))
        .copy_from(&DMatrix::identity(3, 3));
    a.view_mut((3, 0), (3, 3)).copy_from(&(-k / mass));
    a.view_mut((3, 3), (3, 3)).copy_from(&(-c / mass));
    let mut b = DMatrix::zeros(6, 1);
    b[(3, 0)] = unit / mass;
    let mut weights = DMatrix::zeros(6, 6);
    for i in 3..6 {
        weights[(i, i)] = q;
    }
    [a, b, weights, DMatrix::from_element(1, 1, 0.1)]
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("riccati");
    group
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1));
    for (name, problem) in [
        ("shear_n6_q1e3_light", shear(0.01, 1.0, 1e3)),
        ("shear_n6_q1e6_mm", shear(0.01, 1000.0, 1e6)),
    ] {
        let [a, b, q, r] = problem;
        group.bench_function(name, |bencher| {
            bencher.iter(|| {
                solve_care(black_box(&a), black_box(&b), black_box(&q), black_box(&r))
                    .expect("solvable")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
