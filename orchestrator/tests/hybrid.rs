//! `twin hybrid`, through the CLI: the threshold curve's report contract and its agreement with
//! the independent linear computation, the test's runs with the contact law learned from the
//! interface (and the bias of learning it from the command), delay instability found and
//! stopped, delay compensation restoring the test, the learned law added to the twin and
//! explaining dataset3, and bad input refused. The figures in the comments were measured with
//! the release build on this project's machine; the assertions leave the stated margins.

use std::path::Path;

mod common;
use common::{twin, workspace};

fn ok(args: &[&str]) -> String {
    let out = twin(args);
    assert!(
        out.status.success(),
        "twin {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fails(args: &[&str]) -> String {
    let out = twin(args);
    assert!(!out.status.success(), "twin {args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("report")).expect("JSON")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// The contract a check reads, and each threshold against gap / peak y_r of the linear
/// assembly, for the paper's split (the default) and the other. Measured (default structure,
/// generated excitation, 512 Hz × 4 control steps): 0.3819 N with perfect control for both;
/// the paper's split 0.4654 N at a_err −0.1 (+21.9 %) where the other gives 0.5993 N, 0.3248 N
/// at +0.08 against 0.3426 N; bisection and independent equal to 1e-6.
#[test]
fn the_threshold_curve_has_its_contract_and_matches_the_linear_assembly() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let report = dir.path().join("t.json");
    let plot = dir.path().join("t.svg");
    ok(&[
        "hybrid",
        "threshold",
        "--a-err",
        "-0.08",
        "--a-err",
        "0",
        "--a-err",
        "0.08",
        "--report",
        s(&report),
        "--plot",
        s(&plot),
    ]);
    let r = json(&report);
    assert_eq!(r["split"], "specimen-floors-2-3");
    let other = dir.path().join("other.json");
    let out = ok(&[
        "hybrid",
        "threshold",
        "--split",
        "specimen-floor-3",
        "--a-err",
        "-0.08",
        "--a-err",
        "0",
        "--report",
        s(&other),
    ]);
    assert!(out.contains("split: specimen floor 3"), "{out}");
    let o = json(&other);
    assert_eq!(o["split"], "specimen-floor-3");
    let at = |r: &serde_json::Value, i: usize| {
        r["thresholds"][i]["threshold_peak_force"]
            .as_f64()
            .expect("threshold")
    };
    // With perfect control both cuts are the whole structure; under an error they part.
    assert!((at(&r, 1) - at(&o, 1)).abs() <= 1e-9 * at(&o, 1));
    assert!(
        (at(&r, 0) / at(&o, 0) - 1.0).abs() > 0.05,
        "{} {}",
        at(&r, 0),
        at(&o, 0)
    );
    for name in ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"] {
        assert!(
            r["parameters"][name].as_f64().is_some_and(|x| x > 0.0),
            "{name}"
        );
    }
    assert_eq!(r["gap"].as_f64(), Some(5e-4));
    assert_eq!(r["contact_stiffness"].as_f64(), Some(9000.0));
    let points = r["thresholds"].as_array().expect("thresholds");
    assert_eq!(points.len(), 3);
    for p in points {
        let t = p["threshold_peak_force"].as_f64().expect("threshold");
        let independent = p["independent"].as_f64().expect("independent");
        assert!(
            t > 0.0 && (t - independent).abs() <= 2e-6 * independent,
            "{p}"
        );
    }
    assert!(std::fs::read_to_string(&plot)
        .expect("plot")
        .contains("<svg"));
}

/// At 5 N peak the bumper closes tens of times; from the noisy measured interface (the force
/// with floor 2's inertia, and floor 2's accelerometer) the law is learned within 0.1 %
/// (measured: gap −0.02 % and +0.02 %, stiffness +0.003 % and +0.01 %, floor 2's mass 5.2840
/// against 5.2838 kg), whatever the amplitude error; learned from the commanded displacement, a
/// +5 % error biases it (gap −3.8 %, stiffness −7.1 %). Added to the twin calibrated on dataset1, the learned contact explains
/// dataset3 (worst-floor NMSE 68.6 % → 0.49 %).
#[test]
fn the_contact_law_is_learned_from_the_test_and_explains_dataset3() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let cal = dir.path().join("cal.ssp");
    let report = dir.path().join("r.json");
    let plot = dir.path().join("r.svg");
    let added = dir.path().join("added.ssp");
    let cmp = dir.path().join("cmp.json");
    let ds1 = workspace().join("data/dataset1.csv");
    let ds3 = workspace().join("data/dataset3.csv");
    ok(&["calibrate", "--data", s(&ds1), "--out", s(&cal)]);
    ok(&[
        "hybrid",
        "run",
        "--twin",
        s(&cal),
        "--peak",
        "5",
        "--a-err",
        "0",
        "--a-err",
        "0.05",
        "--report",
        s(&report),
        "--plot",
        s(&plot),
    ]);
    let r = json(&report);
    let runs = r["runs"].as_array().expect("runs");
    assert_eq!(runs.len(), 2);
    for run in runs {
        assert!(run["contacts"].as_u64().expect("contacts") >= 10, "{run}");
        let law = &run["identified"];
        let gap = law["gap"].as_f64().expect("gap");
        let k = law["contact_stiffness"].as_f64().expect("stiffness");
        assert!(
            (gap / 5e-4 - 1.0).abs() < 1e-3 && (k / 9000.0 - 1.0).abs() < 1e-3,
            "{law}"
        );
    }
    assert_eq!(r["split"], "specimen-floors-2-3");
    let m2 = r["parameters"]["m2"].as_f64().expect("m2");
    for run in runs {
        let mass = run["identified"]["specimen_mass"].as_f64().expect("mass");
        assert!((mass / m2 - 1.0).abs() < 1e-3, "{mass} against {m2}");
    }
    let biased = runs[1]["identified_from_command"]["gap"]
        .as_f64()
        .expect("gap");
    assert!(biased / 5e-4 - 1.0 < -0.01, "from the command: {biased}");
    ok(&[
        "add-physics",
        "--twin",
        s(&cal),
        "--hybrid",
        s(&report),
        "--out",
        s(&added),
    ]);
    ok(&[
        "compare",
        "--twin",
        s(&added),
        "--data",
        s(&ds3),
        "--report",
        s(&cmp),
    ]);
    let nmse: Vec<f64> = json(&cmp)["nmse"]
        .as_array()
        .expect("nmse")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    assert!(nmse.iter().all(|&x| x < 1.0), "{nmse:?}");
}

/// With floor 2 numerical (`--split specimen-floor-3`), five control steps of delay (4.9 ms)
/// make the test unstable: found from the interface energy and stopped with the reason
/// (measured: at 2.9 s, 10× the excitation's energy); third-order compensation restores it (53
/// contacts, as with perfect control). With the paper's split a delay is refused with the
/// reason (a neutral loop: measured diverging within 5.1 s at one control step of delay).
#[test]
fn a_delay_makes_the_test_unstable_and_compensation_restores_it() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let report = dir.path().join("r.json");
    let delay = "0.0048828125";
    let e = fails(&["hybrid", "run", "--delay", delay, "--report", s(&report)]);
    assert!(
        e.contains("neutral delay loop") && e.contains("--split specimen-floor-3"),
        "{e}"
    );
    assert!(!report.exists());
    let out = ok(&[
        "hybrid",
        "run",
        "--split",
        "specimen-floor-3",
        "--a-err",
        "0",
        "--delay",
        delay,
        "--report",
        s(&report),
    ]);
    assert!(out.contains("unstable"), "{out}");
    let r = json(&report);
    assert!(r["runs"][0]["stopped"]
        .as_str()
        .is_some_and(|x| x.contains("negative damping")));
    ok(&[
        "hybrid",
        "run",
        "--split",
        "specimen-floor-3",
        "--a-err",
        "0",
        "--delay",
        delay,
        "--compensate",
        "3",
        "--report",
        s(&report),
    ]);
    let r = json(&report);
    assert!(r["runs"][0]["stopped"].is_null(), "{}", r["runs"][0]);
    assert!(r["runs"][0]["contacts"].as_u64().expect("contacts") >= 10);
}

/// With an actuator without dynamics the default couples the assembly as one ODE (with perfect
/// control the whole structure to rounding: the unit test `monolithic`); the stepped loop at
/// 4 control steps a 512 Hz sample agrees with it at a_err = 0.05 — with floor 2 numerical to
/// O(h²) (measured: 0.35207 against 0.35197 N), with the paper's split to O(h) (0.37060 against
/// 0.34356 N, +7.9 %: the accelerations the interface estimates from displacements lag by two
/// control steps, which acts as a damping `2h a_err m₂ ω²`, large against this default
/// frame's 0.01 N·s/m; −1.0 % at a_err = −0.1 on the twin calibrated on dataset1).
#[test]
fn the_stepped_loop_agrees_with_the_one_ode_assembly() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let threshold = |split: &str, coupling: &str| {
        let report = dir.path().join(format!("{split}-{coupling}.json"));
        ok(&[
            "hybrid",
            "threshold",
            "--a-err",
            "0.05",
            "--split",
            split,
            "--coupling",
            coupling,
            "--report",
            s(&report),
        ]);
        let r = json(&report);
        assert_eq!(r["coupling"], coupling);
        assert_eq!(r["split"], split);
        r["thresholds"][0]["threshold_peak_force"]
            .as_f64()
            .expect("threshold")
    };
    let split = "specimen-floor-3";
    let (one, stepped) = (threshold(split, "monolithic"), threshold(split, "stepped"));
    assert!(
        (one - stepped).abs() < 1e-3 * one,
        "{one} against {stepped}"
    );
    let split = "specimen-floors-2-3";
    let (one, stepped) = (threshold(split, "monolithic"), threshold(split, "stepped"));
    assert!((one - stepped).abs() < 0.1 * one, "{one} against {stepped}");
    let e = fails(&[
        "hybrid",
        "run",
        "--coupling",
        "monolithic",
        "--delay",
        "0.0048828125",
        "--report",
        s(&dir.path().join("x.json")),
    ]);
    assert!(e.contains("needs the stepped coupling"), "{e}");
}

#[test]
fn bad_input_is_refused_with_the_reason_and_writes_nothing() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let report = dir.path().join("r.json");
    let e = fails(&[
        "hybrid",
        "threshold",
        "--gap",
        "-0.001",
        "--report",
        s(&report),
    ]);
    assert!(e.contains("gap must be positive"), "{e}");
    let e = fails(&["hybrid", "run", "--delay", "0.0003", "--report", s(&report)]);
    assert!(
        e.contains("not a whole number") && e.contains("0.0003"),
        "{e}"
    );
    let e = fails(&[
        "hybrid",
        "threshold",
        "--a-err",
        "-1.5",
        "--report",
        s(&report),
    ]);
    assert!(e.contains("--a-err"), "{e}");
    let csv = dir.path().join("e.csv");
    std::fs::write(&csv, "time,force\n0,0.1\n0.01,NaN\n0.02,0.3\n").expect("write");
    let e = fails(&[
        "hybrid",
        "threshold",
        "--excitation",
        s(&csv),
        "--report",
        s(&report),
    ]);
    assert!(e.contains("e.csv") && e.contains("line 3"), "{e}");
    assert!(!report.exists());
}
