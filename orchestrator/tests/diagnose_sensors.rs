//! `twin diagnose` on the sensors a building has: records of velocity sensors (mm/s), of
//! displacement sensors (mm) and of a mix (an accelerometer on floor 1, a velocity sensor on
//! floor 2, a displacement sensor on floor 3), each with one hidden change the twin was not told
//! about, as in `tests/diagnose.rs` for accelerometers.
//!
//! The records are `twin synth`'s default structure (the dataset1 MAP) with sensor noise of 3 %
//! of each channel's noise-free RMS on the change-free record (so that a velocity or
//! displacement sensor is as noisy, relative to what it reads, as `tests/diagnose.rs`'
//! accelerometers), the same sd on every record. The twin is
//! calibrated on a change-free 20 s record (seed 1) of the same sensors; every test record is a
//! new 20 s record (seed 2, force ×3 between 12 and 17 s) with one hidden change. Each channel
//! is fitted and scored in its own quantity. The expected figures in the comments were measured
//! with the release build on this project's 2-core machine; the assertions leave the stated
//! margins.
//!
//! Needs the FMUs: `scripts/build-fmus.sh` (found through `TWIN_FMU_DIR`).

use orchestrator::calibrate::{calibrate, calibrated_twin, CalibrationSetup};
use orchestrator::data::Measurement;
use orchestrator::diagnose::{diagnose, Action, DiagnoseOptions, Diagnosis, Kind};
use orchestrator::synth::{
    synth_record, EffectSpec, NoiseLevel, Scenario, DEFAULT_MASS, DEFAULT_STIFFNESS,
};
use orchestrator::twin::Twin;
use structure::channel::{Channel, Quantity, Unit};

mod common;
use common::{fmu_dir, hidden_change_record};

/// Which sensors the building has.
#[derive(Clone, Copy)]
enum Sensors {
    Velocities,
    Displacements,
    /// acc1, vel2, disp3.
    Mixed,
}

impl Sensors {
    fn channels(self) -> Vec<(Channel, Unit)> {
        let sensor = |quantity, floor| Channel::Response { quantity, floor };
        match self {
            Sensors::Velocities => (1..=3)
                .map(|f| (sensor(Quantity::Velocity, f), Unit::MilliMetrePerSecond))
                .collect(),
            Sensors::Displacements => (1..=3)
                .map(|f| (sensor(Quantity::Displacement, f), Unit::MilliMetre))
                .collect(),
            Sensors::Mixed => vec![
                (sensor(Quantity::Acceleration, 1), Unit::MetrePerSecond2),
                (sensor(Quantity::Velocity, 2), Unit::MilliMetrePerSecond),
                (sensor(Quantity::Displacement, 3), Unit::MilliMetre),
            ],
        }
    }
}

fn scenario(sensors: Sensors, seed: u64) -> Scenario {
    let mut s = Scenario {
        seed,
        ..Scenario::default()
    };
    s.channels = Some(sensors.channels());
    s.noise.level = NoiseLevel::Sd(noise_sd(sensors));
    s
}

/// Each channel's sensor noise sd: 3 % of its noise-free RMS on the change-free record, the same
/// on every record (a sensor's noise floor does not grow with the response).
fn noise_sd(sensors: Sensors) -> Vec<f64> {
    let mut s = Scenario {
        seed: 1,
        ..Scenario::default()
    };
    s.channels = Some(sensors.channels());
    s.noise.level = NoiseLevel::Sd(vec![0.0]);
    let clean = synth_record(&s).expect("synth").0.measurement;
    clean
        .responses
        .iter()
        .map(|r| {
            0.03 * (r.values.iter().map(|v| v * v).sum::<f64>() / r.values.len() as f64).sqrt()
        })
        .collect()
}

/// The twin calibrated on the change-free record of `sensors`.
fn twin(sensors: Sensors) -> Twin {
    std::env::set_var("TWIN_FMU_DIR", fmu_dir());
    let (record, _) = synth_record(&scenario(sensors, 1)).expect("synth");
    let twin = Twin::default_twin().expect("default twin");
    let cal =
        calibrate(&twin, &record.measurement, &CalibrationSetup::default()).expect("calibration");
    calibrated_twin(&twin, &cal).expect("calibrated twin")
}

/// A new record (seed 2, stronger shaking in 12–17 s, as `tests/diagnose.rs`') of `sensors` on
/// the structure `change` makes.
fn record(sensors: Sensors, change: impl FnOnce(&mut Scenario)) -> Measurement {
    hidden_change_record(0.0, |s| {
        s.channels = Some(sensors.channels());
        s.noise.level = NoiseLevel::Sd(noise_sd(sensors));
        change(s)
    })
}

fn run(sensors: Sensors, change: impl FnOnce(&mut Scenario)) -> Diagnosis {
    let data = record(sensors, change);
    let d = diagnose(&twin(sensors), &data, &DiagnoseOptions::default()).expect("diagnosis");
    let names: Vec<String> = sensors.channels().iter().map(|(c, _)| c.name()).collect();
    assert_eq!(
        d.channels, names,
        "each channel diagnosed in its own quantity"
    );
    d
}

/// Every channel's NMSE after the verdict within 1.5× its noise level (measured: within 6 %).
fn assert_at_the_noise(d: &Diagnosis) {
    for (c, name) in d.channels.iter().enumerate() {
        assert!(
            d.nmse_after[c] <= 1.5 * d.noise_nmse[c],
            "{name}: NMSE after {} against a noise level of {}",
            d.nmse_after[c],
            d.noise_nmse[c]
        );
    }
}

/// [`common::assert_effect`] (the side of a contact: both) and every channel at its noise.
fn assert_effect(
    d: &Diagnosis,
    kind: Kind,
    location: &[usize],
    truth: &[(&str, f64)],
    tolerance: f64,
) {
    let side = (kind == Kind::Contact).then_some("both");
    common::assert_effect(d, kind, location, side, truth, tolerance);
    assert_at_the_noise(d);
}

/// [`common::assert_recalibrated`] and every channel at its noise.
fn assert_recalibrated(d: &Diagnosis, name: &str, relative: f64) {
    common::assert_recalibrated(d, name, relative);
    assert_at_the_noise(d);
}

/// No change: `none`, and no candidate passes.
fn assert_nothing(d: &Diagnosis) {
    assert_eq!(d.action, Action::None, "{}", d.reason);
    assert!(d.effect.is_none());
    assert_eq!(d.nmse_after, d.nmse_before);
    for c in &d.candidates {
        assert!(
            !c.passes,
            "{} passes on a record without change",
            c.name.label
        );
    }
    assert_at_the_noise(d);
}

fn cubic(storey: usize, stiffness: f64) -> impl FnOnce(&mut Scenario) {
    move |s| s.effects.push(EffectSpec::Cubic { storey, stiffness })
}

fn friction(floor: usize, force: f64) -> impl FnOnce(&mut Scenario) {
    move |s| {
        s.effects.push(EffectSpec::Friction {
            floor,
            force,
            velocity_scale: 1e-3,
        })
    }
}

fn contact_2_3() -> impl FnOnce(&mut Scenario) {
    |s| {
        s.effects.push(EffectSpec::Contact {
            lower: 2,
            gap: 5e-4,
            stiffness: 9000.0,
            side: 0,
        })
    }
}

fn cubic_in_storey_1_is_found(sensors: Sensors) {
    let d = run(sensors, cubic(1, 2e9));
    assert_effect(&d, Kind::Cubic, &[1], &[("stiffness", 2e9)], 0.05);
}

fn contact_between_floors_2_and_3_is_found(sensors: Sensors) {
    let d = run(sensors, contact_2_3());
    assert_effect(
        &d,
        Kind::Contact,
        &[2, 3],
        &[("gap", 5e-4), ("stiffness", 9000.0)],
        0.05,
    );
}

fn stiffness_loss_in_storey_2_is_a_recalibration(sensors: Sensors) {
    let d = run(sensors, |s| s.stiffness[1] = 0.85 * DEFAULT_STIFFNESS[1]);
    assert_recalibrated(&d, "k2", -0.15);
}

// Measured (NMSE per channel before → after, the noise level beside): the effect's parameters
// within 0.5 % (cubic), 0.4 % (contact), 0.8 % (friction) on velocities, 1.4 % on
// displacements, 4.4 % (friction's velocity scale) on the mix; every NMSE after within 6 % of
// the channel's noise level; the no-change records' NMSE within 6 % of the noise level. The
// assertions: 5 % (10 % for friction), after ≤ before / 4, as for accelerometers.

// vel: 19.4 / 24.9 / 28.0 % → 0.034 / 0.057 / 0.046 % (noise 0.036 / 0.054 / 0.045 %);
// k₃ 1.989e9 for 2e9.
#[test]
fn velocities_cubic_stiffness_of_storey_1() {
    cubic_in_storey_1_is_found(Sensors::Velocities);
}

// vel: 35.1 / 69.9 / 80.8 % → 0.064 / 0.132 / 0.120 %; force 0.0998 for 0.1, velocity scale
// 0.99e-3 for 1e-3.
#[test]
fn velocities_friction_on_floor_3() {
    let d = run(Sensors::Velocities, friction(3, 0.1));
    assert_effect(
        &d,
        Kind::Friction,
        &[3],
        &[("force", 0.1), ("velocity_scale", 1e-3)],
        0.1,
    );
}

// vel: 6.6 / 3.9 / 4.4 % → 0.030 / 0.060 / 0.045 %; gap 5.007e-4, stiffness 8966 for 9000.
#[test]
fn velocities_contact_between_floors_2_and_3() {
    contact_between_floors_2_and_3_is_found(Sensors::Velocities);
}

// vel: 27.3 / 79.6 / 45.7 % → 0.032 / 0.094 / 0.066 %; k2 moved −14.9 %.
#[test]
fn velocities_a_stiffness_loss_in_storey_2_is_a_recalibration() {
    stiffness_loss_in_storey_2_is_a_recalibration(Sensors::Velocities);
}

// vel: 0.034 / 0.061 / 0.048 % against a noise level of 0.036 / 0.058 / 0.047 %.
#[test]
fn velocities_without_change_need_nothing() {
    assert_nothing(&run(Sensors::Velocities, |_| {}));
}

// disp: 30.2 / 40.1 / 39.3 % → 0.059 / 0.084 / 0.069 %; k₃ 2.001e9 for 2e9.
#[test]
fn displacements_cubic_stiffness_of_storey_1() {
    cubic_in_storey_1_is_found(Sensors::Displacements);
}

// disp: 4.2 / 1.2 / 1.6 % → 0.053 / 0.085 / 0.070 %; gap 4.989e-4, stiffness 9129 for 9000.
#[test]
fn displacements_contact_between_floors_2_and_3() {
    contact_between_floors_2_and_3_is_found(Sensors::Displacements);
}

// disp: 72.2 / 115.7 / 114.3 % → 0.072 / 0.172 / 0.140 %; m3 moved +14.9 %.
#[test]
fn displacements_an_added_mass_on_floor_3_is_a_recalibration() {
    let d = run(Sensors::Displacements, |s| {
        s.mass[2] = 1.15 * DEFAULT_MASS[2]
    });
    assert_recalibrated(&d, "m3", 0.15);
}

// disp: 0.057 / 0.087 / 0.072 % against a noise level of 0.060 / 0.084 / 0.070 %.
#[test]
fn displacements_without_change_need_nothing() {
    assert_nothing(&run(Sensors::Displacements, |_| {}));
}

// acc1, vel2, disp3: 34.8 / 26.6 / 26.4 % → 0.054 / 0.105 / 0.121 %; force 0.0992 for 0.1,
// velocity scale 0.96e-3 for 1e-3.
#[test]
fn mixed_sensors_friction_on_floor_1() {
    let d = run(Sensors::Mixed, friction(1, 0.1));
    assert_effect(
        &d,
        Kind::Friction,
        &[1],
        &[("force", 0.1), ("velocity_scale", 1e-3)],
        0.1,
    );
    // The plot's residual rows in each channel's own unit.
    let svg = orchestrator::report::diagnose_plot::draw_diagnosis(&d).expect("plot");
    for unit in ["residual (m/s²)", "residual (m/s)", "residual (m)"] {
        assert_eq!(svg.matches(unit).count(), 1, "{unit} once in the plot");
    }
}

// acc1, vel2, disp3: 24.8 / 79.5 / 85.5 % → 0.028 / 0.095 / 0.134 %; k2 moved −15.1 %.
#[test]
fn mixed_sensors_a_stiffness_loss_in_storey_2_is_a_recalibration() {
    stiffness_loss_in_storey_2_is_a_recalibration(Sensors::Mixed);
}

// acc1, vel2, disp3: 0.030 / 0.061 / 0.072 % against a noise level of 0.031 / 0.058 / 0.070 %.
#[test]
fn mixed_sensors_without_change_need_nothing() {
    assert_nothing(&run(Sensors::Mixed, |_| {}));
}
