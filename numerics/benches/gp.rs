//! Criterion benches of numerics::gp (group "gp"), single-threaded like the GP itself:
//!
//! - `fit_n1000_d40`: one full type-II ML fit (default options: 3 starts, L-BFGS in the box) of
//!   output 1 of `benchmark_problem` (N = 1000 points, d = 40 inputs, two of them relevant);
//! - `nlml_gradient_n1000_d40`: one NLML + gradient evaluation (the fit's unit of work);
//! - `cholesky_n1000`: faer's Cholesky of a Matérn 3/2 covariance matrix at N = 1000, the
//!   factorisation the GP uses, and `cholesky_n1000_nalgebra`, nalgebra's of the same matrix;
//! - `cholesky_inverse_n1000_faer` / `_nalgebra`: factor and `K⁻¹` from it, the `O(N³)` part
//!   of every gradient;
//! - `traces_n1000_d40_faer` / `_nalgebra`: the `O(N² d)` part of the gradient, the product
//!   `A Z` (`N × N` by `N × d`) of which the d lengthscale traces are made;
//! - `append_n500`: appending one point to a 500-point, d = 40 model (`O(n²)`), and
//!   `remove_n500`: removing its first point (the costliest position);
//! - `predict_point_n1000_d40`: mean and variances at one point of a 1000-point model, and
//!   `predict_n1000_m1024`: at 1024 points in one call (the blocked path).
//!
//!   cargo bench -p numerics --bench gp [-- FILTER]

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use faer::linalg::solvers::DenseSolveCore;
use numerics::gp::{
    benchmark_problem, nlml_with_gradient, FitOptions, GaussianProcess, Hyperparameters, Inputs,
};

/// The benchmark problem's inputs, output 1, and a model at the data-based start values.
fn problem(n: usize) -> (Inputs, Vec<f64>, Hyperparameters) {
    let (inputs, [y, _, _]) = benchmark_problem(1, n, 40).expect("benchmark problem");
    let start = FitOptions::default()
        .start_points(&inputs, &y)
        .expect("start points")
        .remove(0);
    (inputs, y, start)
}

/// `K = K_f + σ_n² I` of the benchmark inputs at the start hyperparameters, as both libraries'
/// matrices.
fn covariance(n: usize) -> (faer::Mat<f64>, nalgebra::DMatrix<f64>) {
    let (inputs, _, hyper) = problem(n);
    let noise = hyper.noise_variance();
    let k = |i: usize, j: usize| {
        let kij = hyper
            .covariance(inputs.row(i), inputs.row(j))
            .expect("valid hyperparameters");
        if i == j {
            kij + noise
        } else {
            kij
        }
    };
    (
        faer::Mat::from_fn(n, n, k),
        nalgebra::DMatrix::from_fn(n, n, k),
    )
}

fn gp(c: &mut Criterion) {
    let mut group = c.benchmark_group("gp");

    let (faer_k, nalgebra_k) = covariance(1000);
    group.bench_function("cholesky_n1000", |b| {
        b.iter(|| {
            black_box(&faer_k)
                .llt(faer::Side::Lower)
                .expect("positive definite")
        })
    });
    group.bench_function("cholesky_n1000_nalgebra", |b| {
        b.iter(|| {
            nalgebra::Cholesky::new(black_box(&nalgebra_k).clone()).expect("positive definite")
        })
    });
    group.bench_function("cholesky_inverse_n1000_faer", |b| {
        b.iter(|| {
            black_box(&faer_k)
                .llt(faer::Side::Lower)
                .expect("positive definite")
                .inverse()
        })
    });
    group.bench_function("cholesky_inverse_n1000_nalgebra", |b| {
        b.iter(|| {
            nalgebra::Cholesky::new(black_box(&nalgebra_k).clone())
                .expect("positive definite")
                .inverse()
        })
    });

    let (inputs, y, start) = problem(1000);
    let faer_z = faer::Mat::from_fn(1000, 40, |i, t| inputs.row(i)[t]);
    let nalgebra_z = nalgebra::DMatrix::from_fn(1000, 40, |i, t| inputs.row(i)[t]);
    group.bench_function("traces_n1000_d40_faer", |b| {
        b.iter(|| black_box(&faer_k) * black_box(&faer_z))
    });
    group.bench_function("traces_n1000_d40_nalgebra", |b| {
        b.iter(|| black_box(&nalgebra_k) * black_box(&nalgebra_z))
    });
    group.bench_function("nlml_gradient_n1000_d40", |b| {
        b.iter(|| nlml_with_gradient(black_box(&inputs), &y, &start).expect("evaluation"))
    });
    let model = GaussianProcess::new(inputs.clone(), y.clone(), start.clone()).expect("model");
    let x = inputs.row(7).iter().map(|v| v + 0.1).collect::<Vec<_>>();
    group.bench_function("predict_point_n1000_d40", |b| {
        b.iter(|| model.predict_point(black_box(&x)).expect("prediction"))
    });

    let (test_inputs, _, _) = problem(1024);
    group.bench_function("predict_n1000_m1024", |b| {
        b.iter(|| model.predict(black_box(&test_inputs)).expect("prediction"))
    });

    let (small_inputs, small_y, small_start) = problem(501);
    let first_500 = Inputs::from_row_major(40, small_inputs.as_row_major()[..500 * 40].to_vec())
        .expect("inputs");
    let base =
        GaussianProcess::new(first_500, small_y[..500].to_vec(), small_start).expect("model");
    group.bench_function("append_n500", |b| {
        b.iter_batched(
            || base.clone(),
            |mut m| {
                m.append(small_inputs.row(500), small_y[500])
                    .expect("append");
                m
            },
            BatchSize::LargeInput,
        )
    });
    group.bench_function("remove_n500", |b| {
        b.iter_batched(
            || base.clone(),
            |mut m| {
                m.remove(0).expect("remove");
                m
            },
            BatchSize::LargeInput,
        )
    });

    group.sample_size(10);
    group.measurement_time(Duration::from_secs(120));
    group.bench_function("fit_n1000_d40", |b| {
        b.iter(|| GaussianProcess::fit(&inputs, &y, &FitOptions::default()).expect("fit"))
    });
    group.finish();
}

criterion_group!(benches, gp);
criterion_main!(benches);
