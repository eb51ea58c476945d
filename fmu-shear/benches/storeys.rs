//! How a step's cost grows with the storey count: one 20 s record (1024 steps of 1/51.2 s) of
//! the linear model in-process (`ShearModel::advance` and the accelerations a host reads), for
//! N = 3, 10, 20 under a force at floor 1, with and without the forward sensitivities; and the
//! set-up of the step map (and of the derivative maps) that a change of parameters costs.
//!
//! Group "contacts": the same record with one bumper (between the ground and floor 1, gap half
//! the storey's largest linear drift, 9000 N/m, both sides) under ground acceleration (0.5 m/s²
//! RMS), for N = 3, 5, 10, 20: `exact/N` the exact contact flows (`piecewise_any`, the maps
//! built once before timing), `exact_cold/N` the same with the maps built in the run (what a
//! fit pays per trial: its parameters change every run),
//! `error_controlled/N` Dormand–Prince to `ADAPTIVE_TOLERANCE` split at the kinks (the path
//! other structures took before), and `exact_rig/3` the paper's rig (force at floor 1) on its
//! fixed-size state (`piecewise_any` on `[f64; 6]`).
//!
//! Group "smooth": the same record with friction on floor 1 (0.1 N, 1 mm/s) or a cubic spring in
//! storey 1 (1e9 N/m³) at N = 4, 10, stepped as a diagnosis's fits step them (RK4, 8 fixed
//! sub-steps a sample, `Integrator::ExactContactsElseFixed`).
//!
//! `cargo bench -p fmu-shear --bench storeys`. Ids in group "storeys": `record/N`,
//! `record_sensitivities/N`, `step_map/N`, `sensitivity_maps/N`; in group "contacts":
//! `exact/N`, `exact_cold/N`, `error_controlled/N`, `exact_rig/3`; in group "smooth":
//! `friction_fixed8/N`, `cubic_fixed8/N`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fmu_shear::effects::{contact, Contact, Cubic, Effects, Friction, Law};
use fmu_shear::integrate::dopri5_with_events;
use fmu_shear::linear::LinearStepMap;
use fmu_shear::linear::StepInputs;
use fmu_shear::model::Integrator;
use fmu_shear::sensitivity::SensitivityMaps;
use fmu_shear::{ShearModel, ShearParameters};
use structure::{Excitation, Structure};

const STEP: f64 = 1.0 / 51.2;
const STEPS: usize = 1024;

fn params(storeys: usize) -> ShearParameters {
    ShearParameters::from_structure(&Structure::uniform(
        storeys,
        5.2,
        0.5,
        4021.0,
        Excitation::Force { floor: 1 },
    ))
}

fn force() -> Vec<f64> {
    (0..=STEPS)
        .map(|n| (0.37 * n as f64).sin() + 0.5 * (1.3 * n as f64).cos())
        .collect()
}

/// One record: per step the force and its slope, the step, then every floor's acceleration
/// (and, with sensitivities, every d_acc output), as a host reads them.
fn record(model: &mut ShearModel, force: &[f64]) -> f64 {
    let mut sum = 0.0;
    for n in 0..STEPS {
        model.force.value = force[n];
        model.force.slope = (force[n + 1] - force[n]) / STEP;
        model.advance(STEP);
        sum += model.absolute_acceleration().iter().sum::<f64>();
    }
    sum
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("storeys");
    group.measurement_time(Duration::from_secs(3));
    group.sample_size(20);
    let force = force();
    for storeys in [3usize, 10, 20] {
        let p = params(storeys);
        group.throughput(Throughput::Elements(STEPS as u64));
        group.bench_with_input(BenchmarkId::new("record", storeys), &p, |b, p| {
            let mut model = ShearModel::new(p.clone(), Effects::default());
            model.advance(STEP); // the step map, built once
            b.iter(|| black_box(record(&mut model, &force)))
        });
        group.bench_with_input(
            BenchmarkId::new("record_sensitivities", storeys),
            &p,
            |b, p| {
                let mut model = ShearModel::new(p.clone(), Effects::default());
                model.sensitivities.on = true;
                model.advance(STEP);
                b.iter(|| black_box(record(&mut model, &force)))
            },
        );
        group.throughput(Throughput::Elements(1));
        group.bench_with_input(BenchmarkId::new("step_map", storeys), &p, |b, p| {
            b.iter(|| black_box(LinearStepMap::new(p, STEP)))
        });
        group.bench_with_input(BenchmarkId::new("sensitivity_maps", storeys), &p, |b, p| {
            b.iter(|| black_box(SensitivityMaps::new(p, STEP)))
        });
    }
    group.finish();
}

/// A model of `storeys` uniform storeys under `excitation` with one bumper between the ground
/// and floor 1, its gap half the storey's largest drift of the linear model under `input`.
fn with_contact(storeys: usize, excitation: Excitation, input: &[f64]) -> ShearModel {
    let p =
        ShearParameters::from_structure(&Structure::uniform(storeys, 5.2, 0.5, 4021.0, excitation));
    let mut linear = ShearModel::new(p.clone(), Effects::new(storeys));
    let mut largest = 0.0f64;
    for n in 0..STEPS {
        linear.force.value = input[n];
        linear.force.slope = (input[n + 1] - input[n]) / STEP;
        linear.advance(STEP);
        largest = largest.max(linear.displacement[0].abs());
    }
    let mut model = ShearModel::new(p, Effects::new(storeys));
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

/// Back at rest at the start, the cached flows kept.
fn rest(model: &mut ShearModel) {
    model.displacement.iter_mut().for_each(|y| *y = 0.0);
    model.velocity.iter_mut().for_each(|v| *v = 0.0);
    model.force = Default::default();
}

/// One record stepped by the error-controlled path directly.
fn record_error_controlled(model: &mut ShearModel, input: &[f64], trial: &mut f64) -> f64 {
    let n = model.storeys();
    let mut sum = 0.0;
    let mut x = model.displacement.clone();
    x.extend_from_slice(&model.velocity);
    for k in 0..STEPS {
        let inputs = StepInputs {
            excitation: input[k],
            excitation_slope: (input[k + 1] - input[k]) / STEP,
            ..Default::default()
        };
        x = dopri5_with_events(model, &x, &inputs, STEP, trial);
        sum += x[n];
    }
    sum
}

fn contacts(c: &mut Criterion) {
    let mut group = c.benchmark_group("contacts");
    group.measurement_time(Duration::from_secs(3));
    group.sample_size(10);
    group.throughput(Throughput::Elements(STEPS as u64));
    let ground: Vec<f64> = force().iter().map(|f| 0.5 * f).collect();
    for storeys in [3usize, 5, 10, 20] {
        let model = with_contact(storeys, Excitation::Base, &ground);
        group.bench_with_input(BenchmarkId::new("exact", storeys), &model, |b, m| {
            let mut model = m.clone();
            record(&mut model, &ground); // the regions' flows, built once
            b.iter(|| {
                rest(&mut model);
                black_box(record(&mut model, &ground))
            })
        });
        group.bench_with_input(BenchmarkId::new("exact_cold", storeys), &model, |b, m| {
            b.iter(|| {
                let mut run = m.clone();
                black_box(record(&mut run, &ground))
            })
        });
        group.bench_with_input(
            BenchmarkId::new("error_controlled", storeys),
            &model,
            |b, m| {
                b.iter(|| {
                    let mut run = m.clone();
                    let mut trial = 0.0;
                    black_box(record_error_controlled(&mut run, &ground, &mut trial))
                })
            },
        );
    }
    let force = force();
    let rig = with_contact(3, Excitation::Force { floor: 1 }, &force);
    group.bench_with_input(BenchmarkId::new("exact_rig", 3), &rig, |b, m| {
        let mut model = m.clone();
        record(&mut model, &force);
        b.iter(|| {
            rest(&mut model);
            black_box(record(&mut model, &force))
        })
    });
    group.finish();
}

fn smooth(c: &mut Criterion) {
    let mut group = c.benchmark_group("smooth");
    group.measurement_time(Duration::from_secs(3));
    group.sample_size(10);
    group.throughput(Throughput::Elements(STEPS as u64));
    let force = force();
    let laws = [
        (
            "friction_fixed8",
            0,
            Law::Friction(Friction {
                force: 0.1,
                velocity_scale: 1e-3,
            }),
        ),
        ("cubic_fixed8", 0, Law::Cubic(Cubic { stiffness: 1e9 })),
    ];
    for storeys in [4usize, 10] {
        for (id, site, law) in &laws {
            let mut model = ShearModel::new(params(storeys), Effects::new(storeys));
            model.effects.switch_on(*site, law.clone());
            model.integrator = Integrator::ExactContactsElseFixed;
            model.params.substeps = 8;
            group.bench_with_input(BenchmarkId::new(*id, storeys), &model, |b, m| {
                let mut model = m.clone();
                b.iter(|| {
                    rest(&mut model);
                    black_box(record(&mut model, &force))
                })
            });
        }
    }
    group.finish();
}

/// The in-process pass of a linear twin's calibration and of compare's band
/// (`batch::accelerations_along`): every floor measured, the derivatives along all 3N
/// parameters, 4,096 samples.
fn batch(c: &mut Criterion) {
    const SAMPLES: usize = 4096;
    let mut group = c.benchmark_group("batch");
    group.measurement_time(Duration::from_secs(3));
    group.sample_size(10);
    group.throughput(Throughput::Elements(SAMPLES as u64));
    let excitation: Vec<f64> = (0..SAMPLES)
        .map(|n| (0.37 * n as f64).sin() + 0.5 * (1.3 * n as f64).cos())
        .collect();
    for storeys in [3usize, 10, 20] {
        let p = params(storeys);
        let floors: Vec<usize> = (0..storeys).collect();
        let directions = nalgebra::DMatrix::<f64>::identity(3 * storeys, 3 * storeys);
        let record = fmu_shear::batch::LinearRecord {
            dt: STEP,
            excitation: &excitation,
            floors: &floors,
        };
        group.bench_with_input(BenchmarkId::new("along", storeys), &p, |b, p| {
            b.iter(|| {
                let mut sum = 0.0;
                fmu_shear::batch::accelerations_along(p, &record, &directions, |_, v, d| {
                    sum += v[0] + d[0];
                });
                black_box(sum)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench, contacts, smooth, batch);
criterion_main!(benches);
