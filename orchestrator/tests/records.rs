//! Records as loggers and buildings give them, through the built `twin` binary: times rounded
//! to 9 significant digits compare as exact times do; units and a column map read as SI; a
//! record without the columns a command needs is refused at once, naming the column.
//!
//! Needs the shear FMU: `scripts/build-fmus.sh` (found through `TWIN_FMU_DIR`).

use std::path::Path;
use std::process::Output;

use orchestrator::record::{format_g9, Measurement};

mod common;
use common::{twin, workspace};

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

fn dataset1() -> Measurement {
    Measurement::read(&workspace().join("data/dataset1.csv")).expect("dataset1")
}

/// `twin compare`'s report for `data`.
fn compare(data: &Path, dir: &Path, name: &str) -> serde_json::Value {
    let report = dir.join(format!("{name}.json"));
    let out = twin(&["compare", "--data", s(data), "--report", s(&report)]);
    assert!(out.status.success(), "{name}: {}", stderr(&out));
    serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON")
}

/// dataset1 repeated to one hour at 51.2 Hz, its times written by `time`.
fn one_hour(time: impl Fn(f64) -> String) -> String {
    let m = dataset1();
    let n = 3600 * 512 / 10;
    let mut text = String::from("time,force,acc1,acc2,acc3\n");
    for k in 0..n {
        let j = k % m.len();
        text.push_str(&time(k as f64 / 51.2));
        text.push(',');
        text.push_str(&format_g9(m.force()[j]));
        for f in 0..3 {
            text.push(',');
            text.push_str(&format_g9(m.acc(f)[j]));
        }
        text.push('\n');
    }
    text
}

/// A logger writing 9 significant digits (`1074.17969`) makes unequal steps of the written
/// times; the record is stepped on its nominal grid, so the comparison is the exact times'
/// to the bit (before, the unequal steps cost 67 s instead of 0.57 s: scripts/bench-records-time.sh).
#[test]
fn an_hour_with_times_to_nine_digits_compares_as_with_exact_times() {
    let dir = tempfile::tempdir().expect("temp");
    let exact = dir.path().join("exact.csv");
    let rounded = dir.path().join("rounded.csv");
    std::fs::write(&exact, one_hour(|t| format!("{t:.6}"))).expect("write");
    std::fs::write(&rounded, one_hour(format_g9)).expect("write");
    let text = std::fs::read_to_string(&rounded).expect("read");
    assert!(
        text.contains("\n1074.17969,"),
        "the times carry 9 significant digits"
    );
    let a = compare(&exact, dir.path(), "exact");
    let b = compare(&rounded, dir.path(), "rounded");
    assert_eq!(a["nmse"], b["nmse"]);
    assert!(a["nmse"][0].as_f64().expect("NMSE") > 0.0);
}

/// The same measurement in other units and under other names, mapped with `--columns`: the
/// same NMSE as the SI file up to the 9 digits the conversions are written with.
#[test]
fn units_and_a_column_map_read_as_si() {
    let dir = tempfile::tempdir().expect("temp");
    let m = dataset1();
    let si = workspace().join("data/dataset1.csv");
    let converted = dir.path().join("units.csv");
    let mut text = String::from("time,fp (kN),a1 (g),acc2 (mm/s2),acc3 (m/s^2)\n");
    for k in 0..m.len() {
        text.push_str(&format!(
            "{:.6},{},{},{},{}\n",
            m.time[k],
            format_g9(m.force()[k] / 1e3),
            format_g9(m.acc(0)[k] / 9.80665),
            format_g9(m.acc(1)[k] * 1e3),
            format_g9(m.acc(2)[k]),
        ));
    }
    std::fs::write(&converted, text).expect("write");
    let map = dir.path().join("map.json");
    std::fs::write(&map, r#"{"fp": "force", "a1 (g)": "acc1"}"#).expect("write");
    let unmapped = twin(&["compare", "--data", s(&converted)]);
    assert!(!unmapped.status.success());
    assert!(
        stderr(&unmapped).contains("'fp (kN)'"),
        "{}",
        stderr(&unmapped)
    );
    let report = dir.path().join("units.json");
    let out = twin(&[
        "compare",
        "--data",
        s(&converted),
        "--columns",
        s(&map),
        "--report",
        s(&report),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let mapped: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    let reference = compare(&si, dir.path(), "si");
    for f in 0..3 {
        let (a, b) = (
            mapped["nmse"][f].as_f64().expect("NMSE"),
            reference["nmse"][f].as_f64().expect("NMSE"),
        );
        // 9 significant digits of each converted value: relative NMSE changes of order 1e-8.
        assert!(
            (a - b).abs() <= 1e-6 * b,
            "floor {}: {a} against {b}",
            f + 1
        );
    }
}

/// A roving-sensor run (acc2 alone) reads; `twin compare` compares the one channel it has (its
/// NMSE that of acc2 on the whole record), and `twin calibrate`, written for the paper's three
/// accelerometers, refuses it at once, naming the missing column, and writes nothing.
#[test]
fn a_command_refuses_a_record_without_its_columns_naming_them() {
    let dir = tempfile::tempdir().expect("temp");
    let m = dataset1();
    let data = dir.path().join("acc2.csv");
    let mut text = String::from("time,force,acc2 (g)\n");
    for k in 0..m.len() {
        text.push_str(&format!(
            "{:.6},{},{}\n",
            m.time[k],
            format_g9(m.force()[k]),
            format_g9(m.acc(1)[k] / 9.80665)
        ));
    }
    std::fs::write(&data, text).expect("write");
    let read = Measurement::read(&data).expect("a subset reads");
    assert_eq!(read.channel_names(), ["force", "acc2"]);
    let report = dir.path().join("r.json");
    let out = twin(&["compare", "--data", s(&data), "--report", s(&report)]);
    assert!(out.status.success(), "{}", stderr(&out));
    let one: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(one["channels"], serde_json::json!(["acc2"]));
    let whole = dir.path().join("whole.json");
    let dataset1_path = workspace().join("data/dataset1.csv");
    let out = twin(&[
        "compare",
        "--data",
        s(&dataset1_path),
        "--report",
        s(&whole),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let whole: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&whole).expect("report")).expect("JSON");
    let (a, b) = (
        one["nmse"][0].as_f64().expect("NMSE"),
        whole["nmse"][1].as_f64().expect("NMSE"),
    );
    // The same prediction and samples, the record rounded to 9 significant digits in g: equal
    // to within that rounding (bar 1e-6 relative).
    assert!(
        (a - b).abs() <= 1e-6 * b,
        "acc2 alone {a} %, in dataset1 {b} %"
    );

    // calibrate takes a record of any channels the structure has (one run of a roving
    // sensor): fitted on acc2 alone, its NMSE reported by that name.
    let calibrated = dir.path().join("c.ssp");
    let report = dir.path().join("c.json");
    let out = twin(&[
        "calibrate",
        "--data",
        s(&data),
        "--out",
        s(&calibrated),
        "--report",
        s(&report),
        "--starts",
        "2",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    let by_channel = r["runs"][0]["nmse"].as_object().expect("NMSE by channel");
    assert_eq!(by_channel.keys().collect::<Vec<_>>(), ["acc2"]);
}
