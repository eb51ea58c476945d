//! `twin control --ssp`: the controlled system as an SSP archive (the twin's shear FMU and the
//! `fmu_lqr` controller FMU), run by `twin run`, against the master's own closed loop (the
//! `LqrBlock` on sampled connections, `workflows::control::predict_controlled`).
//!
//! Which system each master runs (u_k = the command the controller computes from the sample at
//! t_k; the controller's output has no feedthrough, the shear's acc1 has one from
//! `force − control_force`):
//! - `twin control`'s master: at t_k the block reads the accelerations as the last step left
//!   them, acc(x_k, F, u_{k−2}), computes u_k and hands the structure u_{k−1} for [t_k, t_{k+1}];
//! - `twin run --algorithm jacobi`: the controller FMU reads the physics' outputs as the last
//!   step left them, acc(x_k, F, u_{k−2}) (at t_0: the master's initial 0, the block's too, as
//!   the structure is at rest), computes u_k in its step and the structure steps with
//!   u_{k−1}, its output since the last step: the same system, compared to 1e-9 of each output's
//!   peak on a constant force (the block's record ramps the force between samples, the run
//!   file's rows are the points themselves: with a constant force both hold it);
//! - `twin run` (Gauss–Seidel): the structure gets u_{k−1} first, then the controller reads
//!   acc(x_k, F, u_{k−1}): floor 1's reading moves by (u_{k−2} − u_{k−1})/m1 at every sample, a
//!   different system. With the integrating estimator it stays close (measured: 7.8e-2 of the
//!   peak acceleration); the Kalman observer's innovation is off by the command's step at every
//!   sample, and its q = 1e3 loop diverges.

mod common;
use common::twin_ok;

use std::path::Path;

use orchestrator::cosim::import::Fmu;
use orchestrator::twin::data::Measurement;
use orchestrator::twin::{ParameterValue, Twin};
use orchestrator::workflows::control::{predict_controlled, ControllerSpec};

const STEP: f64 = 1.0 / 51.2;
const SAMPLES: usize = 513;
const FORCE: f64 = 2.0;
/// The controller's rate: 4 samples per record sample (at 51.2 Hz, one sample of delay leaves
/// only small gains stable).
const SUBSTEPS: usize = 4;
const CONTROL_STEP: f64 = STEP / SUBSTEPS as f64;

fn write_force(path: &Path, force: impl Fn(usize) -> f64, with_acc: bool) {
    let mut text = String::from(if with_acc {
        "time,force,acc1,acc2,acc3\n"
    } else {
        "time,force\n"
    });
    for k in 0..SAMPLES {
        let t = k as f64 * STEP;
        if with_acc {
            // Any response: `twin control` reads only the force (and the accelerations' RMS
            // for its default Kalman sensor sd).
            let a = 0.01 * (t * 40.0).sin();
            text += &format!("{t},{},{a},{a},{a}\n", force(k));
        } else {
            text += &format!("{t},{}\n", force(k));
        }
    }
    std::fs::write(path, text).expect("write the force");
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).expect("read the run");
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("a header")
        .split(',')
        .map(str::to_owned)
        .collect();
    let mut columns = vec![Vec::new(); header.len()];
    for line in lines {
        for (c, x) in line.split(',').enumerate() {
            columns[c].push(x.parse::<f64>().expect("a number"));
        }
    }
    (header, columns)
}

fn column<'a>(run: &'a (Vec<String>, Vec<Vec<f64>>), name: &str) -> &'a [f64] {
    let i = run
        .0
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {:?}", run.0));
    &run.1[i]
}

/// Largest difference relative to `a`'s peak.
fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let peak = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(peak > 0.0);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / peak
}

#[test]
fn the_controlled_system_as_ssp_is_the_masters_closed_loop() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The design's record: a broadband force (the designs and the report's attenuation need
    // one); the comparison's: a constant force.
    let design_record = dir.path().join("broadband.csv");
    write_force(
        &design_record,
        |k| {
            let t = k as f64 * STEP;
            (1..12)
                .map(|i| (2.0 * i as f64 * t + 0.3 * i as f64).sin())
                .sum::<f64>()
        },
        true,
    );
    let record = dir.path().join("constant.csv");
    write_force(&record, |_| FORCE, true);
    for estimator in ["integrate", "kalman"] {
        let report = dir.path().join(format!("{estimator}.json"));
        let ssp = dir.path().join(format!("{estimator}.ssp"));
        twin_ok(&[
            "control",
            "--data",
            design_record.to_str().expect("utf-8"),
            "--q",
            "1e2",
            "1e3",
            "--r",
            "0.1",
            "--substeps",
            "4",
            "--sensor-noise",
            "0",
            "--estimator",
            estimator,
            "--report",
            report.to_str().expect("utf-8"),
            "--ssp",
            ssp.to_str().expect("utf-8"),
            "--ssp-q",
            "1e3",
        ]);
        let text = std::fs::read_to_string(&report).expect("the report");
        let spec = ControllerSpec::from_json(&text, "report").expect("a control report");

        // (a) The archive: the physics and the controller with the design's parameters.
        let system = Twin::read(&ssp).expect("the SSP reads back");
        let names: Vec<&str> = system.components.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["physics", "lqr"]);
        let lqr = system.component("lqr").expect("the controller");
        let design = spec.design(Some(1e3)).expect("the q = 1e3 design");
        for (i, g) in design.gain.iter().enumerate() {
            assert_eq!(
                lqr.parameters.get(&format!("gain{}", i + 1)),
                Some(&ParameterValue::Real(*g))
            );
        }
        assert_eq!(
            lqr.parameters.get("estimator"),
            Some(&ParameterValue::Integer(i32::from(estimator == "kalman")))
        );
        assert_eq!(
            lqr.parameters.get("sample_interval"),
            Some(&ParameterValue::Real(1.0 / spec.control_rate_hz))
        );
        assert_eq!(system.system_inputs(), ["force"]);
        assert_eq!(
            system.system_outputs(),
            ["acc1", "acc2", "acc3", "control_force"]
        );
        assert_eq!(
            system.default_experiment,
            Some((0.0, (SAMPLES - 1) as f64 * STEP))
        );

        // (b) The master's loop (the block) on the constant force…
        let data = Measurement::read(&record).expect("the record");
        let default = dir.path().join("default.ssp");
        twin_ok(&["init", "--out", default.to_str().expect("utf-8")]);
        let twin = Twin::read(&default).expect("the default twin");
        let block =
            predict_controlled(&twin, &data, &spec, Some(1e3), &mut |_, _| {}).expect("the loop");
        // … and the SSP through `twin run`, Jacobi and Gauss–Seidel, on the same force.
        let force = dir.path().join("force.csv");
        write_force(&force, |_| FORCE, false);
        let run = |algorithm: &str| {
            let out = dir.path().join(format!("{estimator}-{algorithm}.csv"));
            twin_ok(&[
                "run",
                ssp.to_str().expect("utf-8"),
                "--input",
                force.to_str().expect("utf-8"),
                "--hold-inputs",
                "--step",
                &CONTROL_STEP.to_string(),
                "--algorithm",
                algorithm,
                "--output",
                out.to_str().expect("utf-8"),
            ]);
            read_csv(&out)
        };
        let jacobi = run("jacobi");
        assert_eq!(column(&jacobi, "time").len(), (SAMPLES - 1) * SUBSTEPS + 1);
        // The block's loop is recorded at the record's rate: every SUBSTEPS-th point.
        let at_record_rate =
            |c: &[f64]| -> Vec<f64> { c.iter().step_by(SUBSTEPS).copied().collect() };
        for f in 0..3 {
            let name = format!("physics.acc{}", f + 1);
            let e = relative_error(block.acc(f), &at_record_rate(column(&jacobi, &name)));
            assert!(
                e <= 1e-9,
                "{estimator}: {name}: Jacobi run vs the block: {e:.2e}"
            );
        }
        if estimator == "kalman" {
            // Under Gauss–Seidel the observer's innovation is off by the command's step at every
            // sample: this design's loop diverges (measured: the command reaches inf at 3.4 s).
            continue;
        }
        let gauss_seidel = run("gauss-seidel");
        let mut gs_error = 0.0f64;
        for f in 0..3 {
            let name = format!("physics.acc{}", f + 1);
            gs_error = gs_error.max(relative_error(
                block.acc(f),
                &at_record_rate(column(&gauss_seidel, &name)),
            ));
        }
        // The Gauss–Seidel system reads floor 1 with the new command acting: not the same
        // system, but close (measured: see the message).
        eprintln!("{estimator}: Gauss–Seidel twin run vs the block: {gs_error:.3e} of the peak");
        assert!(
            gs_error > 1e-9 && gs_error < 0.2,
            "{estimator}: Gauss–Seidel vs the block: {gs_error:.3e}"
        );
    }
}

#[test]
fn the_controller_fmu_refuses_a_wrong_step_and_carries_on() {
    let fmu = Fmu::open(&common::fmu_dir().join("fmu_lqr.fmu")).expect("fmu_lqr.fmu");
    let vr = |n: &str| fmu.value_reference(n).expect("a variable");
    let mut instance = fmu.instantiate("lqr").expect("instantiate");
    instance.setup_experiment(0.0, None).expect("setup");
    instance.enter_initialization_mode().expect("init");
    instance
        .set_real(&[vr("gain4"), vr("sample_interval")], &[50.0, 0.01])
        .expect("parameters");
    instance.exit_initialization_mode().expect("exit init");
    instance
        .set_real(&[vr("acc1")], &[1.0])
        .expect("an acceleration");
    let wrong = instance
        .do_step(0.0, 0.02)
        .expect_err("a step of 0.02 s with sample_interval 0.01 s is refused");
    let text = wrong.to_string();
    assert!(
        text.contains("fmi2Error") && text.contains("sample_interval"),
        "{text}"
    );
    // Nothing moved: the right step from the same time works.
    instance.do_step(0.0, 0.01).expect("the right step");
    instance
        .do_step(0.01, 0.01 * (1.0 + 1e-12))
        .expect("within 1e-9");
    let mut u = [0.0];
    instance
        .get_real(&[vr("control_force")], &mut u)
        .expect("the command");
    assert!(
        u[0].is_finite() && u[0] != 0.0,
        "the command moved: {}",
        u[0]
    );
}
