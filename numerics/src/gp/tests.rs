use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;

/// `n` points uniform in [−2, 2]^dim and targets `f(x) + noise_sd·ε`, seeded.
fn synthetic(
    seed: u64,
    n: usize,
    dim: usize,
    noise_sd: f64,
    f: impl Fn(&[f64]) -> f64,
) -> (Inputs, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let values: Vec<f64> = (0..n * dim).map(|_| rng.gen_range(-2.0..2.0)).collect();
    let inputs = Inputs::from_row_major(dim, values).expect("finite inputs");
    let targets = inputs
        .rows()
        .map(|x| {
            let e: f64 = StandardNormal.sample(&mut rng);
            f(x) + noise_sd * e
        })
        .collect();
    (inputs, targets)
}

fn smooth(x: &[f64]) -> f64 {
    (1.5 * x[0]).sin() + 0.6 * (2.0 * x[1]).cos()
}

fn hyper(lengthscales: &[f64], signal: f64, noise: f64) -> Hyperparameters {
    Hyperparameters::new(lengthscales, signal, noise).expect("positive hyperparameters")
}

fn test_points(seed: u64, n: usize, dim: usize) -> Inputs {
    synthetic(seed, n, dim, 0.0, |_| 0.0).0
}

/// Largest |a − b| / scale over the three predicted quantities, the mean scaled by the targets'
/// largest magnitude and the variances by σ_f².
fn prediction_gap(a: &GaussianProcess, b: &GaussianProcess, points: &Inputs) -> f64 {
    let pa = a.predict(points).expect("prediction");
    let pb = b.predict(points).expect("prediction");
    let mean_scale = a.targets().iter().fold(0.0f64, |m, y| m.max(y.abs()));
    let var_scale = a.hyperparameters().signal_variance();
    let gap = |x: &[f64], y: &[f64], s: f64| {
        x.iter()
            .zip(y)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / s))
    };
    gap(&pa.mean, &pb.mean, mean_scale)
        .max(gap(&pa.latent_variance, &pb.latent_variance, var_scale))
        .max(gap(
            &pa.predictive_variance,
            &pb.predictive_variance,
            var_scale,
        ))
}

/// Central differences with step 1e-5 in every log-hyperparameter. The truncation error is
/// O(h²) ≈ 1e-10 and the rounding error ε·|NLML|/h ≈ 1e-10 for an NLML of O(10), so 1e-5
/// relative leaves a wide margin for components of order 1e-2 or more, which all are here.
#[test]
fn gradient_matches_central_differences() {
    let (inputs, targets) = synthetic(1, 40, 3, 0.1, smooth);
    let h = hyper(&[0.7, 1.3, 2.5], 0.8, 0.05);
    let analytic = nlml_with_gradient(&inputs, &targets, &h).expect("gradient");
    assert_eq!(analytic.jitter, 0.0);
    let theta = h.to_log_vector();
    let step = 1e-5;
    for (k, g) in analytic.gradient.iter().enumerate() {
        let at = |delta: f64| {
            let mut t = theta.clone();
            t[k] += delta;
            let h = Hyperparameters::from_log_vector(3, &t).expect("finite");
            negative_log_marginal_likelihood(&inputs, &targets, &h).expect("nlml")
        };
        let fd = (at(step) - at(-step)) / (2.0 * step);
        let relative = (fd - g).abs() / g.abs();
        assert!(
            g.abs() > 1e-2 && relative < 1e-5,
            "parameter {k}: analytic {g}, central difference {fd}, relative error {relative:e}"
        );
    }
    // The function and the model agree on the value.
    let model = GaussianProcess::new(inputs, targets, h).expect("model");
    assert!((model.negative_log_marginal_likelihood() - analytic.nlml).abs() < 1e-10);
}

/// Two relevant inputs (x0, x1) and two irrelevant ones (x2, x3), noise sd 0.1 (σ_n² = 0.01),
/// 80 points. ARD must push the irrelevant lengthscales to at least 10× the relevant ones, and
/// the noise variance must come back within a factor 1.5. (Over seeds 1–8 the fitted σ_n² lay
/// in 0.0078–0.0110 and the irrelevant lengthscales were ≥ 15× the relevant ones.)
#[test]
fn fit_recovers_relevance_and_noise() {
    let (inputs, targets) = synthetic(3, 80, 4, 0.1, |x| x[0].sin() + 0.5 * x[1]);
    let (model, report) =
        GaussianProcess::fit(&inputs, &targets, &FitOptions::default()).expect("fit");
    let l = model.hyperparameters().lengthscales();
    let noise = model.hyperparameters().noise_variance();
    assert!(l[0].max(l[1]) * 10.0 < l[2].min(l[3]), "lengthscales {l:?}");
    assert!(noise > 0.01 / 1.5 && noise < 0.01 * 1.5, "σ_n² = {noise}");
    assert_eq!(report.starts.len(), 3);
    assert!((report.nlml - model.negative_log_marginal_likelihood()).abs() < 1e-12);
    let best = report
        .starts
        .iter()
        .map(|s| s.nlml)
        .fold(f64::INFINITY, f64::min);
    assert!((report.nlml - best).abs() < 1e-10 * best.abs());

    // A warm-started single-start refit begins at the optimum: it stops quickly and ends
    // no worse.
    let mut refitted = model.clone();
    let options = FitOptions {
        starts: 1,
        ..FitOptions::default()
    };
    let again = refitted.refit(&options).expect("refit");
    assert!(
        again.nlml <= report.nlml + 1e-6,
        "{} > {}",
        again.nlml,
        report.nlml
    );
    assert!(again.starts[0].iterations < 20, "{:?}", again.starts[0]);
}

/// The same seed gives the same fit; the noise never goes below its floor.
#[test]
fn fit_is_seeded_and_respects_the_noise_floor() {
    // Noise-free targets: the likelihood wants σ_n² → 0.
    let (inputs, targets) = synthetic(3, 30, 2, 0.0, smooth);
    let options = FitOptions {
        starts: 2,
        seed: 11,
        ..FitOptions::default()
    };
    let (a, report) = GaussianProcess::fit(&inputs, &targets, &options).expect("fit");
    let (b, _) = GaussianProcess::fit(&inputs, &targets, &options).expect("fit");
    assert_eq!(a.hyperparameters(), b.hyperparameters());
    let floor = report.bounds.lower[3];
    assert!(a.hyperparameters().log_noise_variance >= floor);
    assert!(floor <= (1e-8 * target_scale(&targets)).ln() + 1e-12);
}

/// `fit_many` on any number of threads gives each output exactly `fit`'s result: every run's
/// outcome and the model's hyperparameters, bit for bit; an output whose data are bad gets its
/// error and the others their fits.
#[test]
fn fit_many_equals_fit_whatever_the_threads() {
    let (inputs, y1) = synthetic(21, 40, 3, 0.05, smooth);
    let y2: Vec<f64> = inputs.rows().map(|x| x[2] * x[0] + 0.1 * x[1]).collect();
    let y3: Vec<f64> = inputs.rows().map(|x| (x[1] - x[2]).tanh()).collect();
    let bad = vec![f64::NAN; inputs.len()];
    let options = FitOptions {
        starts: 3,
        seed: 5,
        max_iterations: 40,
        ..FitOptions::default()
    };
    let alone: Vec<_> = [&y1, &y2, &y3]
        .iter()
        .map(|y| GaussianProcess::fit(&inputs, y, &options).expect("fit"))
        .collect();
    for threads in [1, 2, 3, 8] {
        let many = GaussianProcess::fit_many(&inputs, &[&y1, &bad, &y2, &y3], &options, threads);
        assert_eq!(many.len(), 4);
        assert!(many[1].is_err(), "{threads} threads: NaN targets fitted");
        for (fit, (model, report)) in [&many[0], &many[2], &many[3]].into_iter().zip(&alone) {
            let (m, r) = fit.as_ref().expect("fit");
            assert_eq!(r, report, "{threads} threads");
            assert_eq!(
                m.hyperparameters(),
                model.hyperparameters(),
                "{threads} threads"
            );
        }
    }
}

#[test]
fn predictions_interpolate_and_latent_variance_grows_away_from_data() {
    let xs = [-1.0, -0.4, 0.1, 0.5, 1.2, 2.0];
    let inputs = Inputs::from_rows(&xs.iter().map(|x| [*x]).collect::<Vec<_>>()).expect("rows");
    let targets: Vec<f64> = xs.iter().map(|x| (2.0 * x).sin()).collect();
    let model =
        GaussianProcess::new(inputs, targets.clone(), hyper(&[0.8], 1.0, 1e-10)).expect("model");
    let mut previous = 0.0;
    for (x, y) in xs.iter().zip(&targets) {
        let p = model.predict_point(&[*x]).expect("prediction");
        assert!((p.mean - y).abs() < 1e-6, "mean {} at a target {y}", p.mean);
        assert!(
            p.latent_variance < 1e-8,
            "latent variance {}",
            p.latent_variance
        );
        assert!((p.predictive_variance - p.latent_variance - 1e-10).abs() < 1e-15);
    }
    // Stepping away from the last point, the latent variance rises monotonically to σ_f².
    for step in [0.05, 0.2, 0.5, 1.0, 2.0, 5.0, 50.0] {
        let v = model
            .predict_point(&[2.0 + step])
            .expect("prediction")
            .latent_variance;
        assert!(
            v > previous,
            "variance {v} at distance {step} after {previous}"
        );
        previous = v;
    }
    assert!((previous - 1.0).abs() < 1e-12);
    // Between training points it exceeds the variance at them.
    let mid = model.predict_point(&[0.85]).expect("prediction");
    assert!(mid.latent_variance > 1e-4);
}

/// The blocked path of `predict` (from `BATCH_THRESHOLD` points) and the per-point path agree.
#[test]
fn batch_prediction_matches_point_predictions() {
    let (inputs, targets) = synthetic(4, 40, 3, 0.1, smooth);
    let model =
        GaussianProcess::new(inputs, targets, hyper(&[0.9, 1.1, 3.0], 0.7, 0.02)).expect("model");
    let points = test_points(13, 3 * BATCH_THRESHOLD, 3);
    let batch = model.predict(&points).expect("prediction");
    for (j, x) in points.rows().enumerate() {
        let p = model.predict_point(x).expect("prediction");
        assert!((p.mean - batch.mean[j]).abs() < 1e-12);
        assert!((p.latent_variance - batch.latent_variance[j]).abs() < 1e-12);
        assert!((p.predictive_variance - batch.predictive_variance[j]).abs() < 1e-12);
    }
    let few = Inputs::from_rows(&[points.row(0)]).expect("rows");
    assert_eq!(
        model.predict(&few).expect("prediction").mean[0],
        model.predict_point(points.row(0)).expect("prediction").mean
    );
    let none = Inputs::from_row_major(3, vec![]).expect("no points");
    assert_eq!(
        model.predict(&none).expect("prediction"),
        Predictions::default()
    );
}

#[test]
fn append_matches_a_refactor_from_scratch() {
    let (inputs, targets) = synthetic(5, 30, 3, 0.1, smooth);
    let h = hyper(&[0.9, 1.1, 3.0], 0.7, 0.02);
    let first = 20;
    let head =
        Inputs::from_row_major(3, inputs.as_row_major()[..first * 3].to_vec()).expect("rows");
    let mut appended =
        GaussianProcess::new(head, targets[..first].to_vec(), h.clone()).expect("model");
    for (i, y) in targets.iter().enumerate().skip(first) {
        appended.append(inputs.row(i), *y).expect("append");
    }
    let scratch = GaussianProcess::new(inputs, targets, h).expect("model");
    let gap = prediction_gap(&appended, &scratch, &test_points(9, 25, 3));
    assert!(gap < 1e-10, "append differs from refactoring by {gap:e}");
    let nlml_gap = (appended.negative_log_marginal_likelihood()
        - scratch.negative_log_marginal_likelihood())
    .abs();
    assert!(nlml_gap < 1e-10 * scratch.negative_log_marginal_likelihood().abs());
    assert_eq!(appended.len(), 30);
    assert_eq!(appended.jitter(), 0.0);
}

#[test]
fn remove_matches_a_refactor_from_scratch() {
    let (inputs, targets) = synthetic(6, 25, 3, 0.1, smooth);
    let h = hyper(&[0.9, 1.1, 3.0], 0.7, 0.02);
    let mut model =
        GaussianProcess::new(inputs.clone(), targets.clone(), h.clone()).expect("model");
    let mut kept: Vec<usize> = (0..25).collect();
    for index in [0, 10, 22] {
        model.remove(index).expect("remove");
        kept.remove(index);
        let rows: Vec<&[f64]> = kept.iter().map(|&i| inputs.row(i)).collect();
        let subset = Inputs::from_rows(&rows).expect("rows");
        let subset_targets = kept.iter().map(|&i| targets[i]).collect();
        let scratch = GaussianProcess::new(subset, subset_targets, h.clone()).expect("model");
        assert_eq!(model.inputs(), scratch.inputs());
        let gap = prediction_gap(&model, &scratch, &test_points(10, 25, 3));
        assert!(
            gap < 1e-10,
            "removing {index} differs from refactoring by {gap:e}"
        );
    }
}

/// Exact duplicates with (almost) no noise make `K` singular: the factorisation adds jitter,
/// reports it, and the model still predicts finite values. Appending yet another duplicate takes
/// the refactoring path.
#[test]
fn duplicated_inputs_take_the_jitter_path() {
    let rows = [[0.0, 1.0], [0.5, -0.3], [0.0, 1.0], [1.0, 0.2], [0.5, -0.3]];
    let inputs = Inputs::from_rows(&rows).expect("rows");
    let targets = vec![0.3, -0.1, 0.3, 0.8, -0.1];
    let h = hyper(&[0.7, 0.9], 1.0, 1e-100);
    let direct = nlml_with_gradient(&inputs, &targets, &h).expect("jittered likelihood");
    assert!(
        direct.jitter >= 1e-10 && direct.jitter <= 1e-4,
        "{}",
        direct.jitter
    );
    assert!(direct.nlml.is_finite() && direct.gradient.iter().all(|g| g.is_finite()));

    let mut model = GaussianProcess::new(inputs, targets, h.clone()).expect("model");
    assert_eq!(model.jitter(), direct.jitter);
    let p = model.predict_point(&[0.2, 0.4]).expect("prediction");
    assert!(p.mean.is_finite() && p.latent_variance.is_finite());
    let at_duplicate = model.predict_point(&[0.0, 1.0]).expect("prediction");
    assert!((at_duplicate.mean - 0.3).abs() < 1e-3);

    // A model without jitter meets a duplicate on append: it refactors with jitter.
    let clean = Inputs::from_rows(&rows[..2]).expect("rows");
    let mut growing = GaussianProcess::new(clean, vec![0.3, -0.1], h).expect("model");
    assert_eq!(growing.jitter(), 0.0);
    growing.append(&[0.0, 1.0], 0.3).expect("append duplicate");
    assert!(growing.jitter() > 0.0);
    assert_eq!(growing.len(), 3);
    model
        .append(&[1.0, 0.2], 0.8)
        .expect("append to a jittered model");
    assert!(model
        .predict_point(&[1.0, 0.2])
        .expect("prediction")
        .mean
        .is_finite());
}

/// JSON here parses floats exactly (serde_json's `float_roundtrip`); without it the last bit
/// of a value may change on the way back.
#[test]
fn serialisation_round_trip_gives_identical_predictions() {
    let (inputs, targets) = synthetic(8, 30, 3, 0.1, smooth);
    let points = test_points(12, 20, 3);
    let model =
        GaussianProcess::new(inputs, targets, hyper(&[0.9, 1.1, 3.0], 0.7, 0.02)).expect("model");
    let json = serde_json::to_string(&model).expect("serialise");
    let back: GaussianProcess = serde_json::from_str(&json).expect("deserialise");
    assert_eq!(
        model.predict(&points).expect("prediction"),
        back.predict(&points).expect("prediction")
    );
    assert_eq!(model.hyperparameters(), back.hyperparameters());

    // A jittered model comes back with the same jitter and the same predictions.
    let rows = [[0.0, 1.0], [0.5, -0.3], [0.0, 1.0]];
    let jittered = GaussianProcess::new(
        Inputs::from_rows(&rows).expect("rows"),
        vec![0.3, -0.1, 0.3],
        hyper(&[0.7, 0.9], 1.0, 1e-100),
    )
    .expect("model");
    let back: GaussianProcess =
        serde_json::from_str(&serde_json::to_string(&jittered).expect("serialise"))
            .expect("deserialise");
    assert!(jittered.jitter() > 0.0);
    assert_eq!(back.jitter(), jittered.jitter());
    let x = [0.2, 0.1];
    assert_eq!(
        jittered.predict_point(&x).expect("prediction"),
        back.predict_point(&x).expect("prediction")
    );

    // After appends the reloaded model is refactored whole: equal up to rounding.
    let mut grown = model.clone();
    grown.append(&[0.1, 0.2, 0.3], 0.5).expect("append");
    let back: GaussianProcess =
        serde_json::from_str(&serde_json::to_string(&grown).expect("serialise"))
            .expect("deserialise");
    assert!(prediction_gap(&grown, &back, &points) < 1e-12);
}

#[test]
fn models_can_move_between_threads() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<GaussianProcess>();
    send_sync::<TrackedPoints>();
    send_sync::<PendingAppend>();
    send_sync::<Inputs>();
    send_sync::<FitReport>();
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let good = Inputs::from_rows(&[[0.0, 1.0], [1.0, 0.0]]).expect("rows");
    let h = hyper(&[1.0, 1.0], 1.0, 0.1);
    let nan = f64::NAN;

    assert!(matches!(
        Inputs::from_row_major(2, vec![0.0, nan]),
        Err(GpError::NotFinite { .. })
    ));
    assert!(matches!(
        Inputs::from_row_major(2, vec![0.0, 1.0, 2.0]),
        Err(GpError::RaggedInputs { .. })
    ));
    assert!(matches!(
        Inputs::from_row_major(0, vec![]),
        Err(GpError::ZeroDimension)
    ));
    assert!(Inputs::from_rows(&[vec![0.0, 1.0], vec![1.0]]).is_err());
    assert!(Hyperparameters::new(&[1.0, -1.0], 1.0, 0.1).is_err());
    assert!(Hyperparameters::new(&[1.0, 1.0], nan, 0.1).is_err());

    let empty = Inputs::from_row_major(2, vec![]).expect("an empty set of points");
    assert_eq!(
        GaussianProcess::new(empty.clone(), vec![], h.clone()).err(),
        Some(GpError::NoPoints)
    );
    assert!(GaussianProcess::fit(&empty, &[], &FitOptions::default()).is_err());
    assert!(matches!(
        GaussianProcess::new(good.clone(), vec![1.0], h.clone()),
        Err(GpError::LengthMismatch { .. })
    ));
    assert!(GaussianProcess::new(good.clone(), vec![1.0, nan], h.clone()).is_err());
    assert!(GaussianProcess::fit(&good, &[1.0, f64::INFINITY], &FitOptions::default()).is_err());
    assert!(GaussianProcess::new(good.clone(), vec![1.0, 0.0], hyper(&[1.0], 1.0, 0.1)).is_err());
    let mut overflow = h.clone();
    overflow.log_signal_variance = 800.0;
    assert!(GaussianProcess::new(good.clone(), vec![1.0, 0.0], overflow.clone()).is_err());
    overflow.log_signal_variance = 0.0;
    overflow.log_lengthscales[1] = -400.0;
    assert!(GaussianProcess::new(good.clone(), vec![1.0, 0.0], overflow).is_err());
    assert!(negative_log_marginal_likelihood(&good, &[1.0], &h).is_err());
    assert!(nlml_with_gradient(&empty, &[], &h).is_err());
    for options in [
        FitOptions {
            starts: 0,
            ..FitOptions::default()
        },
        FitOptions {
            noise_floor: 0.0,
            ..FitOptions::default()
        },
        FitOptions {
            gradient_tolerance: nan,
            ..FitOptions::default()
        },
        FitOptions {
            warm_start: Some(hyper(&[1.0], 1.0, 0.1)),
            ..FitOptions::default()
        },
    ] {
        assert!(matches!(
            GaussianProcess::fit(&good, &[1.0, 0.0], &options),
            Err(GpError::InvalidOptions(_) | GpError::LengthMismatch { .. })
        ));
    }

    let mut model = GaussianProcess::new(good, vec![1.0, 0.0], h).expect("model");
    assert!(model.predict_point(&[0.0]).is_err());
    assert!(model.predict_point(&[0.0, nan]).is_err());
    let wrong_dim = Inputs::from_rows(&[[0.0, 1.0, 2.0]]).expect("rows");
    assert!(model.predict(&wrong_dim).is_err());
    assert!(model.append(&[0.0, nan], 1.0).is_err());
    assert!(model.append(&[0.0, 0.5], nan).is_err());
    assert!(model.append(&[0.0], 1.0).is_err());
    assert_eq!(model.len(), 2, "a refused append changes nothing");
    assert!(matches!(
        model.remove(2),
        Err(GpError::IndexOutOfRange { .. })
    ));
    model.remove(1).expect("remove");
    assert_eq!(model.remove(0), Err(GpError::LastPoint));

    // Hostile or broken snapshots.
    for json in [
        r#"{"inputs":{"dim":2,"values":[0.0,1.0]},"targets":[1.0,2.0],"hyperparameters":{"log_lengthscales":[0.0,0.0],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":0.0}"#,
        r#"{"inputs":{"dim":0,"values":[]},"targets":[],"hyperparameters":{"log_lengthscales":[],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":0.0}"#,
        r#"{"inputs":{"dim":2,"values":[0.0,1.0,2.0]},"targets":[1.0],"hyperparameters":{"log_lengthscales":[0.0,0.0],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":0.0}"#,
        r#"{"inputs":{"dim":2,"values":[0.0,1.0]},"targets":[1.0],"hyperparameters":{"log_lengthscales":[0.0],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":0.0}"#,
        r#"{"inputs":{"dim":2,"values":[0.0,1.0]},"targets":[1.0],"hyperparameters":{"log_lengthscales":[0.0,0.0],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":-1.0}"#,
        r#"{"inputs":{"dim":2,"values":[0.0,1.0]},"targets":[1.0],"hyperparameters":{"log_lengthscales":[0.0,0.0],"log_signal_variance":0.0,"log_noise_variance":-2.0},"jitter":1.0}"#,
        r#"{"inputs":{"dim":2,"values":[0.0,1.0]},"targets":[1.0],"hyperparameters":{"log_lengthscales":[0.0,0.0],"log_signal_variance":0.0,"log_noise_variance":1e308},"jitter":0.0}"#,
    ] {
        assert!(
            serde_json::from_str::<GaussianProcess>(json).is_err(),
            "accepted {json}"
        );
    }
}

/// Largest gap between tracked values and fresh predictions: variances relative to σ_f², means
/// relative to the targets' largest magnitude.
fn tracking_gap(tracked: &TrackedPoints, model: &GaussianProcess) -> f64 {
    let fresh = model.predict(tracked.points()).expect("prediction");
    let var_scale = model.hyperparameters().signal_variance();
    let mean_scale = model.targets().iter().fold(0.0f64, |m, y| m.max(y.abs()));
    let latent = tracked.latent_variances();
    (0..tracked.len()).fold(0.0f64, |gap, j| {
        gap.max((latent[j] - fresh.latent_variance[j]).abs() / var_scale)
            .max((tracked.means()[j] - fresh.mean[j]).abs() / mean_scale)
    })
}

/// Appends, removals at the front, middle and end, several changes between syncs, a
/// refactorisation with jitter and a refit: the tracked values follow the model to rounding,
/// incrementally while the change log reaches, by solving again otherwise.
#[test]
fn tracked_points_follow_appends_removals_and_refits() {
    let (inputs, targets) = synthetic(21, 160, 3, 0.1, smooth);
    let h = hyper(&[0.9, 1.1, 3.0], 0.7, 0.02);
    let first = 40;
    let head =
        Inputs::from_row_major(3, inputs.as_row_major()[..first * 3].to_vec()).expect("rows");
    let mut model =
        GaussianProcess::new(head, targets[..first].to_vec(), h.clone()).expect("model");
    // Beyond BLOCK points, so that the rebuild solves in several blocks.
    let points = test_points(22, 300, 3);
    let mut tracked = TrackedPoints::new(&model, points).expect("tracked");
    assert_eq!(tracked.rebuilds(), 1);
    assert!(tracking_gap(&tracked, &model) < 1e-12);
    for (i, y) in targets.iter().enumerate().skip(first) {
        model.append(inputs.row(i), *y).expect("append");
        match i % 4 {
            // A learning step at the size limit: append, then drop the oldest.
            0 => model.remove(0).expect("remove"),
            1 => model.remove(model.len() / 2).expect("remove"),
            2 if i % 8 == 2 => model.remove(model.len() - 1).expect("remove"),
            _ => {}
        }
        // Sync after every step, or every third step (several changes at once).
        if i % 3 != 1 {
            assert_eq!(tracked.sync(&model).expect("sync"), Tracking::Updated);
            let gap = tracking_gap(&tracked, &model);
            assert!(gap < 1e-10, "step {i}: tracked values differ by {gap:e}");
        }
    }
    assert_eq!(tracked.rebuilds(), 1, "the log covered every step");
    assert_eq!(tracked.sync(&model).expect("sync"), Tracking::Current);
    // The model itself after all those steps: as if factored from scratch.
    let scratch = GaussianProcess::new(model.inputs().clone(), model.targets().to_vec(), h.clone())
        .expect("model");
    let gap = prediction_gap(&model, &scratch, tracked.points());
    assert!(
        gap < 1e-10,
        "appends and removals differ from a refactor by {gap:e}"
    );

    // More changes than the log holds: solved again.
    for i in 0..20 {
        model
            .append(&[0.01 * i as f64, -0.5, 0.3], 0.1)
            .expect("append");
    }
    assert_eq!(tracked.sync(&model).expect("sync"), Tracking::Rebuilt);
    assert!(tracking_gap(&tracked, &model) < 1e-12);

    // New hyperparameters: solved again.
    model
        .refit(&FitOptions {
            starts: 1,
            max_iterations: 5,
            ..FitOptions::default()
        })
        .expect("refit");
    assert_eq!(tracked.sync(&model).expect("sync"), Tracking::Rebuilt);
    assert!(tracking_gap(&tracked, &model) < 1e-12);

    // A duplicate with almost no noise takes the jitter path (a refactorisation): solved again.
    let rows = [[0.0, 1.0, 0.5], [0.5, -0.3, 0.2]];
    let mut tiny = GaussianProcess::new(
        Inputs::from_rows(&rows).expect("rows"),
        vec![0.3, -0.1],
        hyper(&[0.7, 0.9, 1.0], 1.0, 1e-100),
    )
    .expect("model");
    let mut near = TrackedPoints::new(&tiny, test_points(23, 10, 3)).expect("tracked");
    tiny.append(&rows[0], 0.3).expect("append duplicate");
    assert!(tiny.jitter() > 0.0);
    assert_eq!(near.sync(&tiny).expect("sync"), Tracking::Rebuilt);
    assert!(tracking_gap(&near, &tiny) < 1e-9);

    // Another model's state is not mistaken for this one's.
    let other = GaussianProcess::new(
        Inputs::from_rows(&[[0.0, 0.0, 0.0]]).expect("rows"),
        vec![1.0],
        h,
    )
    .expect("model");
    assert_eq!(tracked.sync(&other).expect("sync"), Tracking::Rebuilt);
    assert!(tracking_gap(&tracked, &other) < 1e-12);
    assert!(tracked.sync(&tiny).is_ok());
    let wrong = GaussianProcess::new(
        Inputs::from_rows(&[[0.0, 0.0]]).expect("rows"),
        vec![1.0],
        hyper(&[1.0, 1.0], 1.0, 0.1),
    )
    .expect("model");
    assert!(tracked.sync(&wrong).is_err());
    assert!(TrackedPoints::new(&wrong, test_points(24, 3, 3)).is_err());
}

/// Plans for several models, then commits: the same as appending; a plan made from another
/// state is appended afresh; a refused plan changes nothing.
#[test]
fn planned_appends_commit_like_appends() {
    let (inputs, targets) = synthetic(25, 31, 3, 0.1, smooth);
    let h = hyper(&[0.9, 1.1, 3.0], 0.7, 0.02);
    let head = Inputs::from_row_major(3, inputs.as_row_major()[..30 * 3].to_vec()).expect("rows");
    let base = GaussianProcess::new(head, targets[..30].to_vec(), h).expect("model");
    let mut appended = base.clone();
    appended
        .append(inputs.row(30), targets[30])
        .expect("append");
    let mut planned = base.clone();
    let plan = planned
        .plan_append(inputs.row(30), targets[30])
        .expect("plan");
    assert_eq!(planned.len(), 30, "planning changes nothing");
    planned.commit(plan.clone()).expect("commit");
    let points = test_points(26, 20, 3);
    assert_eq!(
        appended.predict(&points).expect("prediction"),
        planned.predict(&points).expect("prediction")
    );
    // Stale: the model moved on since the plan.
    let mut moved = base.clone();
    moved.remove(0).expect("remove");
    moved.commit(plan).expect("commit afresh");
    assert_eq!(moved.len(), 30);
    assert_eq!(moved.inputs().row(29), inputs.row(30));
    assert!(base.plan_append(&[0.0, f64::NAN, 0.0], 1.0).is_err());
}

/// Points added to a tracked set, one at a time or as a block, after the model moved on: the
/// same values as tracking them from the start.
#[test]
fn tracked_points_can_be_extended() {
    let (inputs, targets) = synthetic(27, 60, 3, 0.1, smooth);
    let h = hyper(&[0.9, 1.1, 3.0], 0.7, 0.02);
    let head = Inputs::from_row_major(3, inputs.as_row_major()[..40 * 3].to_vec()).expect("rows");
    let mut model = GaussianProcess::new(head, targets[..40].to_vec(), h).expect("model");
    let none = Inputs::from_row_major(3, Vec::new()).expect("no points");
    let mut tracked = TrackedPoints::new(&model, none).expect("tracked");
    assert!(tracked.is_empty());
    let few = test_points(28, 3, 3);
    let many = test_points(29, 40, 3);
    for (i, y) in targets.iter().enumerate().take(50).skip(40) {
        model.append(inputs.row(i), *y).expect("append");
    }
    model.remove(0).expect("remove");
    // The model changed more than the log holds: extending solves again first.
    assert_eq!(
        tracked.extend(&model, &few).expect("extend"),
        Tracking::Rebuilt
    );
    assert_eq!(tracked.len(), 3);
    assert!(tracking_gap(&tracked, &model) < 1e-12);
    for (i, y) in targets.iter().enumerate().take(55).skip(50) {
        model.append(inputs.row(i), *y).expect("append");
        assert_eq!(tracked.sync(&model).expect("sync"), Tracking::Updated);
    }
    model.append(inputs.row(55), targets[55]).expect("append");
    assert_eq!(
        tracked.extend(&model, &many).expect("extend"),
        Tracking::Updated
    );
    assert_eq!(tracked.len(), 43);
    assert!(tracking_gap(&tracked, &model) < 1e-10);
    let wrong = Inputs::from_rows(&[[0.0, 1.0]]).expect("rows");
    assert!(tracked.extend(&model, &wrong).is_err());
}
