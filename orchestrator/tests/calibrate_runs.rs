//! `twin calibrate` on any building, over several runs each with its own sensors, through the
//! CLI: a roving accelerometer on the paper's rig (three runs, one floor each) calibrated as one
//! MAP; a five-storey building under ground motion with accelerometers in g on three floors,
//! its twin initialised from a nominal 10–20 % off; priors files refused naming the key; a
//! record the structure cannot use refused before any work.

use std::path::Path;
use std::process::Output;

use serde_json::Value;

mod common;
use common::{fmu_dir, twin};

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "twin failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
}

fn p(dir: &Path, name: &str) -> String {
    dir.join(name).display().to_string()
}

fn json(path: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("report")).expect("JSON")
}

/// The MAP of each parameter in a calibrate report, by name.
fn map_values(report: &Value) -> std::collections::BTreeMap<String, f64> {
    report["parameters"]
        .as_array()
        .expect("parameters")
        .iter()
        .map(|p| {
            (
                p["name"].as_str().expect("name").to_owned(),
                p["value"].as_f64().expect("value"),
            )
        })
        .collect()
}

/// The CSV at `from` with only the columns `keep` (in that order).
fn keep_columns(from: &str, to: &str, keep: &[&str]) {
    let text = std::fs::read_to_string(from).expect("csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let at: Vec<usize> = keep
        .iter()
        .map(|k| {
            header
                .iter()
                .position(|h| h.trim() == *k)
                .unwrap_or_else(|| panic!("{from} has no column {k}"))
        })
        .collect();
    let mut out = keep.join(",") + "\n";
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        out += &at.iter().map(|&i| fields[i]).collect::<Vec<_>>().join(",");
        out.push('\n');
    }
    std::fs::write(to, out).expect("write");
}

/// Relative error of the MAP against the truth, per parameter, for `names`.
fn errors(
    map: &std::collections::BTreeMap<String, f64>,
    truth: &Value,
    names: &[&str],
) -> Vec<f64> {
    names
        .iter()
        .map(|name| {
            let (family, i) = name.split_at(1);
            let i: usize = i.parse::<usize>().expect("index") - 1;
            let t = truth["structure"][family][i].as_f64().expect("truth");
            (map[*name] - t).abs() / t
        })
        .collect()
}

/// Three runs of synth's paper rig (seeds 1, 2, 3), the accelerometer moved to floor 1, 2, 3:
/// each record only `time,force,acc<i>`. One MAP over the three recovers every mass and
/// stiffness; and a fourth full record (seed 4) is predicted on every floor at its noise level.
///
/// Measured: three runs, largest relative error of m1..m3, k1..k3 against the truth 0.0011
/// (k2), of c1..c3 0.014; each run's NMSE on its own channel 0.089 / 0.094 / 0.095 %; on seed
/// 4's acc1/acc2/acc3 0.087 / 0.086 / 0.076 % (its noise is 3 % of RMS, about 0.09 % NMSE).
/// Floor 1 alone (the shaker's floor, where all three modes show) is not visibly worse on
/// floors 2 and 3 here: 0.088 / 0.088 / 0.079 % on seed 4, m and k within 0.0033. What one run
/// lacks is data: its posterior sds are 1.78× (m2) to 5.2× (m3) the three runs'.
/// Thresholds: 2 % on m and k (18×), 20 % on c (14×), the NMSEs below 0.2 % (2×), every
/// posterior sd of one run above 1.3× the three runs' (measured at least 1.78×).
#[test]
fn roving_accelerometer_runs_calibrate_every_floor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let mut runs = Vec::new();
    for seed in 1..=4 {
        ok(&twin(&[
            "synth",
            "--seed",
            &seed.to_string(),
            "--out",
            &p(d, &format!("full{seed}.csv")),
            "--truth",
            &p(d, &format!("truth{seed}.json")),
        ]));
        if seed <= 3 {
            let acc = format!("acc{seed}");
            let run = p(d, &format!("run{seed}.csv"));
            keep_columns(
                &p(d, &format!("full{seed}.csv")),
                &run,
                &["time", "force", &acc],
            );
            runs.push(run);
        }
    }
    let truth = json(&p(d, "truth1.json"));
    let full4 = p(d, "full4.csv");

    let mut args = vec!["calibrate", "--data"];
    args.extend(runs.iter().map(String::as_str));
    let (out, report) = (p(d, "roving.ssp"), p(d, "roving.json"));
    args.extend(["--out", &out, "--report", &report, "--validate", &full4]);
    let o = twin(&args);
    ok(&o);
    println!("{}", String::from_utf8_lossy(&o.stdout));
    let roving = json(&report);
    let map = map_values(&roving);
    let mk = errors(&map, &truth, &["m1", "m2", "m3", "k1", "k2", "k3"]);
    let c = errors(&map, &truth, &["c1", "c2", "c3"]);
    println!("roving: m, k relative errors {mk:.4?}, c {c:.4?}");
    assert!(mk.iter().all(|e| *e < 0.02), "m, k relative errors {mk:?}");
    assert!(c.iter().all(|e| *e < 0.2), "c relative errors {c:?}");
    // Each run's NMSE by its own channel's name.
    let runs_report = roving["runs"].as_array().expect("runs");
    assert_eq!(runs_report.len(), 3);
    for (i, r) in runs_report.iter().enumerate() {
        let by_channel = r["nmse"].as_object().expect("nmse by channel");
        let acc = format!("acc{}", i + 1);
        assert_eq!(by_channel.keys().collect::<Vec<_>>(), vec![&acc], "{r}");
        assert!(by_channel[&acc].as_f64().expect("nmse") < 0.2, "{r}");
    }
    let roving_on_4: Vec<f64> = roving["validation"][0]["nmse"]
        .as_array()
        .expect("validation nmse")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    println!("roving on seed 4: NMSE % {roving_on_4:?}");
    assert!(roving_on_4.iter().all(|n| *n < 0.2), "{roving_on_4:?}");

    let (out1, report1) = (p(d, "floor1.ssp"), p(d, "floor1.json"));
    ok(&twin(&[
        "calibrate",
        "--data",
        &runs[0],
        "--out",
        &out1,
        "--report",
        &report1,
        "--validate",
        &full4,
    ]));
    let single = json(&report1);
    let single_on_4: Vec<f64> = single["validation"][0]["nmse"]
        .as_array()
        .expect("validation nmse")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    let single_mk = errors(
        &map_values(&single),
        &truth,
        &["m1", "m2", "m3", "k1", "k2", "k3"],
    );
    println!("floor 1 alone on seed 4: NMSE % {single_on_4:?}; m, k errors {single_mk:.4?}");
    // One run alone sees the three modes in floor 1's response too (the force is there), so
    // it also predicts the other floors; what it lacks is data: its posterior is wider.
    let sds = |report: &Value| -> std::collections::BTreeMap<String, f64> {
        report["parameters"]
            .as_array()
            .expect("parameters")
            .iter()
            .map(|p| {
                (
                    p["name"].as_str().expect("name").to_owned(),
                    p["sd"].as_f64().expect("sd"),
                )
            })
            .collect()
    };
    let (sd3, sd1) = (sds(&roving), sds(&single));
    let ratios: Vec<(String, f64)> = sd3.keys().map(|k| (k.clone(), sd1[k] / sd3[k])).collect();
    println!("posterior sd, one run over three: {ratios:.2?}");
    const SD_RATIO: f64 = 1.3;
    for (name, ratio) in &ratios {
        assert!(
            *ratio > SD_RATIO,
            "{name}: one run's sd only {ratio:.2}× three runs'"
        );
    }
}

/// A shear building's response to ground acceleration, integrated here independently of the
/// twin: `M ÿ + C ẏ + K y = −M 1 a_g` in relative coordinates, classic RK4 at `fine` steps per
/// sample with the ground acceleration interpolated linearly; the absolute accelerations
/// `ÿ + a_g` of every floor at the samples.
fn base_excited(
    m: &[f64],
    c: &[f64],
    k: &[f64],
    ag: &[f64],
    dt: f64,
    fine: usize,
) -> Vec<Vec<f64>> {
    let n = m.len();
    // Storey i joins floor i-1 (the ground for i = 0) and floor i.
    let accel = |y: &[f64], v: &[f64], a_g: f64| -> Vec<f64> {
        (0..n)
            .map(|i| {
                let below = |x: &[f64]| if i == 0 { 0.0 } else { x[i - 1] };
                let mut f = -k[i] * (y[i] - below(y)) - c[i] * (v[i] - below(v));
                if i + 1 < n {
                    f += k[i + 1] * (y[i + 1] - y[i]) + c[i + 1] * (v[i + 1] - v[i]);
                }
                f / m[i] - a_g
            })
            .collect()
    };
    let (mut y, mut v) = (vec![0.0; n], vec![0.0; n]);
    let mut out = vec![Vec::with_capacity(ag.len()); n];
    let h = dt / fine as f64;
    for s in 0..ag.len() {
        let a = accel(&y, &v, ag[s]);
        for f in 0..n {
            out[f].push(a[f] + ag[s]);
        }
        if s + 1 == ag.len() {
            break;
        }
        for j in 0..fine {
            let g = |t: f64| ag[s] + (ag[s + 1] - ag[s]) * t;
            let (t0, t1) = (j as f64 / fine as f64, (j + 1) as f64 / fine as f64);
            let tm = 0.5 * (t0 + t1);
            let add = |x: &[f64], d: &[f64], w: f64| -> Vec<f64> {
                x.iter().zip(d).map(|(a, b)| a + w * b).collect()
            };
            let k1v = accel(&y, &v, g(t0));
            let k1y = v.clone();
            let k2v = accel(&add(&y, &k1y, h / 2.0), &add(&v, &k1v, h / 2.0), g(tm));
            let k2y = add(&v, &k1v, h / 2.0);
            let k3v = accel(&add(&y, &k2y, h / 2.0), &add(&v, &k2v, h / 2.0), g(tm));
            let k3y = add(&v, &k2v, h / 2.0);
            let k4v = accel(&add(&y, &k3y, h), &add(&v, &k3v, h), g(t1));
            let k4y = add(&v, &k3v, h);
            for i in 0..n {
                y[i] += h / 6.0 * (k1y[i] + 2.0 * k2y[i] + 2.0 * k3y[i] + k4y[i]);
                v[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
            }
        }
    }
    out
}

/// A five-storey building under ground motion, accelerometers on floors 1, 3 and 5 reading in
/// g, 3 % noise: its twin from `twin init --storeys 5 --excitation base --nominal` with the
/// stiffnesses 10–20 % off (masses as built, dampings a guess) calibrates the stiffnesses back.
///
/// Measured (4 starts): every stiffness 0.25–0.38 % low (nominal errors 10–20 %): masses and
/// stiffnesses scale together under ground motion and the mass prior (sd 10 % about the
/// nominal) holds the scale; NMSE 0.086 % on each of acc1, acc3, acc5 (noise 3 % of RMS).
/// Thresholds: 3 % on every stiffness (8×), each a quarter of its nominal error or less; NMSE
/// below 0.3 % per channel (3.5×).
#[test]
fn five_storeys_under_ground_motion_with_three_sensors_in_g() {
    use rand::{rngs::StdRng, Rng, SeedableRng};
    use rand_distr::StandardNormal;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let m = [6.0, 5.5, 5.0, 4.5, 4.0];
    let c = [3.0, 2.5, 2.5, 2.0, 2.0];
    let k = [5200.0, 4800.0, 4400.0, 4000.0, 3600.0];
    // The drawings' stiffnesses: 10–20 % off, both ways.
    let off = [1.15, 0.85, 1.2, 0.9, 1.1];
    let nominal_k: Vec<f64> = k.iter().zip(off).map(|(k, o)| k * o).collect();
    let nominal = serde_json::json!({"m": m, "c": vec![1.0; 5], "k": nominal_k});
    std::fs::write(d.join("nominal.json"), nominal.to_string()).expect("write");

    // 30 s at 200 Hz of ground acceleration: a random-phase multisine 0.3–25 Hz, RMS 0.5 m/s².
    let (rate, seconds) = (200.0, 30.0);
    let dt = 1.0 / rate;
    let samples = (seconds * rate) as usize + 1;
    let mut rng = StdRng::seed_from_u64(7);
    let tones: Vec<(f64, f64)> = (3..=250)
        .map(|i| (0.1 * i as f64, rng.gen::<f64>() * std::f64::consts::TAU))
        .collect();
    let mut ag: Vec<f64> = (0..samples)
        .map(|s| {
            let t = s as f64 * dt;
            tones
                .iter()
                .map(|(f, phase)| (std::f64::consts::TAU * f * t + phase).sin())
                .sum()
        })
        .collect();
    let rms = (ag.iter().map(|x| x * x).sum::<f64>() / samples as f64).sqrt();
    ag.iter_mut().for_each(|x| *x *= 0.5 / rms);
    let acc = base_excited(&m, &c, &k, &ag, dt, 20);
    let g = 9.80665;
    let floors = [1usize, 3, 5];
    let noisy: Vec<Vec<f64>> = floors
        .iter()
        .map(|&f| {
            let a = &acc[f - 1];
            let rms = (a.iter().map(|x| x * x).sum::<f64>() / a.len() as f64).sqrt();
            a.iter()
                .map(|x| (x + 0.03 * rms * rng.sample::<f64, _>(StandardNormal)) / g)
                .collect()
        })
        .collect();
    let mut csv = String::from("time,ground_acc (m/s2),acc1 (g),acc3 (g),acc5 (g)\n");
    for s in 0..samples {
        csv += &format!(
            "{:.3},{:e},{:e},{:e},{:e}\n",
            s as f64 * dt,
            ag[s],
            noisy[0][s],
            noisy[1][s],
            noisy[2][s]
        );
    }
    let record = p(d, "quake.csv");
    std::fs::write(&record, csv).expect("write");

    let t = p(d, "five.ssp");
    ok(&twin(&[
        "init",
        "--storeys",
        "5",
        "--excitation",
        "base",
        "--nominal",
        &p(d, "nominal.json"),
        "--out",
        &t,
    ]));
    let (out, report) = (p(d, "five-cal.ssp"), p(d, "five-cal.json"));
    let o = twin(&[
        "calibrate",
        "--twin",
        &t,
        "--data",
        &record,
        "--out",
        &out,
        "--report",
        &report,
        "--starts",
        "4",
    ]);
    ok(&o);
    println!("{}", String::from_utf8_lossy(&o.stdout));
    let r = json(&report);
    let map = map_values(&r);
    assert_eq!(map.len(), 15, "m1..m5, c1..c5, k1..k5: {map:?}");
    for i in 0..5 {
        let name = format!("k{}", i + 1);
        let error = (map[&name] - k[i]).abs() / k[i];
        let nominal_error = (nominal_k[i] - k[i]).abs() / k[i];
        println!(
            "{name}: MAP {:.1} truth {} nominal {:.1} (error {error:.4})",
            map[&name], k[i], nominal_k[i]
        );
        assert!(
            error < 0.03 && error < nominal_error / 4.0,
            "{name}: {error}"
        );
    }
    let nmse = r["runs"][0]["nmse"].as_object().expect("nmse by channel");
    assert_eq!(
        nmse.keys().map(String::as_str).collect::<Vec<_>>(),
        ["acc1", "acc3", "acc5"]
    );
    for (name, v) in nmse {
        assert!(v.as_f64().expect("nmse") < 0.3, "{name}: {v}");
    }
}

/// A priors file is refused naming the file and the key: an unknown field, a width that is not
/// positive, a storey the structure lacks, two widths; by `twin init` and by `twin calibrate`.
#[test]
fn malformed_priors_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let cases = [
        (r#"{"k": {"relative_sdd": 0.2}}"#, "key 'k'", "relative_sdd"),
        (r#"{"m2": {"sd": -1}}"#, "key 'm2'", "positive"),
        (
            r#"{"k7": {"relative_sd": 0.2}}"#,
            "key 'k7'",
            "storeys 1 to 5",
        ),
        (
            r#"{"c": {"sd": 1, "variance": 1}}"#,
            "key 'c'",
            "more than one width",
        ),
        (
            r#"{"k": {"value": 4000, "sd": 1}}"#,
            "key 'k'",
            "per parameter",
        ),
    ];
    for (i, (text, key, why)) in cases.iter().enumerate() {
        let file = p(d, &format!("bad{i}.json"));
        std::fs::write(&file, text).expect("write");
        let o = twin(&[
            "init",
            "--storeys",
            "5",
            "--priors",
            &file,
            "--out",
            &p(d, "t.ssp"),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{text} accepted");
        assert!(
            err.contains(&file) && err.contains(key) && err.contains(why),
            "{text}: {err}"
        );
        assert!(!d.join("t.ssp").exists(), "nothing written for {text}");
    }
    // calibrate --priors: refused before any work, naming file and key.
    let file = p(d, "bad-cal.json");
    std::fs::write(&file, r#"{"k2": {"space": "cubic", "sd": 1}}"#).expect("write");
    let data = common::workspace().join("data/dataset1.csv");
    let o = twin(&[
        "calibrate",
        "--data",
        &data.display().to_string(),
        "--priors",
        &file,
        "--out",
        &p(d, "c.ssp"),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains(&file) && err.contains("key 'k2'"), "{err}");
}

/// A twin whose priors were given at `twin init` calibrates with them: a 5-storey twin whose
/// file pins k3 tightly at a wrong value keeps k3 there. And a record the structure cannot use
/// is refused at once, naming the column.
#[test]
fn stored_priors_are_used_and_an_unusable_record_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let data = common::workspace().join("data/dataset1.csv");
    let data = data.display().to_string();
    // The paper's rig with a prior pinning k2 at 3000 N/m (the data says about 4100).
    let priors = p(d, "pin.json");
    std::fs::write(&priors, r#"{"k2": {"value": 3000, "sd": 1}}"#).expect("write");
    let t = p(d, "pinned.ssp");
    ok(&twin(&["init", "--priors", &priors, "--out", &t]));
    let report = p(d, "pinned.json");
    ok(&twin(&[
        "calibrate",
        "--twin",
        &t,
        "--data",
        &data,
        "--out",
        &p(d, "o.ssp"),
        "--report",
        &report,
        "--starts",
        "2",
    ]));
    let k2 = map_values(&json(&report))["k2"];
    assert!(
        (k2 - 3000.0).abs() < 10.0,
        "k2 {k2}: the stored prior was not used"
    );

    // A five-storey twin under ground motion cannot be driven by dataset1's force.
    let five = p(d, "five.ssp");
    ok(&twin(&[
        "init",
        "--storeys",
        "5",
        "--excitation",
        "base",
        "--out",
        &five,
    ]));
    let o = twin(&[
        "calibrate",
        "--twin",
        &five,
        "--data",
        &data,
        "--out",
        &p(d, "x.ssp"),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("'force'") && err.contains("ground acceleration"),
        "{err}"
    );
}

/// Two long roving runs (12,288 samples each, 240 s at 51.2 Hz, one accelerometer each, a
/// band-limited force at floor 1) calibrated as the ladder does it — four starts screened and
/// raced on each run's first 2,048 samples, the best refined on every sample — and with every
/// start on every sample: the same optimum (what it costs is `scripts/bench-scale.sh`'s).
///
/// Measured: the climb's MAP within 0.0004 posterior sd of the plain one's on every parameter,
/// its objective within 4e-7 nats (both stop at LM's fine gain, 1e-5 nats a step); m, k within
/// 0.1 % of the truth (2,118 simulations, most on the heads, in 2.0 s against 2,114 on every
/// sample in 10.4 s). Thresholds: 0.1 sd (250×), 0.05 nats, 2 % (20×) on m and k.
#[test]
fn long_roving_runs_climb_to_the_optimum_of_every_sample() {
    use orchestrator::calibrate::{calibrate_records, CalibrationSetup, RecordInput};
    use orchestrator::data::Measurement;
    use orchestrator::twin::Twin;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let full = p(d, "full.csv");
    let truth_path = p(d, "truth.json");
    ok(&twin(&[
        "synth",
        "--seed",
        "11",
        "--duration",
        "240",
        "--out",
        &full,
        "--truth",
        &truth_path,
    ]));
    let truth = json(&truth_path);
    let runs: Vec<Measurement> = ["acc1", "acc3"]
        .iter()
        .map(|acc| {
            let run = p(d, &format!("{acc}.csv"));
            keep_columns(&full, &run, &["time", "force", acc]);
            Measurement::read(Path::new(&run)).expect("run reads")
        })
        .collect();
    assert_eq!(runs[0].len(), 12_288);
    let inputs: Vec<RecordInput> = runs
        .iter()
        .map(|data| RecordInput { data, mask: None })
        .collect();
    std::env::set_var("TWIN_FMU_DIR", fmu_dir());
    let twin0 = Twin::default_twin().expect("default twin");
    let setup = |climb: bool| CalibrationSetup {
        starts: 4,
        climb,
        ..CalibrationSetup::default()
    };
    let climbed = calibrate_records(&twin0, &inputs, &setup(true)).expect("climbed");
    let plain = calibrate_records(&twin0, &inputs, &setup(false)).expect("plain");
    assert_eq!(climbed.heads, vec![2048]);
    assert!(plain.heads.is_empty());
    let gap = climbed.neg_log_posterior - plain.neg_log_posterior;
    println!(
        "objective: climbed {:.4}, plain {:.4} ({gap:+.2e} nats); simulations {} / {}; {:.2} / \
         {:.2} s",
        climbed.neg_log_posterior,
        plain.neg_log_posterior,
        climbed.simulations,
        plain.simulations,
        climbed.seconds,
        plain.seconds
    );
    assert!(gap.abs() < 0.05, "objective {gap:+.3e} nats apart");
    for (a, b) in climbed.parameters.iter().zip(&plain.parameters) {
        let in_sd = (a.value - b.value) / b.sd;
        let (family, i) = a.name.split_at(1);
        let i: usize = i.parse::<usize>().expect("index") - 1;
        let truth_value = truth["structure"][family][i].as_f64().expect("truth");
        let error = (a.value - truth_value) / truth_value;
        println!(
            "{}: climbed {:.5}, plain {:.5} ({in_sd:+.4} sd), truth {truth_value:.5} \
             ({error:+.4})",
            a.name, a.value, b.value
        );
        assert_eq!(a.name, b.name);
        assert!(in_sd.abs() < 0.1, "{}: {in_sd:+.4} sd apart", a.name);
        if a.name.starts_with('m') || a.name.starts_with('k') {
            assert!(error.abs() < 0.02, "{}: {error:+.4} from the truth", a.name);
        }
    }
}
