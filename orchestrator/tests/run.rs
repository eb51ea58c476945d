//! `twin run` on FMUs the project's Rust code did not write, row by row against fmpy's
//! `simulate_fmu` on the same inputs (scripts/fmpy_run.py), and the importer's conformance.
//!
//! The C FMUs (tests/c-fmus, built by scripts/make-c-fmus.sh) exercise events, Integer,
//! Boolean, Enumeration and String variables, a resource file, an FMU that ends the run itself
//! and input interpolation; the fmu-manipulation-toolbox container (scripts/
//! make-third-party-fmus.sh) is a master of its own wrapped as an FMU. A missing file fails the
//! test with the command that makes it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use orchestrator::cosim::run::{run, RunOptions};
use orchestrator::import::{Fmu, ImportError};

mod common;
use common::{twin, twin_cmd, workspace};

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"))
}

fn c_fmu(name: &str) -> PathBuf {
    let path = target_dir().join("c-fmus").join(format!("{name}.fmu"));
    assert!(
        path.is_file(),
        "{} is missing: run scripts/make-c-fmus.sh",
        path.display()
    );
    path
}

fn python() -> PathBuf {
    let path = workspace().join(".venv/bin/python");
    assert!(
        path.is_file(),
        "{} is missing: run scripts/setup-python.sh",
        path.display()
    );
    path
}

fn twin_with_env(args: &[&str], env: &[(String, String)]) -> Output {
    twin_cmd()
        .args(args)
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .expect("twin runs")
}

/// What a non-Python host needs to run a pythonfmu FMU: libpython preloaded and PYTHONHOME
/// (target/third-party/python-runtime.env, written by scripts/make-third-party-fmus.sh).
fn python_runtime() -> Vec<(String, String)> {
    let path = target_dir().join("third-party/python-runtime.env");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}: run scripts/make-third-party-fmus.sh",
            path.display()
        )
    });
    let value = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| panic!("{}: no {key}", path.display()))
            .to_owned()
    };
    vec![
        ("LD_PRELOAD".to_owned(), value("LIBPYTHON")),
        ("PYTHONHOME".to_owned(), value("PYTHONHOME")),
    ]
}

fn ok(output: Output, what: &str) -> String {
    assert!(
        output.status.success(),
        "{what} failed: {}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn refused(output: Output, what: &str) -> String {
    assert!(
        !output.status.success(),
        "{what} should have been refused: {}",
        String::from_utf8_lossy(&output.stdout)
    );
    String::from_utf8_lossy(&output.stderr).into_owned()
}

struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn read(path: &Path) -> Table {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let header = reader
            .headers()
            .expect("a header")
            .iter()
            .map(str::to_owned)
            .collect();
        let rows = reader
            .records()
            .map(|r| r.expect("a row").iter().map(str::to_owned).collect())
            .collect();
        Table { header, rows }
    }

    fn column(&self, name: &str) -> Vec<f64> {
        let c = self
            .header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.header));
        self.rows
            .iter()
            .map(|r| r[c].parse().expect("a number"))
            .collect()
    }
}

/// Run `fmu` with `twin run` and with fmpy, the same arguments; the largest relative
/// difference over every value fmpy records (fmpy does not record Strings), after checking
/// that both have the same rows at the same times.
fn against_fmpy(fmu: &Path, twin_args: &[&str], fmpy_args: &[&str]) -> (Table, f64) {
    against_fmpy_with_env(fmu, twin_args, fmpy_args, &[])
}

fn against_fmpy_with_env(
    fmu: &Path,
    twin_args: &[&str],
    fmpy_args: &[&str],
    env: &[(String, String)],
) -> (Table, f64) {
    let dir = tempfile::tempdir().expect("temp dir");
    let ours = dir.path().join("twin.csv");
    let theirs = dir.path().join("fmpy.csv");
    let fmu_text = fmu.to_str().expect("utf-8 path");
    let mut args = vec!["run", fmu_text, "--output", ours.to_str().expect("utf-8")];
    args.extend_from_slice(twin_args);
    ok(twin_with_env(&args, env), "twin run");
    let mut command = Command::new(python());
    command
        .arg(workspace().join("scripts/fmpy_run.py"))
        .arg(fmu)
        .arg("--output")
        .arg(&theirs)
        .args(twin_args)
        .args(fmpy_args);
    ok(command.output().expect("python runs"), "fmpy_run.py");
    let (a, b) = (Table::read(&ours), Table::read(&theirs));
    assert_eq!(a.rows.len(), b.rows.len(), "{}: rows", fmu.display());
    for name in &b.header {
        assert!(
            a.header.contains(name),
            "{}: twin run lacks {name}",
            fmu.display()
        );
    }
    // The output order is modelDescription order; fmpy_run.py writes the same order.
    let ours_numeric: Vec<&String> = a.header.iter().filter(|h| b.header.contains(h)).collect();
    assert_eq!(
        ours_numeric,
        b.header.iter().collect::<Vec<_>>(),
        "column order"
    );
    assert_eq!(
        a.column("time"),
        b.column("time"),
        "{}: times",
        fmu.display()
    );
    let mut worst = 0.0f64;
    for name in &b.header {
        for (x, y) in a.column(name).iter().zip(b.column(name)) {
            if x.to_bits() != y.to_bits() {
                worst = worst.max((x - y).abs() / y.abs().max(1e-300));
            }
        }
    }
    (a, worst)
}

fn input(name: &str) -> String {
    workspace()
        .join("tests/c-fmus/inputs")
        .join(format!("{name}.csv"))
        .to_string_lossy()
        .into_owned()
}

#[test]
fn c_fmus_give_fmpys_rows_and_values_exactly() {
    // (FMU, its input file): every one of these declares no canInterpolateInputs, so both
    // hold the inputs over a step and must agree to the bit.
    for (name, with_input) in [
        ("BouncingBall", false),
        ("Discrete", true),
        ("Table", true),
        ("Stopper", true),
        ("NoInterp", true),
    ] {
        let file = input(name);
        let args: Vec<&str> = if with_input {
            vec!["--input", &file]
        } else {
            vec![]
        };
        let (table, worst) = against_fmpy(&c_fmu(name), &args, &[]);
        assert_eq!(
            worst, 0.0,
            "{name}: largest relative difference from fmpy {worst:e}"
        );
        assert!(table.rows.len() > 10, "{name}: {} rows", table.rows.len());
    }
}

#[test]
fn events_discrete_types_and_strings_come_through() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("discrete.csv");
    let file = input("Discrete");
    ok(
        twin(&[
            "run",
            c_fmu("Discrete").to_str().expect("utf-8"),
            "--input",
            &file,
            "--set",
            "prefix=n",
            "--output",
            out.to_str().expect("utf-8"),
        ]),
        "twin run Discrete",
    );
    let table = Table::read(&out);
    assert_eq!(
        table.header,
        ["time", "counter", "odd", "phase", "label", "time_seen"]
    );
    // The input's changes between grid points (0.45, 0.85) are communication points of their
    // own: the FMU handles variable steps, as fmpy does it.
    let time = table.column("time");
    assert!(time.contains(&0.45) && time.contains(&0.85), "{time:?}");
    let counter = table.column("counter");
    let odd = table.column("odd");
    let label_at = table
        .header
        .iter()
        .position(|h| h == "label")
        .expect("label");
    for (k, row) in table.rows.iter().enumerate() {
        assert_eq!(
            odd[k],
            (counter[k] as i64 % 2).abs() as f64,
            "Boolean as 0/1"
        );
        assert_eq!(
            row[label_at],
            format!("n={}", counter[k] as i64),
            "String output"
        );
    }
    let bounces = {
        let out = dir.path().join("ball.csv");
        ok(
            twin(&[
                "run",
                c_fmu("BouncingBall").to_str().expect("utf-8"),
                "--output",
                out.to_str().expect("utf-8"),
            ]),
            "twin run BouncingBall",
        );
        Table::read(&out).column("bounces")
    };
    assert!(
        bounces.windows(2).all(|w| w[1] >= w[0]),
        "bounces only rise"
    );
    assert!(*bounces.last().expect("rows") >= 5.0, "{bounces:?}");
}

#[test]
fn an_fmu_that_ends_the_run_ends_it_at_its_last_time() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("stopper.csv");
    let file = input("Stopper");
    let stdout = ok(
        twin(&[
            "run",
            c_fmu("Stopper").to_str().expect("utf-8"),
            "--input",
            &file,
            "--set",
            "stop_at=0.425",
            "--output",
            out.to_str().expect("utf-8"),
        ]),
        "twin run Stopper",
    );
    assert!(
        stdout.contains("ended the simulation itself at t = 0.425"),
        "{stdout}"
    );
    let time = Table::read(&out).column("time");
    assert_eq!(*time.last().expect("rows"), 0.425);
    assert_eq!(time.len(), 44, "0 … 0.42 by 0.01, then 0.425");
}

#[test]
fn inputs_are_interpolated_only_for_fmus_that_declare_it() {
    // NoInterp exports fmi2SetRealInputDerivatives but does not declare canInterpolateInputs;
    // called, it fails the run. Its integral is the held input's.
    let file = input("NoInterp");
    let (held, worst) = against_fmpy(&c_fmu("NoInterp"), &["--input", &file], &[]);
    assert_eq!(worst, 0.0);
    // Interp declares it: the piecewise-linear input is integrated exactly (0.475 at t = 1),
    // where holding it is not.
    let file = input("Interp");
    let (interpolated, worst) = against_fmpy(
        &c_fmu("Interp"),
        &["--input", &file],
        &["--set-input-derivatives"],
    );
    let exact = 0.475;
    let end = *interpolated.column("integral").last().expect("rows");
    assert!((end - exact).abs() < 1e-14, "∫u = {end}, exact {exact}");
    let held_end = *held.column("integral").last().expect("rows");
    assert!(
        (held_end - exact).abs() > 1e-3,
        "a held input is not exact: {held_end}"
    );
    // fmpy with set_input_derivatives: the same up to rounding (measured 1.2e-15; margin ×100).
    assert!(
        worst < 1e-13,
        "Interp: {worst:e} from fmpy with input derivatives"
    );
}

#[test]
fn a_container_made_by_another_tool_runs_as_under_fmpy() {
    let container = target_dir().join("third-party/shear_container.fmu");
    assert!(
        container.is_file(),
        "{} is missing: run scripts/make-third-party-fmus.sh",
        container.display()
    );
    // dataset1's force as the input file.
    let dir = tempfile::tempdir().expect("temp dir");
    let force = dir.path().join("force.csv");
    let data = std::fs::read_to_string(workspace().join("data/dataset1.csv")).expect("dataset1");
    let mut text = String::from("time,force\n");
    for line in data.lines().skip(1).take(257) {
        let fields: Vec<&str> = line.split(',').collect();
        text.push_str(&format!("{},{}\n", fields[0], fields[1]));
    }
    std::fs::write(&force, text).expect("write");
    let (table, worst) = against_fmpy(
        &container,
        &[
            "--input",
            force.to_str().expect("utf-8"),
            "--stop",
            "5",
            "--step",
            "0.01953125",
        ],
        &[],
    );
    assert_eq!(worst, 0.0, "shear_container: {worst:e} from fmpy");
    assert_eq!(table.rows.len(), 257);
    assert!(
        table.column("acc3").iter().any(|a| a.abs() > 1e-3),
        "the structure moved"
    );
}

#[test]
fn fmus_made_by_pythonfmu_and_by_a_sequential_container_run_as_under_fmpy() {
    let dir = tempfile::tempdir().expect("temp dir");
    // A step input and a ramp: u is held over each step by both hosts.
    let u = dir.path().join("u.csv");
    std::fs::write(&u, "time,u\n0,0\n0.25,1\n0.5,1\n1,-0.5\n").expect("write");
    let low_pass = target_dir().join("third-party/LowPass.fmu");
    assert!(
        low_pass.is_file(),
        "{} is missing: run scripts/make-third-party-fmus.sh",
        low_pass.display()
    );
    let (table, worst) = against_fmpy_with_env(
        &low_pass,
        &[
            "--input",
            u.to_str().expect("utf-8"),
            "--stop",
            "1",
            "--step",
            "0.01",
            "--set",
            "time_constant=0.05",
        ],
        &[],
        &python_runtime(),
    );
    assert_eq!(worst, 0.0, "LowPass: {worst:e} from fmpy");
    assert_eq!(table.rows.len(), 101);
    // The sequential container: the shear FMU's acc3 through LowPass inside one FMU.
    let container = target_dir().join("third-party/shear_low_pass.fmu");
    let force = dir.path().join("force.csv");
    std::fs::write(&force, "time,force\n0,0\n0.5,2\n1,-1\n2,0\n").expect("write");
    let (table, worst) = against_fmpy_with_env(
        &container,
        &[
            "--input",
            force.to_str().expect("utf-8"),
            "--stop",
            "2",
            "--step",
            "0.01953125",
        ],
        &[],
        &python_runtime(),
    );
    assert_eq!(worst, 0.0, "shear_low_pass: {worst:e} from fmpy");
    assert!(table.column("acc3_filtered").iter().any(|a| a.abs() > 1e-6));
}

#[test]
fn the_configuration_is_checked_before_any_fmu_is_loaded() {
    let fmu = c_fmu("Discrete");
    let fmu = fmu.to_str().expect("utf-8");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--set", "prefx=a"], "closest: prefix"),
        (vec!["--set", "increment=1.5"], "is not an Integer"),
        (vec!["--set", "enable=maybe"], "is not a Boolean"),
        (vec!["--set", "phase=2"], "cannot be given a start value"),
        (vec!["--set", "increment"], "expected NAME=VALUE"),
        (vec!["--step", "0"], "positive"),
        (vec!["--step", "-0.1"], "positive"),
        (
            vec!["--start", "1", "--stop", "0.5"],
            "not after the start time",
        ),
    ];
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.csv");
    let out = out.to_str().expect("utf-8");
    for (extra, expected) in cases {
        let mut args = vec!["run", fmu, "--output", out];
        args.extend_from_slice(&extra);
        let stderr = refused(twin(&args), &format!("{extra:?}"));
        assert!(stderr.contains(expected), "{extra:?}: {stderr}");
    }
    // An input file naming something that is not an input: the file, the line, the closest.
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "time,incremnt\n0,1\n").expect("write");
    let stderr = refused(
        twin(&[
            "run",
            fmu,
            "--input",
            bad.to_str().expect("utf-8"),
            "--output",
            out,
        ]),
        "bad column",
    );
    assert!(
        stderr.contains("bad.csv: line 1") && stderr.contains("closest: increment"),
        "{stderr}"
    );
    std::fs::write(&bad, "time,increment\n0,1\n0.5,x\n").expect("write");
    let stderr = refused(
        twin(&[
            "run",
            fmu,
            "--input",
            bad.to_str().expect("utf-8"),
            "--output",
            out,
        ]),
        "bad value",
    );
    assert!(
        stderr.contains("line 3") && stderr.contains("'x'"),
        "{stderr}"
    );
    assert!(
        !Path::new(out).exists(),
        "nothing is written when the run is refused"
    );
}

#[test]
fn an_error_status_stops_the_run_with_the_time_the_file_and_the_fmus_messages() {
    // A storey far too stiff for one RK4 sub-step per 0.1 s: the shear model's state grows
    // without bound and its step fails with fmi2Error.
    let shear = common::fmu_dir().join("fmu_shear.fmu");
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.csv");
    let stderr = refused(
        twin(&[
            "run",
            shear.to_str().expect("utf-8"),
            "--set",
            "k1=1e12",
            "--set",
            "substeps=1",
            "--set",
            "force=1",
            "--stop",
            "100",
            "--step",
            "0.1",
            "--output",
            out.to_str().expect("utf-8"),
        ]),
        "a diverging run",
    );
    assert!(stderr.contains("at t = "), "the time: {stderr}");
    assert!(stderr.contains("fmu_shear.fmu"), "the file: {stderr}");
    assert!(
        stderr.contains("fmi2DoStep fmi2Error: ") && stderr.contains("diverged"),
        "the call and the FMU's messages: {stderr}"
    );
    assert!(!out.exists(), "no partial output");
}

/// Rewrite the archive `from` into `to` with `edit` applied to its entries.
fn rezip(from: &Path, to: &Path, edit: impl Fn(Vec<(String, Vec<u8>)>) -> Vec<(String, Vec<u8>)>) {
    use std::io::{Read, Write};
    let mut archive = zip::ZipArchive::new(std::fs::File::open(from).expect("open")).expect("zip");
    let mut entries = Vec::new();
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).expect("entry");
        if entry.is_dir() {
            continue;
        }
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).expect("read");
        entries.push((entry.name().to_owned(), bytes));
    }
    let mut writer = zip::ZipWriter::new(std::fs::File::create(to).expect("create"));
    for (name, bytes) in edit(entries) {
        writer
            .start_file(name, zip::write::SimpleFileOptions::default())
            .expect("start");
        writer.write_all(&bytes).expect("write");
    }
    writer.finish().expect("finish");
}

#[test]
fn a_refused_instantiation_names_the_fmu_and_carries_its_log() {
    let dir = tempfile::tempdir().expect("temp dir");
    let broken = dir.path().join("TableWithoutItsFile.fmu");
    rezip(&c_fmu("Table"), &broken, |entries| {
        entries
            .into_iter()
            .filter(|(name, _)| !name.ends_with("table.csv"))
            .collect()
    });
    let fmu = Fmu::open(&broken).expect("the archive itself is sound");
    let err = fmu.instantiate("table").err().expect("refused");
    let message = err.to_string();
    assert!(
        matches!(
            err,
            ImportError::Call {
                call: "fmi2Instantiate",
                ..
            }
        ),
        "{err:?}"
    );
    assert!(
        message.contains("TableWithoutItsFile.fmu"),
        "names the .fmu: {message}"
    );
    assert!(
        message.contains("table.csv"),
        "carries the FMU's log: {message}"
    );
}

#[test]
fn no_binary_for_this_platform_says_what_the_platform_folder_holds() {
    let dir = tempfile::tempdir().expect("temp dir");
    let wrong = dir.path().join("Renamed.fmu");
    rezip(&c_fmu("Table"), &wrong, |entries| {
        entries
            .into_iter()
            .map(|(name, bytes)| {
                (
                    name.replace("binaries/linux64/Table.so", "binaries/linux64/Other.so"),
                    bytes,
                )
            })
            .collect()
    });
    let err = Fmu::open(&wrong).err().expect("refused").to_string();
    assert!(
        err.contains("binaries/linux64/ is there but has no Table.so") && err.contains("Other.so"),
        "{err}"
    );
    let none = dir.path().join("NoPlatform.fmu");
    rezip(&c_fmu("Table"), &none, |entries| {
        entries
            .into_iter()
            .map(|(name, bytes)| {
                (
                    name.replace("binaries/linux64/", "binaries/darwin64/"),
                    bytes,
                )
            })
            .collect()
    });
    let err = Fmu::open(&none).err().expect("refused").to_string();
    assert!(err.contains("platforms present: darwin64"), "{err}");
}

#[test]
fn resources_are_found_under_paths_that_need_percent_encoding() {
    let reference = run(&c_fmu("Table"), &RunOptions::default(), |_, _| {}).expect("runs");
    let dir = tempfile::tempdir().expect("temp dir");
    let odd = dir.path().join("a dir %25 #1 ?x é");
    std::fs::create_dir_all(&odd).expect("mkdir");
    let copy = odd.join("Table.fmu");
    std::fs::copy(c_fmu("Table"), &copy).expect("copy");
    // The FMU is unpacked into a temporary directory; run it from one whose name needs every
    // escape too, by pointing TMPDIR there in a child process.
    let out = odd.join("out.csv");
    let output = twin_cmd()
        .env("TMPDIR", &odd)
        .args([
            "run",
            copy.to_str().expect("utf-8"),
            "--output",
            out.to_str().expect("utf-8"),
        ])
        .output()
        .expect("twin runs");
    ok(output, "twin run Table from an odd directory");
    let table = Table::read(&out);
    assert_eq!(
        table.column("y"),
        reference.column("y").expect("y").to_vec()
    );
}

/// Resident memory (kB) and open file descriptors of this process.
fn footprint() -> (u64, usize) {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let rss = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS");
    let fds = std::fs::read_dir("/proc/self/fd")
        .expect("/proc/self/fd")
        .count();
    (rss, fds)
}

/// Set in the child process that measures the load cycles alone.
const CYCLES_CHILD: &str = "TWIN_RUN_CYCLES_CHILD";

#[test]
fn ten_thousand_load_instantiate_free_unload_cycles_leak_nothing() {
    // Open files and memory are the process's: the other tests of this binary, running in
    // parallel, open and close files too. So the cycles run in a child process of this test
    // binary that runs this test alone.
    if std::env::var_os(CYCLES_CHILD).is_none() {
        let output = Command::new(std::env::current_exe().expect("the test binary"))
            .args([
                "ten_thousand_load_instantiate_free_unload_cycles_leak_nothing",
                "--exact",
                "--test-threads=1",
                "--nocapture",
            ])
            .env(CYCLES_CHILD, "1")
            .output()
            .expect("the child runs");
        let stdout = ok(output, "the load cycles in a child process");
        assert!(
            stdout.contains("10,000 cycles: open files") && stdout.contains("1 passed"),
            "the child ran the cycles: {stdout}"
        );
        return;
    }
    let path = c_fmu("NoInterp");
    let cycle = || {
        let fmu = Fmu::open(&path).expect("opens");
        let mut instance = fmu.instantiate("cycle").expect("instantiates");
        instance.setup_experiment(0.0, None).expect("setup");
        drop(instance);
        drop(fmu);
    };
    for _ in 0..500 {
        cycle();
    }
    let (rss0, fds0) = footprint();
    for _ in 0..10_000 {
        cycle();
    }
    let (rss1, fds1) = footprint();
    assert_eq!(fds1, fds0, "open files after 10,000 cycles");
    // Measured: 5360 → 5360 kB; the bound leaves 8 MiB for allocator noise, and a leak of one
    // unpacked FMU (~20 kB) or one instance per cycle would be ≥ 200 MB.
    assert!(
        rss1 < rss0 + 8 * 1024,
        "resident memory grew from {rss0} kB to {rss1} kB over 10,000 cycles"
    );
    println!("10,000 cycles: open files {fds0} → {fds1}, resident memory {rss0} → {rss1} kB");
}

/// An SSP archive: `SystemStructure.ssd` and the given files (the FMUs, `.ssv` sets).
fn write_ssp(path: &Path, ssd: &str, files: &[(&str, Vec<u8>)]) {
    use std::io::Write;
    let mut writer = zip::ZipWriter::new(std::fs::File::create(path).expect("create"));
    let options = zip::write::SimpleFileOptions::default();
    writer
        .start_file("SystemStructure.ssd", options)
        .expect("start");
    writer.write_all(ssd.as_bytes()).expect("write");
    for (name, bytes) in files {
        writer.start_file(*name, options).expect("start");
        writer.write_all(bytes).expect("write");
    }
    writer.finish().expect("finish");
}

const BALL_AND_GAIN: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="ball-and-gain">
  <ssd:System name="ball-and-gain">
    <ssd:Connectors>
      <ssd:Connector name="offset" kind="input"><ssc:Real/></ssd:Connector>
      <ssd:Connector name="height" kind="output"><ssc:Real/></ssd:Connector>
    </ssd:Connectors>
    <ssd:Elements>
      <ssd:Component name="ball" type="application/x-fmu-sharedlibrary" source="resources/BouncingBall.fmu">
        <ssd:Connectors>
          <ssd:Connector name="h" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding source="resources/ball.ssv"/></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="gain" type="application/x-fmu-sharedlibrary" source="resources/NoInterp.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="shifted" type="application/x-fmu-sharedlibrary" source="resources/Table.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="ball" startConnector="h" endElement="gain" endConnector="u"/>
      <ssd:Connection startElement="ball" startConnector="h" endConnector="height"/>
      <ssd:Connection startConnector="offset" endElement="shifted" endConnector="u"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="2"/>
</ssd:SystemStructureDescription>
"#;

const BALL_SSV: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="ball">
  <ssv:Parameters>
    <ssv:Parameter name="e"><ssv:Real value="0.5"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"#;

#[test]
fn ssp_systems_run_with_connections_bindings_and_system_inputs() {
    let dir = tempfile::tempdir().expect("temp dir");
    let ssp = dir.path().join("system.ssp");
    let read = |name: &str| std::fs::read(c_fmu(name)).expect("read");
    write_ssp(
        &ssp,
        BALL_AND_GAIN,
        &[
            ("resources/BouncingBall.fmu", read("BouncingBall")),
            ("resources/NoInterp.fmu", read("NoInterp")),
            ("resources/Table.fmu", read("Table")),
            ("resources/ball.ssv", BALL_SSV.as_bytes().to_vec()),
        ],
    );
    let offset = dir.path().join("offset.csv");
    std::fs::write(&offset, "time,offset\n0,0\n2,4\n").expect("write");
    let out = dir.path().join("system.csv");
    ok(
        twin(&[
            "run",
            ssp.to_str().expect("utf-8"),
            "--step",
            "0.01",
            "--input",
            offset.to_str().expect("utf-8"),
            "--output",
            out.to_str().expect("utf-8"),
        ]),
        "twin run system.ssp",
    );
    let system = Table::read(&out);
    assert_eq!(
        system.header,
        [
            "time",
            "ball.h",
            "ball.v",
            "ball.bounces",
            "gain.y",
            "gain.integral",
            "shifted.y",
            "shifted.y_plus_u"
        ]
    );
    // The binding's e = 0.5: the ball alone with --set e=0.5 gives the same heights.
    let alone = dir.path().join("alone.csv");
    ok(
        twin(&[
            "run",
            c_fmu("BouncingBall").to_str().expect("utf-8"),
            "--set",
            "e=0.5",
            "--stop",
            "2",
            "--step",
            "0.01",
            "--output",
            alone.to_str().expect("utf-8"),
        ]),
        "twin run BouncingBall",
    );
    let h = system.column("ball.h");
    assert_eq!(h, Table::read(&alone).column("h"), "the bound restitution");
    // The connection: gain.u = ball.h, applied at each point after it is recorded, so the
    // recorded gain.y = 3·h one point earlier (the first point is after the inputs).
    let y = system.column("gain.y");
    assert_eq!(y[0], 3.0 * h[0]);
    for k in 1..h.len() {
        assert_eq!(y[k], 3.0 * h[k - 1], "point {k}");
    }
    // The system input `offset` drives shifted.u: y_plus_u − y is the offset ramp, 2t, one
    // point late.
    let (t, shifted, plus) = (
        system.column("time"),
        system.column("shifted.y"),
        system.column("shifted.y_plus_u"),
    );
    for k in 1..t.len() {
        assert!(
            (plus[k] - shifted[k] - 2.0 * t[k - 1]).abs() < 1e-12,
            "point {k}"
        );
    }
    // --set overrides the binding, by component.variable; a wrong name gets the closest.
    let changed = dir.path().join("changed.csv");
    ok(
        twin(&[
            "run",
            ssp.to_str().expect("utf-8"),
            "--set",
            "ball.e=0.8",
            "--output",
            changed.to_str().expect("utf-8"),
        ]),
        "twin run --set ball.e",
    );
    assert_ne!(Table::read(&changed).column("ball.h"), h);
    let stderr = refused(
        twin(&[
            "run",
            ssp.to_str().expect("utf-8"),
            "--set",
            "bal.e=0.8",
            "--output",
            changed.to_str().expect("utf-8"),
        ]),
        "a misspelt component",
    );
    assert!(stderr.contains("closest: ball.e"), "{stderr}");
}

#[test]
fn output_all_records_the_locals_too() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (outputs, all) = (dir.path().join("outputs.csv"), dir.path().join("all.csv"));
    let ball = c_fmu("BouncingBall");
    let ball = ball.to_str().expect("utf-8");
    ok(
        twin(&["run", ball, "--output", outputs.to_str().expect("utf-8")]),
        "twin run",
    );
    ok(
        twin(&[
            "run",
            ball,
            "--output-all",
            "--output",
            all.to_str().expect("utf-8"),
        ]),
        "twin run --output-all",
    );
    assert_eq!(Table::read(&outputs).header, ["time", "h", "v", "bounces"]);
    let all = Table::read(&all);
    assert_eq!(all.header, ["time", "h", "v", "bounces", "energy"]);
    let (h, v, energy) = (all.column("h"), all.column("v"), all.column("energy"));
    for k in 0..h.len() {
        assert_eq!(
            energy[k],
            9.81 * h[k] + 0.5 * v[k] * v[k],
            "the local at row {k}"
        );
    }
}

#[test]
fn an_ssp_reaching_outside_its_archive_or_naming_a_component_twice_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let ball = std::fs::read(c_fmu("BouncingBall")).expect("read");
    let outside = c_fmu("BouncingBall");
    let cases = [
        (
            outside.to_str().expect("utf-8").to_owned(),
            "is not in the archive",
        ),
        (
            "resources/../resources/BouncingBall.fmu".to_owned(),
            "is not in the archive",
        ),
        (
            "file:///tmp/BouncingBall.fmu".to_owned(),
            "is not in the archive",
        ),
    ];
    for (source, expected) in cases {
        let ssd = format!(
            r#"<SystemStructureDescription version="1.0" name="s"><System name="s"><Elements>
               <Component name="ball" source="{source}"/></Elements></System></SystemStructureDescription>"#
        );
        let ssp = dir.path().join("outside.ssp");
        write_ssp(&ssp, &ssd, &[("resources/BouncingBall.fmu", ball.clone())]);
        let out = dir.path().join("out.csv");
        let stderr = refused(
            twin(&[
                "run",
                ssp.to_str().expect("utf-8"),
                "--output",
                out.to_str().expect("utf-8"),
            ]),
            &source,
        );
        assert!(stderr.contains(expected), "{source}: {stderr}");
    }
    let twice = r#"<SystemStructureDescription version="1.0" name="s"><System name="s"><Elements>
        <Component name="ball" source="resources/BouncingBall.fmu"/>
        <Component name="ball" source="resources/BouncingBall.fmu"/></Elements></System></SystemStructureDescription>"#;
    let ssp = dir.path().join("twice.ssp");
    write_ssp(&ssp, twice, &[("resources/BouncingBall.fmu", ball)]);
    let out = dir.path().join("out.csv");
    let stderr = refused(
        twin(&[
            "run",
            ssp.to_str().expect("utf-8"),
            "--output",
            out.to_str().expect("utf-8"),
        ]),
        "two components named ball",
    );
    assert!(
        stderr.contains("two components are named 'ball'"),
        "{stderr}"
    );
}

#[test]
fn the_shear_fmu_held_is_fmpys_to_the_bit_and_with_slopes_is_twin_compares() {
    // The shear FMU declares canInterpolateInputs: by default twin run sends the force's slope
    // over each step; fmpy's simulate_fmu holds it.
    let dir = tempfile::tempdir().expect("temp dir");
    let record = workspace().join("data/dataset1.csv");
    let force = dir.path().join("force.csv");
    let data = std::fs::read_to_string(&record).expect("dataset1");
    // The record's times are printed to 1 µs; its samples are on the 1/51.2 s grid, which is
    // written exactly here, so that no resampling moves them.
    let mut text = String::from("time,force\n");
    for (k, line) in data.lines().skip(1).enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        text.push_str(&format!("{},{}\n", k as f64 / 51.2, fields[1]));
    }
    std::fs::write(&force, text).expect("write");
    let measurement = orchestrator::data::Measurement::read(&record).expect("dataset1 reads");
    let stop = format!("{}", (measurement.len() - 1) as f64 / 51.2);
    let shear = common::fmu_dir().join("fmu_shear.fmu");
    let shear = shear.to_str().expect("utf-8");
    let args = [
        "--input",
        force.to_str().expect("utf-8"),
        "--stop",
        &stop,
        "--step",
        "0.01953125",
    ];
    let run_to = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut all = vec!["run", shear, "--output", out.to_str().expect("utf-8")];
        all.extend_from_slice(&args);
        all.extend_from_slice(extra);
        ok(twin(&all), name);
        Table::read(&out)
    };
    // Held: fmpy's rows, to the bit.
    let held = run_to("held.csv", &["--hold-inputs"]);
    let theirs = dir.path().join("fmpy.csv");
    let mut command = Command::new(python());
    command
        .arg(workspace().join("scripts/fmpy_run.py"))
        .arg(shear)
        .arg("--output")
        .arg(&theirs)
        .args(args);
    ok(command.output().expect("python runs"), "fmpy_run.py");
    let fmpy = Table::read(&theirs);
    for name in ["acc1", "acc2", "acc3", "disp1", "vel2", "drift3"] {
        assert_eq!(
            held.column(name),
            fmpy.column(name),
            "{name}: held inputs, bit for bit"
        );
    }
    // With slopes, the step ends with the input at its end value, so a point's outputs, read
    // before its input is applied, are those twin compare reads after applying it: the
    // default twin's predictions on the record, up to the rounding of that end value (u_k +
    // u̇·h against u_{k+1}: measured 57 of 1024 values of acc1 apart, by one or two units in
    // the last place; the bound is 1e-13 of the largest acceleration).
    let sloped = run_to("sloped.csv", &[]);
    let init = dir.path().join("default.ssp");
    ok(
        twin_cmd()
            .args(["init", "--out", init.to_str().expect("utf-8")])
            .output()
            .expect("twin init"),
        "twin init",
    );
    let default_twin = orchestrator::twin::Twin::read(&init).expect("the default twin reads");
    let predicted =
        orchestrator::run::run_twin(&default_twin, &measurement, |_, _| {}).expect("run_twin");
    for (f, name) in ["acc1", "acc2", "acc3"].iter().enumerate() {
        let ours = sloped.column(name);
        assert_eq!(ours.len(), predicted.acc(f).len(), "{name}: points");
        let peak = predicted.acc(f).iter().fold(0.0f64, |m, a| m.max(a.abs()));
        for (k, (a, b)) in ours.iter().zip(predicted.acc(f)).enumerate() {
            assert!(
                (a - b).abs() <= 1e-13 * peak,
                "{name} at point {k}: {a} against {b}"
            );
        }
    }
    assert_ne!(held.column("acc1"), sloped.column("acc1"));
}
