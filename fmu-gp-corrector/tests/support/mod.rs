//! What the corrector's behaviour tests share: an instance with a resources folder of the test's
//! own, seeded data, training files and the in-process reference GPs.

// Calls FMUs through their C functions, as a host does.
#![allow(unsafe_code)]
#![allow(dead_code)]

use std::path::Path;

use fmi2::abi::*;
use fmu_gp_corrector::{lagged_inputs, FloorHyperparameters, Sample, TargetForm, TrainingFile};
use numerics::gp::{GaussianProcess, Hyperparameters, Inputs, PointPrediction};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::common::{cstring, Host, Slave};
use crate::fmi2Instantiate;
use fmu_gp_corrector::variables::*;

/// The examples' sampling interval.
pub const H: f64 = 1.0 / 51.2;

pub fn guid() -> &'static str {
    &info().guid
}

/// `fmi2Instantiate` with `resources` as the resource location; null on failure.
pub fn instantiate_in(host: &Host, resources: &Path) -> fmi2Component {
    let name = cstring("corrector");
    let guid = cstring(guid());
    let uri = cstring(&format!("file://{}", resources.display()));
    let callbacks = host.callbacks();
    // SAFETY: every pointer is valid for the call.
    unsafe {
        fmi2Instantiate(
            name.as_ptr(),
            fmi2CoSimulation,
            guid.as_ptr(),
            uri.as_ptr(),
            &callbacks,
            fmi2False,
            fmi2False,
        )
    }
}

/// An instance (state Instantiated) whose resources folder is `resources`.
pub fn slave_in(resources: &Path) -> Slave {
    let host = Host::new();
    let c = instantiate_in(&host, resources);
    assert!(
        !c.is_null(),
        "fmi2Instantiate failed: {:#?}",
        host.records()
    );
    Slave { host, c }
}

/// Set up at t = 0 and enter initialization mode.
pub fn enter(s: &Slave) {
    assert_eq!(s.setup(0.0, None), fmi2OK, "{:#?}", s.host.records());
    assert_eq!(s.enter(), fmi2OK, "{:#?}", s.host.records());
}

pub fn exit(s: &Slave) {
    assert_eq!(s.exit(), fmi2OK, "{:#?}", s.host.records());
}

pub fn set_integer(s: &Slave, vr: u32, value: i32) {
    assert_eq!(
        s.set_integers(&[vr], &[value]),
        fmi2OK,
        "{:#?}",
        s.host.records()
    );
}

pub fn set_string(s: &Slave, vr: u32, value: &str) {
    assert_eq!(
        s.set_strings(&[vr], &[value]),
        fmi2OK,
        "{:#?}",
        s.host.records()
    );
}

/// The current physics sample and measured accelerations as inputs, and the learn flag.
pub fn set_inputs(s: &Slave, sample: &Sample, measured: &[f64; 3], learn: bool) {
    let vrs = [
        PHYSICS_ACC,
        PHYSICS_ACC + 1,
        PHYSICS_ACC + 2,
        FORCE,
        MEASURED_ACC,
        MEASURED_ACC + 1,
        MEASURED_ACC + 2,
    ];
    let values = [
        sample[0],
        sample[1],
        sample[2],
        sample[3],
        measured[0],
        measured[1],
        measured[2],
    ];
    assert_eq!(
        s.set_reals(&vrs, &values),
        fmi2OK,
        "{:#?}",
        s.host.records()
    );
    assert_eq!(
        s.set_booleans(&[LEARN], &[fmi2Boolean::from(learn)]),
        fmi2OK
    );
}

/// The outputs of the three floors: (acc, latent_var, sd).
pub fn outputs(s: &Slave) -> [[f64; 3]; 3] {
    let vrs: Vec<u32> = (0..3)
        .flat_map(|i| [ACC + i, LATENT_VAR + i, SD + i])
        .collect();
    let (status, values) = s.get_reals(&vrs);
    assert_eq!(status, fmi2OK, "{:#?}", s.host.records());
    [0, 1, 2].map(|f| [values[3 * f], values[3 * f + 1], values[3 * f + 2]])
}

pub fn training_points(s: &Slave) -> i32 {
    let (status, values) = s.get_integers(&[TRAINING_POINTS]);
    assert_eq!(status, fmi2OK, "{:#?}", s.host.records());
    values[0]
}

/// A record of physics samples at about the example data's scale (accelerations of 0.1 m/s²,
/// forces of 0.25 N), smooth enough that neighbouring lag vectors are close.
pub fn samples(seed: u64, n: usize) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let phase: [f64; 4] = std::array::from_fn(|_| rng.gen_range(0.0..6.0));
    (0..n)
        .map(|k| {
            let t = k as f64 * H;
            let mut s = [0.0; 4];
            for (c, v) in s.iter_mut().enumerate() {
                let w = 2.0 * std::f64::consts::PI * (3.0 + c as f64);
                let noise: f64 = rng.gen_range(-0.01..0.01);
                *v = (if c == 3 { 0.25 } else { 0.1 }) * (w * t + phase[c]).sin() + noise;
            }
            s
        })
        .collect()
}

/// "Measured" accelerations: the physics ones plus a smooth discrepancy per floor.
pub fn measured(sample: &Sample) -> [f64; 3] {
    [0, 1, 2].map(|f| {
        sample[f] + 0.02 * (3.0 * sample[3] + (f as f64 + 1.0) * sample[f]).sin() + 0.005 * f as f64
    })
}

/// A training file on `n` samples of `samples(seed)`, with hyperparameters when `with_hyper`.
pub fn training_file(
    seed: u64,
    n: usize,
    lags: usize,
    target: TargetForm,
    with_hyper: bool,
) -> TrainingFile {
    let record = samples(seed, n);
    let inputs = lagged_inputs(&record, lags);
    let targets = record
        .iter()
        .map(|s| {
            let m = measured(s);
            [0, 1, 2].map(|f| target.target(m[f], s[f]))
        })
        .collect();
    let dimension = inputs[0].len();
    let hyperparameters = with_hyper.then(|| {
        (0..3)
            .map(|f| FloorHyperparameters {
                length_scales: (0..dimension)
                    .map(|i| 0.3 + 0.05 * ((i + f) % 7) as f64)
                    .collect(),
                signal_variance: 4e-4 * (f as f64 + 1.0),
                noise_variance: 1e-6,
            })
            .collect()
    });
    TrainingFile {
        lags,
        target,
        inputs,
        targets,
        hyperparameters,
    }
}

/// The in-process GPs of a training file that has hyperparameters.
pub fn reference_gps(file: &TrainingFile) -> Vec<GaussianProcess> {
    let inputs = Inputs::from_rows(&file.inputs).expect("inputs");
    let sets = file.hyperparameters.as_ref().expect("hyperparameters");
    (0..3)
        .map(|f| {
            let h = &sets[f];
            let hyper = Hyperparameters::new(&h.length_scales, h.signal_variance, h.noise_variance)
                .expect("hyperparameters");
            let targets = file.targets.iter().map(|y| y[f]).collect();
            GaussianProcess::new(inputs.clone(), targets, hyper).expect("GP")
        })
        .collect()
}

/// (corrected acc, latent variance, sd) as the FMU computes them from a prediction.
pub fn expected_outputs(target: TargetForm, physics: f64, p: &PointPrediction) -> [f64; 3] {
    [
        target.corrected(physics, p.mean),
        p.latent_variance,
        p.predictive_variance.sqrt(),
    ]
}

pub fn write(dir: &Path, name: &str, file: &TrainingFile) -> std::path::PathBuf {
    let path = dir.join(name);
    file.write(&path).expect("write the training file");
    path
}
