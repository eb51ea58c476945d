//! The modal parts of `twin compare` and `twin diagnose` (`workflows::modal::evidence`): on a
//! record of the twin's own building no mode leaves the band; on a record of the building with
//! storey 2 15 % softer the modes have moved by what the softer structure's exact modes say, and
//! one moved beyond the band is called moved. The same records without their excitation column
//! (ambient: what a building's monitoring measures) are diagnosed by their modes alone: the
//! unchanged one `none`, the softer one `recalibrate`, storey 2's stiffness the best single
//! explanation of the frequencies.

use std::path::{Path, PathBuf};
use std::process::Command;

use orchestrator::record::Measurement;
use orchestrator::twin::Twin;
use orchestrator::workflows::modal::{modal_evidence, twin::structure_modes, ModalBand};
use structure::{Excitation, Structure};

mod common;
use common::{synth_five_storeys_in_g, twin_cmd};

fn building() -> Structure {
    Structure::uniform(5, 5.2, 3.0, 4021.0, Excitation::Base)
}

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("twin runs");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `building()` as a twin file, by `twin init --nominal`: `dir/T.ssp`.
fn building_twin(dir: &Path) -> PathBuf {
    let b = building();
    let nominal = dir.join("nominal.json");
    let json = serde_json::json!({"m": b.mass, "c": b.damping, "k": b.stiffness});
    std::fs::write(&nominal, json.to_string()).expect("nominal");
    let twin = dir.join("T.ssp");
    let storeys = b.storeys().to_string();
    run(twin_cmd()
        .args([
            "init",
            "--storeys",
            &storeys,
            "--excitation",
            "base",
            "--nominal",
        ])
        .arg(&nominal)
        .arg("--out")
        .arg(&twin));
    twin
}

/// 120 s of stationary ground motion, acc1/3/5 in g; `softer`: k2 × 0.85 throughout.
fn record(dir: &Path, name: &str, softer: bool) -> PathBuf {
    let scenario = dir.join("stationary.json");
    std::fs::write(&scenario, r#"{"ground_motion": {"strong_end": 100000}}"#).expect("scenario");
    let out = dir.join(format!("{name}.csv"));
    let mut cmd = synth_five_storeys_in_g(&scenario, "base", 120, 5, &out);
    if softer {
        cmd.args(["--change", "k2@0:0.85"]);
    }
    run(&mut cmd);
    out
}

#[test]
fn a_softer_storey_shows_in_the_modes_and_an_unchanged_building_does_not() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = Twin::for_structure(&building()).expect("twin");
    let unchanged = Measurement::read(&record(d, "unchanged", false)).expect("record");
    let e = modal_evidence(&twin, &unchanged, ModalBand::default()).expect("evidence");
    assert!(
        e.shifted.is_empty(),
        "moved modes on an unchanged record: {:?}",
        e.modes
    );
    // Measured: LSCF pairs modes 2–4 within 0.02 % (band 1.5 %); modes 1 and 5 are not found
    // (mode 1's half-power band, 0.008 Hz, is far inside one 0.05 Hz bin).
    assert!(e.modes.len() >= 3, "paired {}", e.modes.len());
    for m in &e.modes {
        assert!(m.pair.frequency_shift_percent.abs() < 0.5, "{m:?}");
        assert!(m.pair.mac > 0.95, "{m:?}");
    }

    let softer_record = Measurement::read(&record(d, "softer", true)).expect("record");
    let e = modal_evidence(&twin, &softer_record, ModalBand::default()).expect("evidence");
    let mut softer = building();
    softer.stiffness[1] *= 0.85;
    let (before, after) = (
        structure_modes(&building()).unwrap(),
        structure_modes(&softer).unwrap(),
    );
    assert!(!e.shifted.is_empty(), "no mode moved: {:?}", e.modes);
    for m in &e.modes {
        let i = m.pair.twin_mode - 1;
        let exact = 100.0 * (after[i].frequency - before[i].frequency) / before[i].frequency;
        // Measured (LSCF, 120 s): −0.26 / −0.99 / −2.95 % for modes 2–4 against exact −0.25 /
        // −0.98 / −2.95 %; within 0.5 points.
        assert!(
            (m.pair.frequency_shift_percent - exact).abs() < 0.5,
            "mode {}: {} % against exact {exact} %",
            m.pair.twin_mode,
            m.pair.frequency_shift_percent
        );
        // Moved beyond the band's 1.5 % floor by twice it: called moved; by less than 1 %: not.
        if exact.abs() > 2.0 {
            assert!(
                m.outside,
                "mode {} not called moved for an exact {exact} %",
                m.pair.twin_mode
            );
        }
        if exact.abs() < 1.0 {
            assert!(
                !m.outside,
                "mode {} called moved for an exact {exact} %",
                m.pair.twin_mode
            );
        }
    }
}

/// `twin modal --data D --twin T --plot P.svg`: the stabilisation diagrams (P.svg), the FRFs
/// (P-frf.svg), the shapes along the height with the record's beside the twin's
/// (P-shapes.svg) and the MAC matrix (P-mac.svg); the report pairs the modes.
#[test]
fn twin_modal_with_a_record_and_a_twin_draws_every_view() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = building_twin(d);
    let data = record(d, "unchanged", false);
    let (plot, report) = (d.join("modal.svg"), d.join("modal.json"));
    run(twin_cmd()
        .args(["modal", "--samples", "0", "--data"])
        .arg(&data)
        .arg("--twin")
        .arg(&twin)
        .arg("--plot")
        .arg(&plot)
        .arg("--report")
        .arg(&report));
    for name in [
        "modal.svg",
        "modal-frf.svg",
        "modal-shapes.svg",
        "modal-mac.svg",
    ] {
        let svg = std::fs::read_to_string(d.join(name)).expect(name);
        assert!(svg.starts_with("<svg"), "{name}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    let pairs = json["comparison"]["pairs"].as_array().expect("pairs");
    assert!(pairs.len() >= 3, "paired {}", pairs.len());
    assert_eq!(
        json["comparison"]["mac_matrix"]
            .as_array()
            .expect("MAC")
            .len(),
        5
    );
}

/// `record` with its excitation column left out: an ambient record (responses only).
fn ambient(dir: &Path, name: &str, softer: bool) -> PathBuf {
    let measured = std::fs::read_to_string(record(dir, name, softer)).expect("record");
    let mut lines = measured.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let excitation = header
        .iter()
        .position(|h| h.starts_with("ground_acc"))
        .expect("ground_acc column");
    let keep = |line: &str| {
        line.split(',')
            .enumerate()
            .filter(|&(i, _)| i != excitation)
            .map(|(_, f)| f)
            .collect::<Vec<_>>()
            .join(",")
    };
    let mut text = keep(&header.join(","));
    for line in lines {
        text.push('\n');
        text.push_str(&keep(line));
    }
    text.push('\n');
    let out = dir.join(format!("{name}-ambient.csv"));
    std::fs::write(&out, text).expect("write");
    out
}

/// `twin diagnose` of ambient records through the CLI: by the modes alone (SSI-COV), `none`
/// on the unchanged building, `recalibrate` with k2 the best explanation on the softer one.
#[test]
fn an_ambient_record_is_diagnosed_by_its_modes() {
    let dir = tempfile::tempdir().expect("dir");
    let d = dir.path();
    let twin = building_twin(d);
    let diagnose = |data: &Path, name: &str| -> serde_json::Value {
        let report = d.join(format!("{name}.json"));
        let plot = d.join(format!("{name}.svg"));
        let out = run(twin_cmd()
            .arg("diagnose")
            .arg("--twin")
            .arg(&twin)
            .arg("--data")
            .arg(data)
            .arg("--report")
            .arg(&report)
            .arg("--plot")
            .arg(&plot));
        println!("{out}");
        let svg = std::fs::read_to_string(&plot).expect("plot");
        assert!(svg.starts_with("<svg"), "{name}");
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON")
    };

    let r = diagnose(&ambient(d, "unchanged", false), "unchanged");
    assert_eq!(r["evidence"], "ambient");
    assert_eq!(r["action"], "none", "{}", r["reason"]);
    assert!(r["modes"]["modes"].as_array().expect("modes").len() >= 3);

    let r = diagnose(&ambient(d, "softer", true), "softer");
    assert_eq!(r["action"], "recalibrate", "{}", r["reason"]);
    // Measured: mode 1 −2.75 % (exact −2.56 %), modes 2, 3 and 5 within 1 %; the
    // explanations k2 −14.5 % and m4 +16.9 % tie (misfit 2.8 each against 35.0 unchanged; under
    // ground motion the two move the frequencies alike), k1 next at 13.3. Bars: k2 among those
    // tied for best, within 5 points of −15 %, its misfit under half the unchanged twin's.
    let tied = r["tied_for_best"].as_u64().expect("tied") as usize;
    let explanations = r["explanations"].as_array().expect("explanations");
    let k2 = explanations[..tied]
        .iter()
        .find(|e| e["parameter"] == "k2")
        .unwrap_or_else(|| panic!("k2 not among the best: {}", r["reason"]));
    let change = k2["change_percent"].as_f64().expect("change");
    assert!((change + 15.0).abs() < 5.0, "k2 {change} % against −15 %");
    assert!(
        k2["misfit"].as_f64().unwrap() < 0.5 * r["misfit_unchanged"].as_f64().unwrap(),
        "{}",
        r["reason"]
    );
    assert!(tied <= 3, "{tied} explanations tied: {}", r["reason"]);

    // `twin modal --data` takes the ambient record too: SSI-COV alone, no FRF.
    let report = d.join("modal.json");
    run(twin_cmd()
        .args(["modal", "--samples", "0", "--data"])
        .arg(d.join("softer-ambient.csv"))
        .arg("--twin")
        .arg(&twin)
        .arg("--report")
        .arg(&report));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("JSON");
    assert_eq!(json["record"]["excitation"], "none (ambient)");
    assert!(json["record"]["frf"].is_null());
    assert!(json["record"]["input_output"].is_null());
    assert!(!json["comparison"]["pairs"]
        .as_array()
        .expect("pairs")
        .is_empty());

    // An ambient record with --effects is refused, saying why.
    let out = twin_cmd()
        .arg("diagnose")
        .arg("--twin")
        .arg(&twin)
        .arg("--data")
        .arg(d.join("softer-ambient.csv"))
        .arg("--report")
        .arg(d.join("x.json"))
        .args(["--effects", "cubic@1"])
        .output()
        .expect("twin runs");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no excitation column"), "{stderr}");
}
