//! FMUs made by other tools, loaded and stepped by `orchestrator::import::Fmu`:
//!
//! - `LowPass.fmu`, a pythonfmu co-simulation FMU (a first-order low-pass with gain, written in
//!   Python: tests/python/fixtures/low_pass.py), against its exact solution;
//! - `shear_container.fmu`, fmu-manipulation-toolbox's FMU Container holding the shear FMU,
//!   against the shear FMU run directly on the container's schedule;
//! - `shear_low_pass.fmu`, a sequential container of the shear FMU and LowPass.fmu, against the
//!   shear FMU and the low-pass formula.
//!
//! Built by `scripts/make-third-party-fmus.sh` into target/third-party/; a missing file fails
//! the test. A pythonfmu binary takes CPython's symbols from its host process, so the tests that
//! load one run in a child process of this test binary started with libpython preloaded and
//! PYTHONHOME set, as target/third-party/python-runtime.env (written by the script) says.

use std::path::{Path, PathBuf};
use std::process::Command;

use orchestrator::import::{Fmu, Instance};

mod common;
use common::workspace;

/// The examples' sampling interval, 1/51.2 s: exact in binary.
const STEP: f64 = 1.0 / 51.2;
/// Set in the child processes that run the Python-hosting tests.
const CHILD: &str = "TWIN_THIRD_PARTY_CHILD";

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"))
}

fn third_party(file: &str) -> PathBuf {
    let path = target_dir().join("third-party").join(file);
    assert!(
        path.is_file(),
        "{} is missing: run scripts/make-third-party-fmus.sh",
        path.display()
    );
    path
}

fn shear_fmu() -> PathBuf {
    let path = target_dir().join("fmu/fmu_shear.fmu");
    assert!(
        path.is_file(),
        "{} is missing: run scripts/build-fmus.sh",
        path.display()
    );
    path
}

/// dataset1's force column, F_0 … F_1023.
fn dataset1_force() -> Vec<f64> {
    let path = workspace().join("data/dataset1.csv");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .nth(1)
                .and_then(|f| f.trim().parse().ok())
                .expect("a force value")
        })
        .collect()
}

fn initialized(fmu: &Fmu, name: &str, reals: &[(&str, f64)]) -> Instance {
    let mut instance = fmu
        .instantiate(name)
        .unwrap_or_else(|e| panic!("instantiate: {e}"));
    instance
        .setup_experiment(0.0, None)
        .expect("fmi2SetupExperiment");
    instance
        .enter_initialization_mode()
        .expect("fmi2EnterInitializationMode");
    for (variable, value) in reals {
        let vr = fmu.value_reference(variable).expect("variable");
        instance
            .set_real(&[vr], &[*value])
            .unwrap_or_else(|e| panic!("set {variable}: {e}"));
    }
    instance
        .exit_initialization_mode()
        .expect("fmi2ExitInitializationMode");
    instance
}

fn vrs(fmu: &Fmu, names: &[&str]) -> Vec<u32> {
    names
        .iter()
        .map(|n| fmu.value_reference(n).unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

/// max |a − b| over max |b|, per column.
fn relative_deviation(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<f64> {
    assert_eq!(a.len(), b.len());
    (0..b[0].len())
        .map(|j| {
            let scale = b.iter().map(|r| r[j].abs()).fold(0.0, f64::max);
            let worst = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x[j] - y[j]).abs())
                .fold(0.0, f64::max);
            worst / scale
        })
        .collect()
}

/// The shear FMU as a container drives it: values only (the force held over each step), the
/// outputs read after each step. Row k is the accelerations at t_{k+1}.
fn shear_held(force: &[f64]) -> Vec<Vec<f64>> {
    let fmu = Fmu::open(&shear_fmu()).unwrap_or_else(|e| panic!("{e}"));
    let mut shear = initialized(&fmu, "direct", &[]);
    let (force_vr, acc) = (vrs(&fmu, &["force"]), vrs(&fmu, &["acc1", "acc2", "acc3"]));
    let mut rows = Vec::new();
    for (k, value) in force[..force.len() - 1].iter().enumerate() {
        shear.set_real(&force_vr, &[*value]).expect("set force");
        shear.do_step(k as f64 * STEP, STEP).expect("fmi2DoStep");
        let mut out = [0.0; 3];
        shear.get_real(&acc, &mut out).expect("get accelerations");
        rows.push(out.to_vec());
    }
    rows
}

/// Run `test` in a child process of this test binary with CPython available to FMUs:
/// libpython preloaded and PYTHONHOME set from target/third-party/python-runtime.env. In the
/// child (CHILD set) run `body` itself.
fn with_python_host(test: &str, body: impl FnOnce()) {
    if std::env::var_os(CHILD).is_some() {
        body();
        return;
    }
    let runtime = third_party("python-runtime.env");
    let text = std::fs::read_to_string(&runtime).expect("read python-runtime.env");
    let value = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| {
                panic!(
                    "{}: no {key}: run scripts/make-third-party-fmus.sh",
                    runtime.display()
                )
            })
            .to_owned()
    };
    let (library, home) = (value("LIBPYTHON"), value("PYTHONHOME"));
    assert!(
        Path::new(&library).is_file(),
        "{library} (from {}) does not exist",
        runtime.display()
    );
    let output = Command::new(std::env::current_exe().expect("the test binary"))
        .args([test, "--exact", "--nocapture", "--test-threads", "1"])
        .env(CHILD, "1")
        .env("LD_PRELOAD", &library)
        .env("PYTHONHOME", &home)
        .env("PYTHONNOUSERSITE", "1")
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("the test binary runs");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr),
    );
    assert!(
        output.status.success(),
        "{test} in a Python host: {:?}\nstdout:\n{stdout}\nstderr:\n{stderr}",
        output.status
    );
    // A filter that matched nothing would pass silently: make sure the test ran.
    assert!(
        stdout.contains(&format!("test {test} ... ok")) && stdout.contains("1 passed"),
        "{test} did not run in the child:\n{stdout}"
    );
    eprintln!("{stderr}");
}

#[test]
fn pythonfmu_low_pass_matches_its_exact_solution() {
    with_python_host("pythonfmu_low_pass_matches_its_exact_solution", || {
        let path = third_party("LowPass.fmu");
        let fmu = Fmu::open(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(fmu.model_description.model_identifier, "LowPass");
        assert!(!fmu.model_description.can_interpolate_inputs);
        // A non-default time constant, to see that parameters reach the Python object.
        let (gain, time_constant) = (2.0, 0.05);
        let mut instance = initialized(&fmu, "low_pass", &[("time_constant", time_constant)]);
        let (u, y) = (vrs(&fmu, &["u"]), vrs(&fmu, &["y"]));
        let mut out = [f64::NAN];
        instance.get_real(&y, &mut out).expect("get y");
        assert_eq!(out[0], 0.0, "y starts at rest");

        let h = 0.01;
        let decay = (-h / time_constant).exp();
        let (mut expected, mut rows, mut exact) = (0.0, Vec::new(), Vec::new());
        for k in 0..500 {
            let t = k as f64 * h;
            let input = 0.5 + (2.0 * std::f64::consts::PI * 1.3 * t).sin();
            instance.set_real(&u, &[input]).expect("set u");
            instance
                .do_step(t, h)
                .unwrap_or_else(|e| panic!("fmi2DoStep at t = {t}: {e}"));
            instance.get_real(&y, &mut out).expect("get y");
            expected = gain * input + (expected - gain * input) * decay;
            rows.push(vec![out[0]]);
            exact.push(vec![expected]);
        }
        // The FMU evaluates the same formula in Python (math.exp is the C library's exp, as is
        // f64::exp here): measured bit-identical. Bound 1e-12 of the peak.
        let deviation = relative_deviation(&rows, &exact)[0];
        eprintln!("LowPass.fmu against the exact solution: max |Δ| / max |y| = {deviation:e}");
        assert!(
            deviation <= 1e-12,
            "LowPass.fmu deviates from its exact solution by {deviation:e} of the peak"
        );
        // With the default time constant (0.1 s) the answer is far off: the parameter was used.
        let slow = 0.1f64;
        let mut other = 0.0;
        for k in 0..500 {
            let input = 0.5 + (2.0 * std::f64::consts::PI * 1.3 * k as f64 * h).sin();
            other = gain * input + (other - gain * input) * (-h / slow).exp();
        }
        assert!(
            (other - expected).abs() > 1e-3,
            "the time constant made no difference"
        );

        instance.terminate().expect("fmi2Terminate");

        // A step the Python model refuses (its do_step returns False: here a zero time constant)
        // comes back as an error, not a crash.
        let mut refusing = initialized(&fmu, "refusing", &[("time_constant", 0.0)]);
        let err = refusing
            .do_step(0.0, h)
            .expect_err("a zero time constant is refused");
        eprintln!("LowPass.fmu with time_constant 0: {err}");
        assert!(err.to_string().contains("fmi2DoStep"), "{err}");
    });
}

#[test]
fn pythonfmu_without_cpython_in_the_host_is_refused_not_a_crash() {
    // This test binary has no libpython (nothing Python is linked into it); run directly, the
    // FMU's library cannot be loaded, and that must be an error naming the file.
    if std::env::var_os("LD_PRELOAD").is_some_and(|p| p.to_string_lossy().contains("libpython")) {
        panic!("run without LD_PRELOAD=libpython: this test checks the error without it");
    }
    let path = third_party("LowPass.fmu");
    let err = match Fmu::open(&path) {
        Ok(_) => panic!("{} loaded without CPython in the process", path.display()),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains(path.to_str().expect("UTF-8")),
        "the message names the file: {err}"
    );
    assert!(
        err.contains("undefined symbol"),
        "the message says why: {err}"
    );
}

#[test]
fn a_container_of_the_shear_fmu_matches_the_shear_fmu_run_directly() {
    let path = third_party("shear_container.fmu");
    let container = Fmu::open(&path).unwrap_or_else(|e| panic!("{e}"));
    // The container neither interpolates inputs nor saves states; its ports are named as mapped.
    assert!(!container.model_description.can_interpolate_inputs);
    let mut instance = initialized(&container, "container", &[]);
    let (force_vr, acc) = (
        vrs(&container, &["force"]),
        vrs(&container, &["acc1", "acc2", "acc3"]),
    );
    let force = dataset1_force();
    let mut rows = Vec::new();
    for (k, value) in force[..force.len() - 1].iter().enumerate() {
        instance.set_real(&force_vr, &[*value]).expect("set force");
        instance
            .do_step(k as f64 * STEP, STEP)
            .unwrap_or_else(|e| panic!("container fmi2DoStep at step {k}: {e}"));
        let mut out = [0.0; 3];
        instance
            .get_real(&acc, &mut out)
            .expect("get accelerations");
        rows.push(out.to_vec());
    }
    instance.terminate().expect("fmi2Terminate");

    // The container calls the same library with the same values in the same order, and its
    // internal step, 5/256 s, is exact in binary: measured bit-identical. Bound 1e-12 of each
    // floor's peak.
    let direct = shear_held(&force);
    let deviation = relative_deviation(&rows, &direct);
    eprintln!(
        "container against the shear FMU run directly: max |Δ| / peak per floor = {deviation:?}"
    );
    for (floor, d) in deviation.iter().enumerate() {
        assert!(
            *d <= 1e-12,
            "acc{}: the container deviates by {d:e} of the peak",
            floor + 1
        );
    }
    // The container holds the force over each step, the orchestrator ramps it: the golden (ramps,
    // outputs read before each step) is far from these rows (measured 0.4–0.6 of the peak), so
    // the comparison above would see a container that interpolated or lagged.
    let golden = read_golden();
    let shifted: Vec<Vec<f64>> = golden[1..].to_vec();
    let apart = relative_deviation(&rows, &shifted);
    eprintln!("container against the golden (ramped force): {apart:?}");
    assert!(
        apart.iter().all(|d| *d > 0.05),
        "a held force should differ from a ramped one: {apart:?}"
    );
}

fn read_golden() -> Vec<Vec<f64>> {
    let path = workspace().join("tests/golden/shear_default_dataset1.csv");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .skip(1)
                .map(|f| f.trim().parse().expect("a number"))
                .collect()
        })
        .collect()
}

#[test]
fn a_sequential_container_of_the_shear_fmu_and_the_pythonfmu_low_pass_runs() {
    with_python_host(
        "a_sequential_container_of_the_shear_fmu_and_the_pythonfmu_low_pass_runs",
        || {
            let path = third_party("shear_low_pass.fmu");
            let container = Fmu::open(&path).unwrap_or_else(|e| panic!("{e}"));
            let mut instance = initialized(&container, "container", &[]);
            let (force_vr, out_vrs) = (
                vrs(&container, &["force"]),
                vrs(&container, &["acc1", "acc2", "acc3", "acc3_filtered"]),
            );
            let force = dataset1_force();
            let mut rows = Vec::new();
            for (k, value) in force[..force.len() - 1].iter().enumerate() {
                instance.set_real(&force_vr, &[*value]).expect("set force");
                instance
                    .do_step(k as f64 * STEP, STEP)
                    .unwrap_or_else(|e| panic!("container fmi2DoStep at step {k}: {e}"));
                let mut out = [0.0; 4];
                instance.get_real(&out_vrs, &mut out).expect("get outputs");
                rows.push(out.to_vec());
            }
            instance.terminate().expect("fmi2Terminate");

            // Sequential schedule: the shear FMU steps, then the low-pass steps with u = the acc3 just
            // computed, held over the step; the container set time_constant = 0.05 s, gain stays 2.
            let (gain, decay) = (2.0, (-STEP / 0.05f64).exp());
            let mut y = 0.0;
            let expected: Vec<Vec<f64>> = shear_held(&force)
                .into_iter()
                .map(|mut row| {
                    y = gain * row[2] + (y - gain * row[2]) * decay;
                    row.push(y);
                    row
                })
                .collect();
            let deviation = relative_deviation(&rows, &expected);
            eprintln!(
                "shear + LowPass container against the emulation: max |Δ| / peak = {deviation:?}"
            );
            // Measured bit-identical; bound 1e-12 of each signal's peak.
            for (j, d) in deviation.iter().enumerate() {
                assert!(
                    *d <= 1e-12,
                    "output {j}: the container deviates by {d:e} of the peak"
                );
            }
        },
    );
}
