//! Helpers shared by the orchestrator's integration tests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

pub mod modal_records;

/// The workspace root (the bundled data is under `data/`).
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the orchestrator crate sits in the workspace")
        .to_owned()
}

/// Where `scripts/build-fmus.sh` put the FMUs (`<target>/fmu`); fails the test when they are
/// not there.
pub fn fmu_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"));
    let dir = target.join("fmu");
    let fmu = dir.join("fmu_shear.fmu");
    assert!(
        fmu.is_file(),
        "{} is missing: run scripts/build-fmus.sh",
        fmu.display()
    );
    dir
}

/// The twin calibrated (MAP, default setup) on a 20 s record of `twin synth`'s default
/// structure, seed 1, with absolute sensor noise of `noise_sd` m/s² on every floor.
pub fn twin_calibrated_on_default_structure(noise_sd: f64) -> orchestrator::twin::Twin {
    use orchestrator::calibrate::{calibrate, calibrated_twin, CalibrationSetup};
    use orchestrator::synth::{synth_record, NoiseLevel, Scenario};
    std::env::set_var("TWIN_FMU_DIR", fmu_dir());
    let mut s = Scenario {
        seed: 1,
        ..Scenario::default()
    };
    s.noise.level = NoiseLevel::Sd(vec![noise_sd; 3]);
    let (record, _) = synth_record(&s).expect("synth");
    let twin = orchestrator::twin::Twin::default_twin().expect("default twin");
    let cal =
        calibrate(&twin, &record.measurement, &CalibrationSetup::default()).expect("calibration");
    calibrated_twin(&twin, &cal).expect("calibrated twin")
}

/// A new 20 s record of the default structure (seed 2, sensor noise `noise_sd` m/s², the force
/// ×3 between 12 and 17 s, like dataset3's stronger shaking) with the hidden changes `change`
/// makes.
pub fn hidden_change_record(
    noise_sd: f64,
    change: impl FnOnce(&mut orchestrator::synth::Scenario),
) -> orchestrator::data::Measurement {
    use orchestrator::synth::{synth_record, ForceWindow, NoiseLevel, Scenario};
    let mut s = Scenario {
        seed: 2,
        ..Scenario::default()
    };
    s.noise.level = NoiseLevel::Sd(vec![noise_sd; 3]);
    s.force.windows.push(ForceWindow {
        start: 12.0,
        end: 17.0,
        gain: 3.0,
        ramp: 0.5,
    });
    change(&mut s);
    synth_record(&s).expect("synth").0.measurement
}

/// The twin of the hidden-change tests: calibrated on the default structure's change-free
/// record with 0.003 m/s² of sensor noise, once per test binary.
pub fn hidden_change_twin() -> &'static orchestrator::twin::Twin {
    static TWIN: std::sync::OnceLock<orchestrator::twin::Twin> = std::sync::OnceLock::new();
    TWIN.get_or_init(|| twin_calibrated_on_default_structure(HIDDEN_CHANGE_NOISE_SD))
}

/// Sensor noise sd (m/s²) of the hidden-change records and their twin.
pub const HIDDEN_CHANGE_NOISE_SD: f64 = 0.003;

/// The `twin` binary of this build, on this build's FMUs (`TWIN_FMU_DIR`), without an FMU log.
pub fn twin_cmd() -> std::process::Command {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_twin"));
    cmd.env("TWIN_FMU_DIR", fmu_dir())
        .env_remove("TWIN_FMU_LOG");
    cmd
}

/// `twin synth` of the five-storey test building under the scenario file `scenario`, excited by
/// `excitation` (`base`, `force:2`), `duration` seconds, noise seed `seed`, acc1/3/5 in g,
/// written to `out`; the caller may add arguments (a change) before running it.
pub fn synth_five_storeys_in_g(
    scenario: &Path,
    excitation: &str,
    duration: u32,
    seed: u64,
    out: &Path,
) -> std::process::Command {
    let mut cmd = twin_cmd();
    cmd.arg("synth").arg("--scenario").arg(scenario);
    cmd.args(["--storeys", "5", "--excitation", excitation]);
    cmd.args([
        "--duration",
        &duration.to_string(),
        "--seed",
        &seed.to_string(),
    ]);
    cmd.args(["--channels", "acc1,acc3,acc5", "--units", "acc=g"]);
    cmd.arg("--out").arg(out);
    cmd
}

/// `twin ARGS`, run to its end: its output.
pub fn twin<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> std::process::Output {
    twin_cmd()
        .args(args)
        .output()
        .expect("the twin binary runs")
}

/// `twin ARGS`, which must succeed: its output (a failure shows the arguments and `twin`'s
/// stderr).
pub fn twin_ok<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> std::process::Output {
    let out = twin(args);
    assert!(
        out.status.success(),
        "twin {}: {}",
        shown(args),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `twin ARGS`, which must fail: its stderr.
pub fn twin_fails<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> String {
    let out = twin(args);
    assert!(!out.status.success(), "twin {} succeeded", shown(args));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn shown<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> String {
    args.iter()
        .map(|a| a.as_ref().to_string_lossy())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The worst floor's value (the largest; a figure per floor, at least one floor).
pub fn worst(x: &[f64]) -> f64 {
    x.iter()
        .copied()
        .reduce(f64::max)
        .expect("a figure for at least one floor")
}

/// A report's JSON array of numbers (a figure per floor), as numbers.
pub fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

/// `add_physics` naming `kind` at `location`, the parameters within `tolerance` (relative) of
/// the truth, and the worst-floor NMSE after at most a quarter of before.
pub fn assert_effect(
    d: &orchestrator::diagnose::Diagnosis,
    kind: orchestrator::diagnose::Kind,
    location: &[usize],
    side: Option<&str>,
    truth: &[(&str, f64)],
    tolerance: f64,
) {
    assert_eq!(
        d.action,
        orchestrator::diagnose::Action::AddPhysics,
        "{}",
        d.reason
    );
    let e = d.effect.as_ref().expect("an effect");
    assert_eq!(
        (e.name.kind, e.name.location.as_slice()),
        (kind.into(), location),
        "{}",
        d.reason
    );
    assert_eq!(e.name.side, side, "{}", d.reason);
    for (name, value) in truth {
        let got = e.parameters[*name];
        assert!(
            (got - value).abs() <= tolerance * value.abs(),
            "{name}: {got} for {value} (±{tolerance})"
        );
    }
    assert!(
        worst(&d.nmse_after) <= worst(&d.nmse_before) / 4.0,
        "NMSE {:?} → {:?}",
        d.nmse_before,
        d.nmse_after
    );
}

/// `recalibrate`, `name` the parameter that moved most, by `relative` (within 2 points:
/// measured within 0.1).
pub fn assert_recalibrated(d: &orchestrator::diagnose::Diagnosis, name: &str, relative: f64) {
    assert_eq!(
        d.action,
        orchestrator::diagnose::Action::Recalibrate,
        "{}",
        d.reason
    );
    assert!(d.effect.is_none());
    let r = d.recalibration.as_ref().expect("recalibration");
    let top = &r.parameters[0];
    assert_eq!(top.name, name, "{}", d.reason);
    assert!(
        (top.relative_change - relative).abs() < 0.02,
        "{name} moved by {} for {relative}",
        top.relative_change
    );
    assert_eq!(d.nmse_after, r.nmse_after);
    assert!(worst(&d.nmse_after) <= worst(&d.nmse_before) / 4.0);
}
