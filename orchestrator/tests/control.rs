//! `twin control` through the built binary: the report contract and the design's checks, the
//! attenuation growing with q, the contacts falling with it on a twin with the contact, the
//! retune and the gain schedule, controlled synthetic records predicted in the closed loop, and
//! bad input refused clearly (an unstable loop reported, never written as numbers).
//!
//! Measured figures (printed with `--nocapture`) set the bounds: see each test.

use std::path::{Path, PathBuf};
use std::process::Output;

use nalgebra::{DMatrix, Matrix6};
use orchestrator::twin::{ParameterValue, Twin, PHYSICS};
use serde_json::Value;

mod common;
use common::{fmu_dir, twin, workspace};

fn ok(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: exit {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn failed(out: &Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 paths")
}

fn data(n: u32) -> PathBuf {
    workspace().join(format!("data/dataset{n}.csv"))
}

fn read(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("report written")).expect("JSON")
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

/// The default twin (the shear FMU's defaults: the paper's prior means), with `set` applied to
/// its physics, written to `path`.
fn write_twin(path: &Path, set: &[(&str, ParameterValue)]) {
    std::env::set_var("TWIN_FMU_DIR", fmu_dir());
    let mut t = Twin::default_twin().expect("the default twin");
    let physics = t.component_mut(PHYSICS).expect("physics");
    for (name, value) in set {
        physics.parameters.insert((*name).to_owned(), *value);
    }
    t.write(path).expect("twin written");
}

/// The contact of the example data's diagnosis, on the default structure: floors 2–3 close on
/// negative drift at 0.5 mm.
fn contact_twin(path: &Path) {
    write_twin(
        path,
        &[
            ("contact23_enabled", ParameterValue::Boolean(true)),
            ("contact23_gap", ParameterValue::Real(5e-4)),
            ("contact23_stiffness", ParameterValue::Real(9000.0)),
            ("contact23_side", ParameterValue::Integer(-1)),
        ],
    );
}

/// The report has the contract's fields; A and B are eqs 17–19 rebuilt here from the reported
/// parameters; Q = q·diag(0, I); the closed-loop poles are those of A − B·gain, all stable; the
/// attenuation is positive at every resonance and grows with q; the estimators cost little
/// against the exact state. (Gains against scipy and python-control: tests/python.)
#[test]
fn report_contract_and_design() {
    let dir = tempfile::tempdir().expect("temp dir");
    let report = dir.path().join("control.json");
    let plot = dir.path().join("control.svg");
    let tw = dir.path().join("default.ssp");
    write_twin(&tw, &[]);
    let out = twin(&[
        "control",
        "--twin",
        s(&tw),
        "--data",
        s(&data(2)),
        "--q",
        "1e3",
        "--q",
        "5e3",
        "--r",
        "0.1",
        "--estimator-costs",
        "--report",
        s(&report),
        "--plot",
        s(&plot),
    ]);
    let stdout = ok(&out, "twin control");
    println!("{stdout}");
    let r = read(&report);
    for key in [
        "parameters",
        "A",
        "B",
        "R",
        "state_scale",
        "designs",
        "passive",
    ] {
        assert!(r.get(key).is_some(), "report lacks {key}");
    }
    assert_eq!(f(&r["R"]), 0.1);
    assert_eq!(f(&r["state_scale"]), 1.0);
    let p = |name: &str| f(&r["parameters"][name]);
    let (m, c, k) = (
        [p("m1"), p("m2"), p("m3")],
        [p("c1"), p("c2"), p("c3")],
        [p("k1"), p("k2"), p("k3")],
    );
    let tri = |x: [f64; 3]| {
        DMatrix::from_row_slice(
            3,
            3,
            &[
                x[0] + x[1],
                -x[1],
                0.0,
                -x[1],
                x[1] + x[2],
                -x[2],
                0.0,
                -x[2],
                x[2],
            ],
        )
    };
    let minv = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(m.map(|v| 1.0 / v).to_vec()));
    let (mk, mc) = (-&minv * tri(k), -&minv * tri(c));
    let mut a = Matrix6::<f64>::zeros();
    for i in 0..3 {
        a[(i, 3 + i)] = 1.0;
        for j in 0..3 {
            a[(3 + i, j)] = mk[(i, j)];
            a[(3 + i, 3 + j)] = mc[(i, j)];
        }
    }
    for i in 0..6 {
        for j in 0..6 {
            let reported = f(&r["A"][i][j]);
            assert!(
                (reported - a[(i, j)]).abs() <= 1e-12 * a[(i, j)].abs().max(1.0),
                "A[{i}][{j}]"
            );
        }
        let b = if i == 3 { 1.0 / m[0] } else { 0.0 };
        assert!((f(&r["B"][i]) - b).abs() <= 1e-15, "B[{i}]");
    }
    let designs = r["designs"].as_array().expect("designs");
    assert_eq!(designs.len(), 2);
    let mut attenuation = Vec::new();
    for d in designs {
        let q = f(&d["q"]);
        for i in 0..6 {
            for j in 0..6 {
                let expected = if i == j && i >= 3 { q } else { 0.0 };
                assert_eq!(f(&d["Q"][i][j]), expected);
            }
        }
        assert!(f(&d["riccati_residual"]) <= 1e-10);
        let gain: Vec<f64> = d["gain"].as_array().expect("gain").iter().map(f).collect();
        let mut closed = a;
        for j in 0..6 {
            closed[(3, j)] -= gain[j] / m[0];
        }
        let mut poles: Vec<(f64, f64)> = closed
            .complex_eigenvalues()
            .iter()
            .map(|z| (z.re, z.im))
            .collect();
        let mut reported: Vec<(f64, f64)> = d["closed_loop_poles"]
            .as_array()
            .expect("poles")
            .iter()
            .map(|p| (f(&p[0]), f(&p[1])))
            .collect();
        let key = |x: &(f64, f64), y: &(f64, f64)| x.1.total_cmp(&y.1).then(x.0.total_cmp(&y.0));
        poles.sort_by(key);
        reported.sort_by(key);
        for (x, y) in poles.iter().zip(&reported) {
            assert!(
                (x.0 - y.0).abs() + (x.1 - y.1).abs() < 1e-6 * x.0.hypot(x.1),
                "{x:?} vs {y:?}"
            );
            assert!(x.0 < 0.0, "unstable pole {x:?}");
        }
        for a in d["attenuation_db"].as_array().expect("attenuation") {
            for v in a["floors_db"].as_array().expect("floors") {
                // Every resonance of every floor is attenuated (measured 19.0 and 25.6 dB on
                // average).
                assert!(f(v) > 1.0, "q = {q}: {a}");
            }
        }
        attenuation.push(f(&d["mean_attenuation_db"]));
        assert!(f(&d["control_rms"]) > 0.0 && f(&d["control_peak"]) >= f(&d["control_rms"]));
        assert_eq!(d["contacts"], 0, "the default twin has no contact");
    }
    // Measured 19.0 and 25.6 dB: the higher state weight attenuates more.
    assert!(attenuation[1] > attenuation[0] + 3.0, "{attenuation:?}");
    // The estimators against the exact state: measured within 0.1 dB.
    let costs = r["estimator_costs"].as_array().expect("estimator costs");
    assert_eq!(costs.len(), 3);
    let exact = f(&costs[0]["mean_attenuation_db"]);
    for c in costs {
        assert!((f(&c["mean_attenuation_db"]) - exact).abs() < 1.5, "{c}");
    }
    let svg = std::fs::read_to_string(&plot).expect("plot written");
    assert!(svg.contains("contact initiations") && svg.contains("floor 3"));
}

/// On a twin with the contact, dataset3's force: the passive structure hits the bumper, the
/// contacts fall as q grows; the retune picks the smallest q meeting the target; the schedule
/// switches up inside the strong window and back, with no more contacts than the low gain and
/// less effort than the high gain held throughout.
#[test]
fn contacts_retune_and_schedule() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tw = dir.path().join("contact.ssp");
    contact_twin(&tw);
    let report = dir.path().join("control.json");
    let out = twin(&[
        "control",
        "--twin",
        s(&tw),
        "--data",
        s(&data(3)),
        "--q",
        "10",
        "--retune",
        "--schedule",
        "--report",
        s(&report),
    ]);
    println!("{}", ok(&out, "twin control --retune --schedule"));
    let r = read(&report);
    let passive = r["passive"]["contacts"].as_u64().expect("passive contacts");
    assert!(
        passive > 3,
        "the passive structure must hit the bumper: {passive}"
    );
    assert_eq!(
        r["passive"]["contact_times"]
            .as_array()
            .expect("times")
            .len() as u64,
        passive
    );
    let grid = r["retune"]["grid"].as_array().expect("grid");
    let contacts: Vec<u64> = grid
        .iter()
        .map(|g| g["contacts"].as_u64().expect("stable"))
        .collect();
    println!("contacts over the retune grid: {contacts:?}");
    assert!(contacts[0] <= passive);
    // Non-increasing with q (a stronger controller never makes more contacts here).
    assert!(contacts.windows(2).all(|w| w[1] <= w[0]), "{contacts:?}");
    let chosen = f(&r["retune"]["chosen_q"]);
    let first_ok = grid
        .iter()
        .find(|g| g["contacts"].as_u64() <= Some(3))
        .expect("some q meets the target");
    assert_eq!(chosen, f(&first_ok["q"]));
    let s = &r["schedule"];
    assert_eq!(f(&s["q_low"]), 10.0);
    assert_eq!(f(&s["q_high"]), chosen);
    let low = r["designs"]
        .as_array()
        .expect("designs")
        .iter()
        .find(|d| f(&d["q"]) == 10.0)
        .expect("low design")
        .clone();
    let high = r["designs"]
        .as_array()
        .expect("designs")
        .iter()
        .find(|d| f(&d["q"]) == chosen)
        .expect("high design")
        .clone();
    let switches = s["switches"].as_array().expect("switches");
    assert!(!switches.is_empty() && switches[0]["to"] == "high");
    let times: Vec<f64> = switches.iter().map(|w| f(&w["time"])).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]));
    let fraction = f(&s["high_fraction"]);
    assert!(fraction > 0.0 && fraction < 0.6, "high gain {fraction}");
    assert!(s["contacts"].as_u64() <= low["contacts"].as_u64());
    assert!(f(&s["control_rms"]) < f(&high["control_rms"]));
}

/// A controlled synthetic record (the controller in the synthetic structure's loop, fed noisy
/// accelerations) is predicted by the twin in the closed loop about as well as the passive one
/// (measured NMSE 0.093 / 0.087 / 0.091 % against 0.083 / 0.075 / 0.079 %: bound 2× the passive
/// + 0.05).
#[test]
fn controlled_records_are_predicted_in_the_closed_loop() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |n: &str| dir.path().join(n);
    let params = ["--mass", "5.2,5.2,5.2", "--stiffness", "4021,4021,4021"];
    let damping = format!("{0},{0},{0}", (-4.605f64).exp());
    let synth = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "synth",
            "--out",
            s(out),
            "--seed",
            "5",
            "--damping",
            &damping,
        ];
        args.extend(params);
        args.extend(extra);
        ok(&twin(&args), "twin synth");
    };
    synth(&path("passive.csv"), &[]);
    let report = path("control.json");
    ok(
        &twin(&[
            "control",
            "--data",
            s(&path("passive.csv")),
            "--q",
            "1e3",
            "--report",
            s(&report),
        ]),
        "twin control",
    );
    synth(&path("controlled.csv"), &["--controller", s(&report)]);
    let text = std::fs::read_to_string(path("controlled.csv")).expect("record");
    assert!(text.starts_with("time,force,acc1,acc2,acc3,control\n"));
    let nmse = |args: &[&str]| -> Vec<f64> {
        let r = path("compare.json");
        let mut all = vec!["compare", "--report", s(&r)];
        all.extend(args);
        ok(&twin(&all), "twin compare");
        read(&r)["nmse"]
            .as_array()
            .expect("nmse")
            .iter()
            .map(f)
            .collect()
    };
    let passive = nmse(&["--data", s(&path("passive.csv"))]);
    let controlled = nmse(&[
        "--data",
        s(&path("controlled.csv")),
        "--controller",
        s(&report),
    ]);
    println!("NMSE % passive {passive:?}, controlled (closed loop) {controlled:?}");
    for floor in 0..3 {
        assert!(
            controlled[floor] <= 2.0 * passive[floor] + 0.05,
            "floor {}: {} vs {}",
            floor + 1,
            controlled[floor],
            passive[floor]
        );
    }
}

/// Bad input: a clear error and no report; an unstable loop reported as such, not as numbers.
#[test]
fn bad_input_is_refused_and_instability_reported() {
    let dir = tempfile::tempdir().expect("temp dir");
    let report = dir.path().join("r.json");
    let d2 = data(2);
    let run = |extra: &[&str]| {
        let mut args = vec!["control", "--data", s(&d2), "--report", s(&report)];
        args.extend(extra);
        twin(&args)
    };
    let e = failed(&run(&["--q", "1e3", "--r", "0"]), "R = 0");
    assert!(e.contains("--r 0") && e.contains("> 0"), "{e}");
    let e = failed(&run(&["--q", "-1"]), "q < 0");
    assert!(e.contains("--q -1"), "{e}");
    let e = failed(&run(&["--q", "NaN"]), "q NaN");
    assert!(e.contains("--q NaN"), "{e}");
    assert!(!report.exists(), "no report after an error");

    // A non-finite or non-positive parameter in the twin.
    let bad = dir.path().join("bad.ssp");
    write_twin(&bad, &[("k2", ParameterValue::Real(-5.0))]);
    let e = failed(&run(&["--twin", s(&bad), "--q", "1e3"]), "k2 < 0");
    assert!(e.contains("k2"), "{e}");

    // No stabilising solution: an undamped frame with nothing weighted (q = 0) leaves the
    // Hamiltonian's eigenvalues on the imaginary axis.
    let undamped = dir.path().join("undamped.ssp");
    write_twin(
        &undamped,
        &[
            ("c1", ParameterValue::Real(0.0)),
            ("c2", ParameterValue::Real(0.0)),
            ("c3", ParameterValue::Real(0.0)),
        ],
    );
    let e = failed(
        &run(&["--twin", s(&undamped), "--q", "0"]),
        "no stabilising solution",
    );
    assert!(e.contains("q = 0") && e.contains("imaginary axis"), "{e}");
    assert!(!report.exists());

    // A loop that cannot be sampled this slowly (mm state: the floor-1 pole at ≈ −2·10⁴ 1/s,
    // one controller sample per record sample) goes unstable: reported, no numbers.
    let out = run(&["--q", "1e3", "--state-unit", "mm", "--substeps", "1"]);
    let stdout = ok(&out, "unstable design reported");
    assert!(stdout.contains("closed loop unstable"), "{stdout}");
    let r = read(&report);
    let d = &r["designs"][0];
    assert!(d["unstable"]
        .as_str()
        .is_some_and(|m| m.contains("unstable")));
    assert!(
        d["control_rms"].is_null() && d["attenuation_db"].as_array().is_some_and(Vec::is_empty)
    );
    let text = std::fs::read_to_string(&report).expect("report");
    assert!(!text.contains("NaN") && !text.contains("inf"));
}

/// With a GP corrector in the twin, the schedule also switches up where the corrector is unsure
/// (its latent variance above the threshold): the corrector runs beside the physics at the
/// record's rate. Off, only the drift triggers.
#[test]
fn schedule_switches_on_the_correctors_latent_variance() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tw = dir.path().join("default.ssp");
    write_twin(&tw, &[]);
    let corrected = dir.path().join("corrected.ssp");
    ok(
        &twin(&[
            "train",
            "--twin",
            s(&tw),
            "--data",
            s(&data(1)),
            "--out",
            s(&corrected),
            "--stride",
            "8",
        ]),
        "twin train",
    );
    let d3 = data(3);
    let run = |extra: &[&str]| -> Value {
        let report = dir.path().join("schedule.json");
        let mut args = vec![
            "control",
            "--twin",
            s(&corrected),
            "--data",
            s(&d3),
            "--q",
            "10",
            "--q",
            "300",
            "--schedule",
            "--gap",
            "2-3:5e-4:negative",
            "--report",
            s(&report),
        ];
        args.extend(extra);
        println!("{}", ok(&twin(&args), "twin control --schedule"));
        read(&report)["schedule"].clone()
    };
    let with = run(&[]);
    let without = run(&["--variance-threshold", "off"]);
    let fraction = |s: &Value, key: &str| f(&s[key]);
    assert!(with["variance_threshold"].is_array());
    assert!(without["variance_threshold"].is_null());
    assert!(fraction(&with, "variance_trigger_fraction") > 0.0);
    assert_eq!(fraction(&without, "variance_trigger_fraction"), 0.0);
    assert!(fraction(&with, "high_fraction") >= fraction(&without, "high_fraction"));
    // A twin without a corrector cannot take a threshold.
    let e = failed(
        &twin(&[
            "control",
            "--twin",
            s(&tw),
            "--data",
            s(&d3),
            "--q",
            "10",
            "--q",
            "300",
            "--schedule",
            "--gap",
            "2-3:5e-4",
            "--variance-threshold",
            "1e-6",
            "--report",
            s(&dir.path().join("x.json")),
        ]),
        "threshold without a corrector",
    );
    assert!(e.contains("no corrector"), "{e}");
}
