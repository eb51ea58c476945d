//! The reference paper's sections 2–3 on the bundled examples, through the CLI: calibrated on
//! dataset1, the twin predicts datasets 1 and 2 well and fails on dataset 3; recalibrated on
//! dataset 3, its parameters move away (bias) and it gets worse on datasets 1 and 2.
//!
//! Measured (64 sub-steps, 12 starts, transient 2 s), worst-floor NMSE %:
//!   calibrated on dataset1: dataset1 0.097, dataset2 0.136, dataset3 68.6
//!   calibrated on dataset3: dataset3 17.7, dataset1 49.9, dataset2 36.9
//! and, between the two calibrations, k1 3850 → 3549 N/m, k2 4100 → 3751 N/m (posterior sd
//! 4 and 56 N/m), c2 3.65 → 0.009 N s/m. Thresholds below leave a margin of 3× or more.

use std::path::Path;

use serde_json::Value;

mod common;
use common::{numbers, twin_cmd, workspace, worst};

fn calibrate(data: &str, validate: &[&str], dir: &Path) -> Value {
    let report = dir.join(format!("{data}.json"));
    let mut cmd = twin_cmd();
    cmd.arg("calibrate")
        .arg("--data")
        .arg(workspace().join(format!("data/{data}.csv")))
        .arg("--out")
        .arg(dir.join(format!("{data}.ssp")))
        .arg("--report")
        .arg(&report);
    if !validate.is_empty() {
        cmd.arg("--validate");
        for v in validate {
            cmd.arg(workspace().join(format!("data/{v}.csv")));
        }
    }
    let out = cmd.output().expect("twin runs");
    assert!(
        out.status.success(),
        "twin calibrate failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        dir.join(format!("{data}.ssp")).is_file(),
        "the calibrated twin is written"
    );
    serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON")
}

fn validation(report: &Value, data: &str) -> f64 {
    let entry = report["validation"]
        .as_array()
        .expect("validation list")
        .iter()
        .find(|v| {
            v["data"]
                .as_str()
                .is_some_and(|p| p.ends_with(&format!("{data}.csv")))
        })
        .unwrap_or_else(|| panic!("no validation on {data}"));
    worst(&numbers(&entry["nmse"]))
}

fn parameter(report: &Value, name: &str) -> (f64, f64) {
    let p = report["parameters"]
        .as_array()
        .expect("parameters")
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no parameter {name}"));
    (
        p["value"].as_f64().expect("value"),
        p["sd"].as_f64().expect("sd"),
    )
}

#[test]
fn calibration_on_dataset1_generalises_to_dataset2_and_fails_on_dataset3_and_recalibrating_on_dataset3_biases(
) {
    let dir = tempfile::tempdir().expect("temp dir");
    let d1 = calibrate("dataset1", &["dataset2", "dataset3"], dir.path());
    let on1 = worst(&numbers(&d1["nmse"]));
    let on2 = validation(&d1, "dataset2");
    let on3 = validation(&d1, "dataset3");
    println!("calibrated on dataset1: worst NMSE % on 1: {on1:.3}, 2: {on2:.3}, 3: {on3:.1}");
    assert!(on1 < 0.5, "fits its own record: {on1}");
    assert!(
        on2 < 1.0,
        "predicts dataset2 (worst floor below 1 %): {on2}"
    );
    assert!(
        on3 > 20.0,
        "fails on dataset3 (worst floor above 20 %): {on3}"
    );

    // Mass and stiffness trade off: the user must see it in the correlation matrix.
    let names: Vec<&str> = d1["parameters"]
        .as_array()
        .expect("list")
        .iter()
        .map(|p| p["name"].as_str().expect("name"))
        .collect();
    let corr = &d1["correlation"];
    let (m2, k2) = (
        names.iter().position(|n| *n == "m2").expect("m2"),
        names.iter().position(|n| *n == "k2").expect("k2"),
    );
    let r = corr[m2][k2].as_f64().expect("number");
    assert!(
        r > 0.8,
        "m2 and k2 are strongly correlated (measured 0.99): {r}"
    );

    let d3 = calibrate("dataset3", &["dataset1", "dataset2"], dir.path());
    let back1 = validation(&d3, "dataset1");
    let back2 = validation(&d3, "dataset2");
    println!(
        "calibrated on dataset3: worst NMSE % on 3: {:.2}, 1: {back1:.2}, 2: {back2:.2}",
        worst(&numbers(&d3["nmse"]))
    );
    assert!(
        back1 > 10.0 * on1 && back1 > 5.0,
        "recalibration on dataset3 generalises worse to dataset1: {back1} vs {on1}"
    );
    assert!(
        back2 > 10.0 * on2 && back2 > 5.0,
        "…and to dataset2: {back2} vs {on2}"
    );

    // The parameters moved well beyond their uncertainty: count those more than 3 combined sd away.
    let moved: Vec<String> = ["k1", "k2", "k3", "m1", "m2", "m3"]
        .iter()
        .filter_map(|name| {
            let (a, sa) = parameter(&d1, name);
            let (b, sb) = parameter(&d3, name);
            let z = (a - b).abs() / (sa * sa + sb * sb).sqrt();
            (z > 3.0).then(|| format!("{name} {a:.1} → {b:.1} ({z:.0} sd)"))
        })
        .collect();
    println!("moved: {moved:?}");
    assert!(
        moved.len() >= 3,
        "recalibrating on dataset3 biases the parameters: {moved:?}"
    );
}

#[test]
fn the_input_twin_is_kept() {
    let dir = tempfile::tempdir().expect("temp dir");
    let twin = dir.path().join("t.ssp");
    let init = twin_cmd()
        .args(["init", "--out"])
        .arg(&twin)
        .output()
        .expect("runs");
    assert!(init.status.success());
    let before = std::fs::read(&twin).expect("twin");
    let out = twin_cmd()
        .arg("calibrate")
        .arg("--data")
        .arg(workspace().join("data/dataset1.csv"))
        .arg("--twin")
        .arg(&twin)
        .arg("--out")
        .arg(&twin)
        .output()
        .expect("runs");
    assert!(
        !out.status.success(),
        "overwriting the input twin is refused"
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("old twin is kept"));
    assert_eq!(std::fs::read(&twin).expect("twin"), before);
}
