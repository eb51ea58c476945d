//! How a step's cost grows with the storey count: one 20 s record (1024 steps of 1/51.2 s) of
//! the linear model in-process (`ShearModel::advance` and the accelerations a host reads), for
//! N = 3, 10, 20 under a force at floor 1, with and without the forward sensitivities; and the
//! set-up of the step map (and of the derivative maps) that a change of parameters costs.
//!
//! `cargo bench -p fmu-shear --bench storeys`. Ids in group "storeys": `record/N`,
//! `record_sensitivities/N`, `step_map/N`, `sensitivity_maps/N`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use fmu_shear::effects::Effects;
use fmu_shear::linear::LinearStepMap;
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

criterion_group!(benches, bench);
criterion_main!(benches);
