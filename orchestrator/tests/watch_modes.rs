//! `twin watch --track-modes`: the natural frequencies identified on a sliding window of the
//! stream (output-only) against the twin's band. A five-storey building under stationary
//! ground motion, accelerometers on floors 1, 3 and 5 reading in g: on an unchanged stream no
//! mode leaves its band; with storey 2 15 % softer from 150 s the first mode's tracked
//! frequency falls by what the softer structure's exact modes say, and a `frequency` alert
//! names that mode after the change and not before.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use structure::{Excitation, Structure};

mod common;
use common::{synth_five_storeys_in_g, twin_cmd};

const CHANGE_AT: f64 = 150.0;

fn run(cmd: &mut Command) {
    let out = cmd.output().expect("twin runs");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn building() -> Structure {
    Structure::uniform(5, 5.2, 3.0, 4021.0, Excitation::Base)
}

fn twin(dir: &Path) -> PathBuf {
    twin_excited(dir, "base")
}

/// The five-storey twin, excited at `excitation` (`base`, `force:F`).
fn twin_excited(dir: &Path, excitation: &str) -> PathBuf {
    let nominal = dir.join("nominal.json");
    std::fs::write(
        &nominal,
        r#"{"m": [5.2, 5.2, 5.2, 5.2, 5.2], "c": [3, 3, 3, 3, 3], "k": [4021, 4021, 4021, 4021, 4021]}"#,
    )
    .expect("nominal");
    let twin = dir.join("T.ssp");
    run(twin_cmd()
        .args([
            "init",
            "--storeys",
            "5",
            "--excitation",
            excitation,
            "--nominal",
        ])
        .arg(&nominal)
        .arg("--out")
        .arg(&twin));
    twin
}

/// 300 s of stationary ground motion, acc1/3/5 in g; with `change`, k2 × 0.85 from 150 s.
fn stream(dir: &Path, name: &str, seed: u64, change: bool) -> PathBuf {
    let scenario = dir.join("stationary.json");
    std::fs::write(&scenario, r#"{"ground_motion": {"strong_end": 100000}}"#).expect("scenario");
    let out = dir.join(format!("{name}.csv"));
    let mut cmd = synth_five_storeys_in_g(&scenario, "base", 300, seed, &out);
    if change {
        cmd.args(["--change", &format!("k2@{CHANGE_AT}:0.85")]);
    }
    run(&mut cmd);
    out
}

fn watch(twin: &Path, source: &Path, alerts: &Path) -> Vec<Value> {
    let plot = alerts.with_extension("svg");
    run(twin_cmd()
        .args(["watch", "--no-diagnosis", "--track-modes", "--twin"])
        .arg(twin)
        .arg("--source")
        .arg(source)
        .arg("--alerts")
        .arg(alerts)
        .arg("--modes-plot")
        .arg(&plot));
    // The frequencies against time: a panel per twin mode.
    let svg = std::fs::read_to_string(&plot).expect("the tracked frequencies' plot");
    assert!(
        svg.starts_with("<svg") && svg.contains("mode 1: twin") && svg.contains("mode 5: twin")
    );
    std::fs::read_to_string(alerts)
        .expect("alerts")
        .lines()
        .map(|l| serde_json::from_str(l).expect("an alert is JSON"))
        .collect()
}

fn of_kind<'a>(alerts: &'a [Value], kind: &str) -> Vec<&'a Value> {
    alerts.iter().filter(|a| a["kind"] == kind).collect()
}

#[test]
fn an_unchanged_building_keeps_its_frequencies_in_the_band() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = twin(d);
    let alerts = watch(
        &twin,
        &stream(d, "healthy", 3, false),
        &d.join("healthy.jsonl"),
    );
    assert!(
        of_kind(&alerts, "frequency").is_empty(),
        "a frequency alert on an unchanged building"
    );
    assert!(of_kind(&alerts, "modes_failed").is_empty());
    let modes = of_kind(&alerts, "modes");
    // A 60 s window every 10 s over 300 s, the first when the window is full; the tracker
    // starts at the second sample (the first gives no interval), so the last falls just short.
    assert_eq!(modes.len(), 24);
    let mut worst: f64 = 0.0;
    let mut found = vec![0usize; 5];
    for m in &modes {
        for (i, t) in m["modes"].as_array().expect("modes").iter().enumerate() {
            if let Some(s) = t["shift_percent"].as_f64() {
                worst = worst.max(s.abs());
                found[i] += 1;
            }
        }
    }
    println!("worst tracked shift {worst:.2} %, modes found per window {found:?}");
    // Measured: the worst tracked shift 0.76 % (the band's floor is 1.5 %); the first three
    // modes found in most windows (20, 19, 16 of 24, windows identified as `twin modal`
    // identifies a record; by the diagram's clusters alone 21, 19, 16), the upper two (little
    // excited from the ground) in few (0 and 1; before 1 and 1).
    assert!(worst < 1.0, "worst tracked shift {worst} %");
    assert!(
        found[0] >= 18 && found[2] >= 12,
        "modes found per window: {found:?}"
    );
}

#[test]
fn a_softer_storey_moves_the_first_frequency_out_of_the_band_after_the_change() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = twin(d);
    let alerts = watch(
        &twin,
        &stream(d, "changed", 4, true),
        &d.join("changed.jsonl"),
    );
    let frequency = of_kind(&alerts, "frequency");
    assert!(!frequency.is_empty(), "no frequency alert");
    for a in &frequency {
        assert!(
            a["time"].as_f64().expect("time") > CHANGE_AT,
            "an alert before the change: {a}"
        );
    }
    let first = frequency[0];
    assert_eq!(first["mode"], 1);
    // The window must hold mostly the changed structure, and two identifications must agree:
    // measured 50 s after the change.
    assert!(first["time"].as_f64().expect("time") < CHANGE_AT + 90.0);
    // The exact shift of the first mode: the softer structure's modes against the twin's.
    let mut softer = building();
    softer.stiffness[1] *= 0.85;
    let exact = |s: &Structure| {
        orchestrator::workflows::modal::twin::structure_modes(s).expect("modes")[0].frequency
    };
    let expected = 100.0 * (exact(&softer) - exact(&building())) / exact(&building());
    // Tracked once the window is wholly after the change: measured −2.60 to −3.08 % for an
    // exact −2.56 % (SSI-COV on a minute of a lightly damped 1.26 Hz mode is biased by up to
    // half a point here); within 0.8 points of %.
    let last = of_kind(&alerts, "modes");
    let late: Vec<f64> = last
        .iter()
        .filter(|m| m["time"].as_f64().unwrap_or(0.0) >= CHANGE_AT + 100.0)
        .filter_map(|m| m["modes"][0]["shift_percent"].as_f64())
        .collect();
    assert!(
        late.len() >= 4,
        "the first mode tracked late in {} windows",
        late.len()
    );
    println!("late shifts {late:.2?} %, exact {expected:.2} %");
    for s in late {
        assert!(
            (s - expected).abs() < 0.8,
            "tracked {s} %, exact {expected} %"
        );
    }
}

/// A force at floor 2 band-limited to 0.5–6.5 Hz, its top edge inside the building's band
/// (1.26, 3.68, 5.80, 7.45 and 8.50 Hz), 300 s at 51.2 Hz, acc1/3/5 in g and the force
/// measured: the windows are identified as `twin modal` identifies a record, and a pole at the
/// force's band edge (which output-only SSI-COV reads as a lightly damped mode) is set aside,
/// not tracked as a twin mode. Before (the diagram's clusters alone, unscreened): twin mode 4
/// (7.45 Hz) tracked at the edge's 6.27–6.37 Hz in 4 of the 24 windows; now none, and no
/// `frequency` alert on the unchanged building. The modes the force drives still tracked:
/// measured modes 1–3 in 20, 24 and 13 windows (bars 18, 18, 12).
#[test]
fn a_band_limited_forces_edge_is_not_tracked_as_a_mode() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = twin_excited(d, "force:2");
    let scenario = d.join("band.json");
    std::fs::write(&scenario, r#"{"force": {"low_hz": 0.5, "band_hz": 6.5}}"#).expect("scenario");
    let source = d.join("band.csv");
    run(&mut synth_five_storeys_in_g(
        &scenario, "force:2", 300, 5, &source,
    ));
    let alerts = watch(&twin, &source, &d.join("band.jsonl"));
    let modes = of_kind(&alerts, "modes");
    assert_eq!(modes.len(), 24);
    let edge = 6.5;
    let mut at_edge = 0;
    let mut found = vec![0usize; 5];
    for m in &modes {
        for (i, t) in m["modes"].as_array().expect("modes").iter().enumerate() {
            if let Some(f) = t["frequency"].as_f64() {
                found[i] += 1;
                if (f / edge - 1.0).abs() < 0.05 {
                    at_edge += 1;
                    println!("{}: twin mode {} tracked at {f:.4} Hz", m["time"], i + 1);
                }
            }
        }
    }
    println!("modes found per window {found:?}; tracked at the edge {at_edge}");
    assert_eq!(
        at_edge, 0,
        "a pole at the force's band edge tracked as a mode"
    );
    assert!(
        of_kind(&alerts, "frequency").is_empty(),
        "a frequency alert on an unchanged building"
    );
    assert!(
        found[0] >= 18 && found[1] >= 18 && found[2] >= 12,
        "{found:?}"
    );
}
