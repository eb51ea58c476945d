//! `twin synth` for buildings other than the paper's rig, in-process: the record written reads
//! back through the project's record reader with the channels and units asked for, and equals
//! what synth holds in memory; the paper's scenario still gives the paper's columns. (Against an
//! independent integration by scipy: `tests/python/test_synth_buildings.py`.)

use std::path::Path;

use orchestrator::record::Measurement;
use orchestrator::synth::{
    csv_text, parse_effect_flag_for, synth_record, EffectSpec, NoiseLevel, Scenario,
};
use structure::channel::{parse_header_field, Channel, Quantity, Unit};
use structure::Excitation;

fn channels(text: &str) -> Vec<(Channel, Unit)> {
    text.split(',')
        .map(|f| parse_header_field(f).expect("a channel"))
        .collect()
}

/// Write the record, read it back with the project's reader.
fn round_trip(s: &Scenario, folder: &Path) -> (String, Measurement, Measurement) {
    let (record, _) = synth_record(s).expect("a record");
    let text = csv_text(&record.measurement);
    let path = folder.join("record.csv");
    std::fs::write(&path, &text).expect("written");
    let read = Measurement::read(&path).expect("reads back");
    (text, record.measurement, read)
}

fn assert_same_values(a: &Measurement, b: &Measurement) {
    assert_eq!(a.time, b.time);
    for (x, y) in a.channels().zip(b.channels()) {
        assert_eq!((x.channel, x.unit), (y.channel, y.unit));
        for (k, (p, q)) in x.values.iter().zip(&y.values).enumerate() {
            // The reader multiplies the written number by the unit's SI factor, as synth did.
            assert!(
                (p - q).abs() <= 1e-15 * p.abs().max(1e-300),
                "{} at {k}: {p} vs {q}",
                x.channel.name()
            );
        }
    }
}

#[test]
fn five_storeys_under_ground_motion_three_accelerometers_in_g_and_a_hidden_cubic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut s = Scenario::default();
    s.set_storeys(5);
    s.excitation = Excitation::Base;
    s.duration = 10.0;
    s.ground = orchestrator::synth::GroundMotion::for_duration(s.duration);
    s.channels = Some(channels("acc1 (g),acc3 (g),acc5 (g)"));
    s.effects
        .push(parse_effect_flag_for("cubic@3:stiffness=2e9", 5).expect("cubic@3"));
    assert!(matches!(s.effects[0], EffectSpec::Cubic { storey: 3, .. }));
    let (text, made, read) = round_trip(&s, dir.path());
    assert_eq!(
        text.lines().next(),
        Some("time,ground_acc,acc1 (g),acc3 (g),acc5 (g)")
    );
    assert_eq!(read.channel_names(), ["ground_acc", "acc1", "acc3", "acc5"]);
    assert!(read.responses.iter().all(|r| r.unit == Unit::G));
    assert_same_values(&made, &read);
    // Under ground motion an accelerometer reads the absolute acceleration: of the order of
    // the ground's (0.25 m/s² RMS stationary), not of the relative one alone.
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    let ground = rms(&read.excitation.values);
    let top = rms(&read.responses[2].values);
    println!("ground RMS {ground:.3} m/s², acc5 RMS {top:.3} m/s²");
    assert!(ground > 0.05 && top > 0.5 * ground, "{ground} {top}");
}

#[test]
fn two_storeys_shaken_at_floor_two_velocities_in_mm_per_s_at_1_khz() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut s = Scenario::default();
    s.set_storeys(2);
    s.excitation = Excitation::Force { floor: 2 };
    s.sample_rate = 1000.0;
    s.duration = 2.0;
    s.force.band_hz = Some(40.0);
    s.channels = Some(channels("vel1 (mm/s),vel2 (mm/s)"));
    s.noise.level = NoiseLevel::Fraction(vec![0.01, 0.02]);
    let (text, made, read) = round_trip(&s, dir.path());
    assert_eq!(
        text.lines().next(),
        Some("time,force,vel1 (mm/s),vel2 (mm/s)")
    );
    assert_eq!(read.channel_names(), ["force", "vel1", "vel2"]);
    assert!((read.dt - 1e-3).abs() < 1e-12, "{}", read.dt);
    assert_eq!(read.len(), 2000);
    assert!(
        read.responses
            .iter()
            .all(|r| r.unit == Unit::MilliMetrePerSecond
                && r.channel.quantity() == Quantity::Velocity)
    );
    assert_same_values(&made, &read);
}

#[test]
fn what_the_building_lacks_is_refused_naming_the_field() {
    let says = |s: &Scenario| s.validate("test").expect_err("refused").to_string();
    let mut s = Scenario::default();
    s.set_storeys(5);
    s.channels = Some(channels("acc6"));
    assert!(says(&s).contains("acc6"), "{}", says(&s));
    let mut s = Scenario::default();
    s.set_storeys(2);
    s.excitation = Excitation::Force { floor: 3 };
    assert!(says(&s).contains("force:3"), "{}", says(&s));
    assert!(parse_effect_flag_for("cubic@6", 5)
        .expect_err("no storey 6")
        .to_string()
        .contains("cubic is at storey"));
    let mut s = Scenario::default();
    s.set_storeys(4);
    s.effects.push(EffectSpec::QuadraticDamping {
        site: orchestrator::synth::DampingSite::Floor(5),
        coefficient: 400.0,
    });
    assert!(
        says(&s).contains("floor 5 is not one of 1..4"),
        "{}",
        says(&s)
    );
}

/// The largest |a − b| over the largest |b|, over every channel of two records' clean responses.
fn worst_relative(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let scale = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    worst / scale
}

#[test]
fn hysteresis_far_below_its_yield_is_a_storey_spring_on_any_building() {
    // With |z| ≪ z_y, ż = δ̇: the Bouc–Wen storey is a linear spring k_h, so a five-storey
    // building with it at storey 4 responds as the one whose k4 is k_h stiffer (the linear model
    // stepped exactly, the hysteretic one by RK4 on the fine grid), under ground motion and under
    // a force at floor 2 (away from the control force's floor 1).
    for excitation in [Excitation::Base, Excitation::Force { floor: 2 }] {
        let mut s = Scenario::default();
        s.set_storeys(5);
        s.excitation = excitation;
        s.duration = 5.0;
        s.ground = orchestrator::synth::GroundMotion::for_duration(s.duration);
        let mut linear = s.clone();
        linear.stiffness[3] += 1000.0;
        s.effects.push(
            parse_effect_flag_for("hysteresis@4:stiffness=1000,yield=1", 5).expect("hysteresis@4"),
        );
        let (record, truth) = synth_record(&s).expect("a record with hysteresis");
        let (reference, _) = synth_record(&linear).expect("the linear record");
        let d = worst_relative(&record.clean_acc, &reference.clean_acc);
        // Measured: 1.9e-7 (base, max |z| 1.4e-3 m: |z/z_y|² ≈ 2e-6) and 1.8e-9 (force at floor
        // 2, max |z| 1.5e-4 m); the bar 10× the larger. The wrong storey or floor differs by far
        // more than that.
        assert!(
            d < 2e-6,
            "{excitation:?}: the hysteretic storey differs by {d:e}"
        );
        let z = truth.effects[0].max_abs_z.expect("max |z|");
        // Measured 1.4e-3 and 1.5e-4 m: far below z_y = 1 m, as the comparison needs.
        assert!(z > 0.0 && z < 1e-2, "{excitation:?}: max |z| {z}");
    }
}

#[test]
fn the_paper_scenario_keeps_its_columns_and_its_json() {
    let s = Scenario::default();
    let json = s.to_json();
    for key in ["storeys", "excitation", "channels", "ground_motion"] {
        assert!(json.get(key).is_none(), "{key}");
    }
    assert_eq!(
        json["noise"]["fraction"],
        serde_json::json!([0.03, 0.03, 0.03])
    );
    let mut short = s.clone();
    short.duration = 1.0;
    let (record, truth) = synth_record(&short).expect("record");
    assert_eq!(
        csv_text(&record.measurement).lines().next(),
        Some("time,force,acc1,acc2,acc3")
    );
    assert_eq!(
        truth.record.columns,
        ["time", "force", "acc1", "acc2", "acc3"]
    );
    assert!(truth.structure.excitation.is_none());
}
