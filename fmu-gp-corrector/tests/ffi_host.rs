//! The corrector driven through its C exports as a host drives it: physics passed through when
//! untrained, learning lowers the latent variance where it learned, predictions equal to
//! `numerics::gp` run in-process on the same data (with learning and the refit schedule), FMU
//! states that carry the learned points, and bad training files or parameters refused with a
//! message that says what is wrong.

// The test host (recording logger, thin wrappers over the C functions) is the export layer's;
// it calls the `fmi2*` functions at this crate's root.
#[path = "../../fmi2/tests/common/mod.rs"]
mod common;
mod support;

use fmu_gp_corrector::{
    fmi2DeSerializeFMUstate, fmi2DoStep, fmi2EnterInitializationMode, fmi2ExitInitializationMode,
    fmi2FreeFMUstate, fmi2FreeInstance, fmi2GetBoolean, fmi2GetFMUstate, fmi2GetInteger,
    fmi2GetReal, fmi2GetString, fmi2Instantiate, fmi2Reset, fmi2SerializeFMUstate,
    fmi2SerializedFMUstateSize, fmi2SetBoolean, fmi2SetDebugLogging, fmi2SetFMUstate,
    fmi2SetInteger, fmi2SetReal, fmi2SetRealInputDerivatives, fmi2SetString, fmi2SetupExperiment,
    fmi2Terminate,
};

use common::Slave;
use fmi2::abi::*;
use fmu_gp_corrector::model::{refit_options, INITIAL_NOISE_VARIANCE, INITIAL_SIGNAL_VARIANCE};
use fmu_gp_corrector::variables::*;
use fmu_gp_corrector::{lagged_inputs, Sample, TargetForm, TrainingFile};
use numerics::gp::{FitOptions, GaussianProcess, Inputs};
use support::*;

#[track_caller]
fn assert_refused(s: &Slave, status: fmi2Status, needles: &[&str]) {
    assert_eq!(
        status,
        fmi2Error,
        "expected fmi2Error; logged: {:#?}",
        s.host.records()
    );
    s.host.expect(fmi2Error, needles);
    s.host.clear();
}

/// An initialized instance with no training data, `lags` lags and the given target form.
fn untrained(dir: &std::path::Path, lags: i32, target: i32) -> Slave {
    let s = slave_in(dir);
    enter(&s);
    set_integer(&s, LAGS, lags);
    set_integer(&s, TARGET, target);
    exit(&s);
    s
}

#[test]
fn an_untrained_corrector_passes_the_physics_through_with_the_prior_variance() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = untrained(dir.path(), 9, 0);
    assert_eq!(training_points(&s), 0);
    let record = samples(1, 40);
    for (k, sample) in record.iter().enumerate() {
        set_inputs(&s, sample, &measured(sample), false);
        for (floor, [acc, latent, sd]) in outputs(&s).into_iter().enumerate() {
            assert_eq!(
                acc.to_bits(),
                sample[floor].to_bits(),
                "step {k} floor {floor}"
            );
            // σ_f² as the GP holds it, in log form: the parameter to rounding.
            assert!((latent - INITIAL_SIGNAL_VARIANCE).abs() < 1e-15, "{latent}");
            let prior_sd = (INITIAL_SIGNAL_VARIANCE + INITIAL_NOISE_VARIANCE).sqrt();
            assert!((sd - prior_sd).abs() < 1e-15, "{sd}");
        }
        assert_eq!(s.step(k as f64 * H, H), fmi2OK);
    }
    assert_eq!(training_points(&s), 0, "learn was false throughout");

    // The paper's form without data: the GP's zero prior mean.
    let s = untrained(dir.path(), 9, 1);
    set_inputs(&s, &record[3], &measured(&record[3]), false);
    for [acc, latent, _] in outputs(&s) {
        assert_eq!(acc, 0.0);
        assert!((latent - INITIAL_SIGNAL_VARIANCE).abs() < 1e-15, "{latent}");
    }
}

#[test]
fn the_initial_hyperparameters_set_the_prior() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = slave_in(dir.path());
    enter(&s);
    assert_eq!(
        s.set_reals(
            &[INITIAL_SIGNAL_VARIANCE_VR, INITIAL_NOISE_VARIANCE_VR],
            &[0.25, 0.01]
        ),
        fmi2OK
    );
    exit(&s);
    let [_, latent, sd] = outputs(&s)[1];
    assert!((latent - 0.25).abs() < 1e-15, "{latent}");
    assert!((sd - 0.26f64.sqrt()).abs() < 1e-15, "{sd}");
}

#[test]
fn learning_a_sample_lowers_the_latent_variance_at_its_input() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sample: Sample = [0.05, -0.02, 0.08, 0.3];
    let truth = measured(&sample);

    // Without lags the input vector is the current sample alone, the same after the step.
    let s = untrained(dir.path(), 0, 0);
    set_inputs(&s, &sample, &truth, true);
    let before = outputs(&s);
    assert_eq!(s.step(0.0, H), fmi2OK);
    let after = outputs(&s);
    assert_eq!(training_points(&s), 1);
    for floor in 0..3 {
        let latent = (before[floor][1], after[floor][1]);
        assert!(
            latent.1 < 0.05 * latent.0,
            "floor {floor}: latent variance {} → {}",
            latent.0,
            latent.1
        );
        // With σ_n² = 1 % of σ_f², the mean moves nearly all the way to the learned target.
        let learned = truth[floor] - sample[floor];
        let moved = after[floor][0] - sample[floor];
        assert!(
            (moved - learned).abs() < 0.02 * learned.abs(),
            "floor {floor}: {moved} for {learned}"
        );
    }

    // With 9 lags: a sample held for 10 steps fills the buffer, so the lag vector before and
    // after learning at the last step is the same.
    let s = untrained(dir.path(), 9, 0);
    set_inputs(&s, &sample, &truth, false);
    for k in 0..10 {
        assert_eq!(s.step(k as f64 * H, H), fmi2OK);
    }
    let before = outputs(&s);
    assert_eq!(s.set_booleans(&[LEARN], &[fmi2True]), fmi2OK);
    assert_eq!(s.step(10.0 * H, H), fmi2OK);
    let after = outputs(&s);
    assert_eq!(training_points(&s), 1);
    for floor in 0..3 {
        assert!(after[floor][1] < 0.05 * before[floor][1], "floor {floor}");
        assert!(after[floor][2] < before[floor][2], "floor {floor}: sd");
    }
    // Elsewhere in the input space the variance stays near the prior's.
    set_inputs(&s, &[-0.3, 0.3, -0.3, -1.0], &truth, false);
    assert!(outputs(&s)[0][1] > 0.9 * before[0][1]);
}

/// Drive an instance through `record` (set inputs → read outputs → step, learning at the steps
/// `learn_at` selects) and an in-process copy of its GPs alongside; every output must be the
/// in-process value, bit for bit.
fn assert_matches_in_process(
    s: &Slave,
    mut gps: Vec<GaussianProcess>,
    target: TargetForm,
    lags: usize,
    refit_every: u32,
    record: &[Sample],
    learn_at: impl Fn(usize) -> bool,
) {
    let x = lagged_inputs(record, lags);
    let mut learned_since_refit = 0;
    let mut refits = 0;
    for (k, sample) in record.iter().enumerate() {
        let truth = measured(sample);
        let learn = learn_at(k);
        set_inputs(s, sample, &truth, learn);
        let fmu = outputs(s);
        for floor in 0..3 {
            let p = gps[floor].predict_point(&x[k]).expect("prediction");
            let expected = expected_outputs(target, sample[floor], &p);
            assert_eq!(
                fmu[floor].map(f64::to_bits),
                expected.map(f64::to_bits),
                "step {k}, floor {}: FMU {:?}, in-process {:?}",
                floor + 1,
                fmu[floor],
                expected
            );
        }
        assert_eq!(s.step(k as f64 * H, H), fmi2OK, "{:#?}", s.host.records());
        if learn {
            for (floor, gp) in gps.iter_mut().enumerate() {
                gp.append(&x[k], target.target(truth[floor], sample[floor]))
                    .expect("append");
            }
            learned_since_refit += 1;
            if refit_every > 0 && learned_since_refit == refit_every {
                for gp in gps.iter_mut() {
                    gp.refit(&refit_options()).expect("refit");
                }
                learned_since_refit = 0;
                refits += 1;
            }
        }
        assert_eq!(training_points(s) as usize, gps[0].len());
    }
    if refit_every > 0 {
        assert!(refits > 0, "the run reached a refit");
    }
}

#[test]
fn predictions_through_the_fmu_equal_the_gp_in_process_while_learning_and_refitting() {
    let dir = tempfile::tempdir().expect("temp dir");
    // The refit schedule in the discrepancy form; the paper's form learns without refits (the
    // refits dominate this test's time in a debug build).
    for (target, code, refit_every) in [
        (TargetForm::Discrepancy, 0, 6),
        (TargetForm::Measured, 1, 0),
    ] {
        let file = training_file(7, 30, 9, target, true);
        // A relative training_path is looked up in the resources folder.
        write(dir.path(), "set.json", &file);
        let s = slave_in(dir.path());
        enter(&s);
        set_integer(&s, TARGET, code);
        set_string(&s, TRAINING_PATH, "set.json");
        set_integer(&s, REFIT_EVERY, refit_every as i32);
        exit(&s);
        assert_eq!(training_points(&s), 30);
        let record = samples(8, 40);
        assert_matches_in_process(
            &s,
            reference_gps(&file),
            target,
            9,
            refit_every,
            &record,
            |k| k % 3 == 1,
        );
    }
}

#[test]
fn hyperparameters_missing_from_the_file_are_fitted_as_numerics_fits_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = training_file(11, 30, 1, TargetForm::Discrepancy, false);
    let path = write(dir.path(), "fit.json", &file);
    let s = slave_in(dir.path());
    enter(&s);
    set_integer(&s, LAGS, 1);
    set_string(&s, TRAINING_PATH, &path.display().to_string());
    set_integer(&s, REFIT_EVERY, 0);
    exit(&s);
    let inputs = Inputs::from_rows(&file.inputs).expect("inputs");
    let gps: Vec<GaussianProcess> = (0..3)
        .map(|f| {
            let targets: Vec<f64> = file.targets.iter().map(|y| y[f]).collect();
            GaussianProcess::fit(&inputs, &targets, &FitOptions::default())
                .expect("fit")
                .0
        })
        .collect();
    let record = samples(12, 12);
    assert_matches_in_process(&s, gps, TargetForm::Discrepancy, 1, 0, &record, |k| k == 5);
}

#[test]
fn the_first_refit_of_an_untrained_corrector_fits_from_the_data() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = slave_in(dir.path());
    enter(&s);
    set_integer(&s, LAGS, 2);
    set_integer(&s, REFIT_EVERY, 8);
    exit(&s);
    let record = samples(21, 20);
    let x = lagged_inputs(&record, 2);
    for (k, sample) in record[..19].iter().enumerate() {
        set_inputs(&s, sample, &measured(sample), k < 8);
        assert_eq!(s.step(k as f64 * H, H), fmi2OK, "{:#?}", s.host.records());
    }
    assert_eq!(training_points(&s), 8);
    // After 8 learned points the hyperparameters are the data-based fit of those 8.
    let inputs = Inputs::from_rows(&x[..8]).expect("inputs");
    set_inputs(&s, &record[19], &[0.0; 3], false);
    let fmu = outputs(&s);
    for floor in 0..3 {
        let targets: Vec<f64> = record[..8]
            .iter()
            .map(|sm| measured(sm)[floor] - sm[floor])
            .collect();
        let (gp, _) = GaussianProcess::fit(&inputs, &targets, &FitOptions::default()).expect("fit");
        let p = gp.predict_point(&x[19]).expect("prediction");
        let expected = expected_outputs(TargetForm::Discrepancy, record[19][floor], &p);
        // The fit replaced the model grown point by point with one factorised whole, as
        // in-process.
        assert_eq!(fmu[floor], expected, "floor {floor}");
        assert_ne!(fmu[floor][1], INITIAL_SIGNAL_VARIANCE);
    }
}

/// Learn on a record from `first` for `steps` steps; the outputs read before each step.
fn learn_run(s: &Slave, record: &[Sample], first: usize, steps: usize) -> Vec<u64> {
    let mut out = Vec::new();
    for (k, sample) in record.iter().enumerate().skip(first).take(steps) {
        set_inputs(s, sample, &measured(sample), k % 2 == 0);
        out.extend(outputs(s).iter().flatten().map(|v| v.to_bits()));
        assert_eq!(s.step(k as f64 * H, H), fmi2OK, "{:#?}", s.host.records());
    }
    out
}

#[track_caller]
fn assert_close(a: &[u64], b: &[u64], relative: f64) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let (x, y) = (f64::from_bits(*x), f64::from_bits(*y));
        assert!(
            (x - y).abs() <= relative * y.abs().max(1e-3),
            "value {i}: {x} vs {y}"
        );
    }
}

#[test]
fn fmu_states_carry_the_learned_points() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = untrained(dir.path(), 9, 0);
    set_integer(&s, REFIT_EVERY, 0);
    let record = samples(31, 80);
    learn_run(&s, &record, 0, 40);
    assert_eq!(training_points(&s), 20);
    let state = s.get_state();
    let bytes = s.serialize(state);
    let reference = learn_run(&s, &record, 40, 20);
    assert_eq!(training_points(&s), 30);

    // In memory: exactly where it was, and the same continuation.
    assert_eq!(s.set_state(state), fmi2OK);
    assert_eq!(training_points(&s), 20);
    assert_eq!(learn_run(&s, &record, 40, 20), reference);
    s.free_state(state);

    // Serialized, into another instance: the 20 points, the hyperparameters and the lag buffer
    // came along. The factor is recomputed whole on loading, so the values agree to rounding.
    let other = untrained(dir.path(), 9, 0);
    assert_eq!(training_points(&other), 0);
    let (status, restored) = other.deserialize(&bytes);
    assert_eq!(status, fmi2OK, "{:#?}", other.host.records());
    assert_eq!(other.set_state(restored), fmi2OK);
    assert_eq!(training_points(&other), 20);
    assert_eq!(other.get_integers(&[REFIT_EVERY]).1, vec![0]);
    assert_close(&learn_run(&other, &record, 40, 20), &reference, 1e-9);
    assert_eq!(training_points(&other), 30);
    other.free_state(restored);
}

#[test]
fn a_bad_bundled_training_file_fails_instantiation_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("training.json");
    for (text, problem) in [
        ("{\"lags\": 9, \"target\": ", "not a training file"),
        (
            r#"{"lags": 0, "target": "discrepancy", "inputs": [[1, 2, 3]], "targets": [[0, 0, 0]]}"#,
            "inputs[0] has 3 values, expected 4",
        ),
    ] {
        std::fs::write(&path, text).expect("write");
        let host = common::Host::new();
        let c = instantiate_in(&host, dir.path());
        assert!(c.is_null(), "instantiated with {text}");
        host.expect(
            fmi2Error,
            &["fmi2Instantiate", &path.display().to_string(), problem],
        );
    }
    // A good bundled file is loaded when training_path is empty.
    let file = training_file(3, 10, 9, TargetForm::Discrepancy, true);
    write(dir.path(), "training.json", &file);
    let s = slave_in(dir.path());
    enter(&s);
    exit(&s);
    assert_eq!(training_points(&s), 10);
}

#[test]
fn a_state_taken_before_initialization_carries_the_bundled_file() {
    // Without hyperparameters, so that the optional field travels as "absent" in the state.
    let dir = tempfile::tempdir().expect("temp dir");
    let file = training_file(13, 8, 1, TargetForm::Discrepancy, false);
    write(dir.path(), "training.json", &file);
    let s = slave_in(dir.path());
    let state = s.get_state();
    let bytes = s.serialize(state);
    s.free_state(state);

    // Another instance, whose own resources hold no file, takes the state and initializes with
    // the file it carries.
    let empty = tempfile::tempdir().expect("temp dir");
    let other = slave_in(empty.path());
    let (status, restored) = other.deserialize(&bytes);
    assert_eq!(status, fmi2OK, "{:#?}", other.host.records());
    assert_eq!(other.set_state(restored), fmi2OK);
    other.free_state(restored);
    enter(&other);
    set_integer(&other, LAGS, 1);
    exit(&other);
    assert_eq!(training_points(&other), 8);
}

#[test]
fn bad_training_paths_are_refused_at_initialization_and_can_be_fixed() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = training_file(5, 12, 9, TargetForm::Discrepancy, true);
    let mut short_row = good.clone();
    short_row.inputs[4].pop();
    let mut measured_targets = good.clone();
    measured_targets.target = TargetForm::Measured;
    let lags_3 = training_file(5, 12, 3, TargetForm::Discrepancy, true);
    let cases: Vec<(String, Vec<String>)> = vec![
        (
            write(dir.path(), "short.json", &short_row)
                .display()
                .to_string(),
            vec!["inputs[4] has 39 values, expected 40".into()],
        ),
        (
            dir.path().join("absent.json").display().to_string(),
            vec!["cannot read it".into()],
        ),
        (
            write(dir.path(), "measured.json", &measured_targets)
                .display()
                .to_string(),
            vec![
                "targets are 'measured'".into(),
                "parameter target is 0".into(),
            ],
        ),
        (
            write(dir.path(), "lags3.json", &lags_3)
                .display()
                .to_string(),
            vec!["lags = 3".into(), "parameter lags is 9".into()],
        ),
    ];
    let s = slave_in(dir.path());
    enter(&s);
    for (path, problems) in &cases {
        set_string(&s, TRAINING_PATH, path);
        let mut needles = vec!["fmi2ExitInitializationMode", path.as_str()];
        needles.extend(problems.iter().map(String::as_str));
        assert_refused(&s, s.exit(), &needles);
        // Reading an output in initialization mode meets the same problem, refused too.
        assert_refused(
            &s,
            s.get_reals(&[ACC]).0,
            &["fmi2GetReal", "training_path", path.as_str()],
        );
    }
    // Still in initialization mode: a good file gets the instance going.
    let path = write(dir.path(), "good.json", &good);
    set_string(&s, TRAINING_PATH, &path.display().to_string());
    exit(&s);
    assert_eq!(training_points(&s), 12);
    assert_eq!(s.step(0.0, H), fmi2OK);
}

#[test]
fn parameters_outside_their_ranges_are_refused_and_fixed_ones_stay_fixed() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s = slave_in(dir.path());
    enter(&s);
    for (vr, value, needle) in [
        (LAGS, 65, "'lags': 65 is outside [0, 64]"),
        (LAGS, -1, "'lags': -1 is outside"),
        (TARGET, 2, "'target': 2 is neither 0"),
        (REFIT_EVERY, -3, "'refit_every': -3 must be ≥ 0"),
        (BUDGET, 0, "'budget': 0 is outside [1, 2048]"),
        (BUDGET, 2049, "'budget': 2049 is outside [1, 2048]"),
    ] {
        assert_refused(&s, s.set_integers(&[vr], &[value]), &[needle]);
    }
    for vr in [
        INITIAL_SIGNAL_VARIANCE_VR,
        INITIAL_NOISE_VARIANCE_VR,
        INITIAL_LENGTH_SCALE_VR,
    ] {
        assert_refused(&s, s.set_reals(&[vr], &[0.0]), &["0 must be > 0"]);
    }
    assert_eq!(
        s.get_integers(&[LAGS, TARGET, REFIT_EVERY]).1,
        vec![9, 0, 25]
    );
    exit(&s);
    assert_refused(
        &s,
        s.set_integers(&[LAGS], &[3]),
        &["'lags' is a fixed parameter"],
    );
    assert_refused(
        &s,
        s.set_strings(&[TRAINING_PATH], &["x.json"]),
        &["'training_path' is a fixed parameter"],
    );
    // The refit schedule is tunable.
    assert_eq!(s.set_integers(&[REFIT_EVERY], &[5]), fmi2OK);
    assert_eq!(s.get_integers(&[REFIT_EVERY]).1, vec![5]);
    assert_eq!(s.get_strings(&[TRAINING_PATH]).1, vec![Some(String::new())]);
}

#[test]
fn outputs_follow_inputs_set_after_the_last_step() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = training_file(41, 30, 9, TargetForm::Discrepancy, true);
    write(dir.path(), "training.json", &file);
    let s = slave_in(dir.path());
    enter(&s);
    exit(&s);
    let record = samples(42, 12);
    for (k, sample) in record[..11].iter().enumerate() {
        set_inputs(&s, sample, &[0.0; 3], false);
        assert_eq!(s.step(k as f64 * H, H), fmi2OK);
    }
    let stale = outputs(&s);
    // No step in between: the new current sample alone changes the lag vector's last entries.
    set_inputs(&s, &record[11], &[0.0; 3], false);
    let fresh = outputs(&s);
    let x = lagged_inputs(&record, 9);
    let gps = reference_gps(&file);
    for floor in 0..3 {
        let p = gps[floor].predict_point(&x[11]).expect("prediction");
        assert_eq!(
            fresh[floor],
            expected_outputs(TargetForm::Discrepancy, record[11][floor], &p)
        );
        assert_ne!(fresh[floor][0], stale[floor][0]);
    }
}

#[test]
fn a_training_file_written_from_the_model_loads_back_to_the_same_predictions() {
    use fmi2::{CoSimModel, InstantiateContext};
    use fmu_gp_corrector::GpCorrector;

    let dir = tempfile::tempdir().expect("temp dir");
    let context = InstantiateContext {
        instance_name: "in-process".into(),
        resource_dir: Some(dir.path().to_path_buf()),
    };
    let mut model = GpCorrector::instantiate(&context).expect("instantiate");
    model.set_integer(LAGS, 4).expect("lags");
    model.set_integer(REFIT_EVERY, 10).expect("refit_every");
    model.exit_initialization().expect("initialize");
    let record = samples(51, 25);
    for (k, sample) in record.iter().enumerate() {
        for (i, v) in sample.iter().enumerate() {
            model.set_real(PHYSICS_ACC + i as u32, *v).expect("set");
        }
        for (i, v) in measured(sample).iter().enumerate() {
            model.set_real(MEASURED_ACC + i as u32, *v).expect("set");
        }
        model.set_boolean(LEARN, k < 15).expect("learn");
        model.do_step(k as f64 * H, H).expect("step");
    }
    let file = model.training_file().expect("built");
    assert_eq!(file.inputs.len(), 15);
    let path = write(dir.path(), "learned.json", &file);
    assert_eq!(TrainingFile::read(&path).expect("read back"), file);

    let mut loaded = GpCorrector::instantiate(&context).expect("instantiate");
    loaded.set_integer(LAGS, 4).expect("lags");
    loaded
        .set_string(TRAINING_PATH, "learned.json")
        .expect("path");
    loaded.exit_initialization().expect("initialize");
    // Same lag buffer, same inputs: the same predictions, to the rounding of a factor computed
    // whole rather than point by point.
    loaded.history = model.history.clone();
    loaded.inputs = model.inputs.clone();
    for vr in (ACC..ACC + 3).chain(LATENT_VAR..LATENT_VAR + 3) {
        let (a, b) = (
            model.get_real(vr).expect("get"),
            loaded.get_real(vr).expect("get"),
        );
        assert!(
            (a - b).abs() <= 1e-9 * a.abs().max(1e-6),
            "vr {vr}: {a} vs {b}"
        );
    }
}

/// A budget of 8 points: 20 samples learned leave the last 8, and the predictions are those of
/// a corrector that learned only those 8 (the oldest forgotten, not merely hidden).
#[test]
fn a_budget_keeps_the_most_recent_points_and_forgets_the_oldest() {
    use fmi2::{CoSimModel, InstantiateContext};
    use fmu_gp_corrector::GpCorrector;

    let dir = tempfile::tempdir().expect("temp dir");
    let context = InstantiateContext {
        instance_name: "in-process".into(),
        resource_dir: Some(dir.path().to_path_buf()),
    };
    let record = samples(41, 30);
    let run = |budget: i32, learn_from: usize| {
        let mut model = GpCorrector::instantiate(&context).expect("instantiate");
        model.set_integer(LAGS, 2).expect("lags");
        model.set_integer(REFIT_EVERY, 0).expect("refit_every");
        model.set_integer(BUDGET, budget).expect("budget");
        model.exit_initialization().expect("initialize");
        for (k, sample) in record.iter().enumerate().take(21) {
            for (i, v) in sample.iter().enumerate() {
                model.set_real(PHYSICS_ACC + i as u32, *v).expect("set");
            }
            for (i, v) in measured(sample).iter().enumerate() {
                model.set_real(MEASURED_ACC + i as u32, *v).expect("set");
            }
            model
                .set_boolean(LEARN, (learn_from..20).contains(&k))
                .expect("learn");
            model.do_step(k as f64 * H, H).expect("step");
        }
        model
    };
    let mut budgeted = run(8, 0);
    let mut recent = run(2048, 12);
    assert_eq!(budgeted.get_integer(TRAINING_POINTS).expect("points"), 8);
    assert_eq!(budgeted.get_integer(BUDGET).expect("budget"), 8);
    for vr in (ACC..ACC + 3).chain(LATENT_VAR..LATENT_VAR + 3) {
        let (a, b) = (
            budgeted.get_real(vr).expect("get"),
            recent.get_real(vr).expect("get"),
        );
        assert!(
            (a - b).abs() <= 1e-9 * a.abs().max(1e-9),
            "vr {vr}: {a} vs {b}"
        );
    }
}
