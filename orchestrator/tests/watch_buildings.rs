//! `twin watch` on a building other than the paper's rig: a five-storey twin under ground
//! motion (`twin init --storeys 5 --excitation base`) watched on streams `twin synth` makes of
//! the same building with accelerometers on floors 1, 3 and 5 reading in g (and velocities in
//! mm/s). An unchanged building raises no alert; the second storey's stiffness stepped down at
//! 30 s raises none before the change and a `failing` alert naming the channels after it; a
//! column map renames the stream's columns; a stream with a column for a floor the twin lacks,
//! or the wrong excitation, is refused at once naming the column.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;
use common::twin_cmd;

/// The stiffness step of the changed streams, s.
const CHANGE_AT: f64 = 30.0;

fn run(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().expect("twin runs");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The five-storey twin of synth's building (its equal floors: 5.2 kg, 3 N s/m, 4021 N/m),
/// under ground motion.
fn five_storey_twin(dir: &Path) -> PathBuf {
    let nominal = dir.join("nominal.json");
    std::fs::write(
        &nominal,
        r#"{"m": [5.2, 5.2, 5.2, 5.2, 5.2], "c": [3, 3, 3, 3, 3],
            "k": [4021, 4021, 4021, 4021, 4021]}"#,
    )
    .expect("nominal");
    let twin = dir.join("T.ssp");
    run(twin_cmd()
        .args([
            "init",
            "--storeys",
            "5",
            "--excitation",
            "base",
            "--nominal",
        ])
        .arg(&nominal)
        .arg("--out")
        .arg(&twin));
    twin
}

/// A 60 s record of the building under stationary ground motion (the envelope's strong phase
/// the whole record), seed 3, with `channels` in `units`; with `change`, k2 × 0.7 at 30 s.
fn stream(dir: &Path, name: &str, channels: &str, units: &str, change: bool) -> PathBuf {
    let scenario = dir.join("stationary.json");
    std::fs::write(&scenario, r#"{"ground_motion": {"strong_end": 1000}}"#).expect("scenario");
    let out = dir.join(format!("{name}.csv"));
    let mut cmd = twin_cmd();
    cmd.arg("synth")
        .arg("--scenario")
        .arg(&scenario)
        .args(["--storeys", "5", "--excitation", "base", "--duration", "60"])
        .args(["--seed", "3", "--channels", channels, "--units", units])
        .arg("--out")
        .arg(&out);
    if change {
        cmd.args(["--change", &format!("k2@{CHANGE_AT}:0.7")]);
    }
    run(&mut cmd);
    out
}

fn watch(twin: &Path, source: &Path, alerts: &Path, extra: &[&str]) -> Vec<Value> {
    run(twin_cmd()
        .args(["watch", "--no-diagnosis", "--twin"])
        .arg(twin)
        .arg("--source")
        .arg(source)
        .arg("--alerts")
        .arg(alerts)
        .args(extra));
    std::fs::read_to_string(alerts)
        .expect("alerts")
        .lines()
        .map(|l| serde_json::from_str(l).expect("an alert is JSON"))
        .collect()
}

fn of_kind<'a>(alerts: &'a [Value], kind: &str) -> Vec<&'a Value> {
    alerts.iter().filter(|a| a["kind"] == kind).collect()
}

fn names(v: &Value) -> Vec<String> {
    v.as_array()
        .expect("a list")
        .iter()
        .map(|n| n.as_str().expect("a name").to_owned())
        .collect()
}

/// The unchanged stream: no alert but the end, whose NMSE per channel (by name) is the twin's
/// own error on a record of its building — measured 0.085–0.091 % for acc1/3/5 in g, against
/// the 0.5 % tolerance (over 5× margin).
fn assert_quiet(alerts: &[Value], channels: &[&str]) {
    assert_eq!(alerts.len(), 1, "only the end alert: {alerts:?}");
    let end = &alerts[0];
    assert_eq!(end["kind"], "end");
    assert_eq!(end["failing_windows"], 0);
    assert_eq!(names(&end["channels"]), channels);
    let nmse = end["nmse"].as_array().expect("nmse per channel");
    assert_eq!(nmse.len(), channels.len());
    for v in nmse {
        assert!(v.as_f64().expect("a number") < 0.5, "{end}");
    }
    // The twin holds no noise variance for a five-storey building: the band is the prior's.
    assert!(
        end["noise_source"]
            .as_str()
            .expect("noise source")
            .starts_with("prior"),
        "{end}"
    );
}

/// The changed stream: nothing before the change; after it a `failing` alert naming channels
/// of the stream (by name, with their floors), within 10 s of the change (measured: 3.4 s for
/// acc1/3/5 and for vel2/acc5 with the prior's band, 0.3 s with the calibrated twin's), and
/// the end's NMSE far above the tolerance.
fn assert_alerted(alerts: &[Value], channels: &[&str]) -> f64 {
    let failing = of_kind(alerts, "failing");
    assert!(!failing.is_empty(), "{alerts:?}");
    for a in alerts.iter().filter(|a| a["kind"] != "end") {
        let t = a["time"].as_f64().expect("time");
        assert!(t > CHANGE_AT, "an alert before the change: {a}");
    }
    let first = failing[0];
    let at = first["time"].as_f64().expect("time");
    assert!(
        // The stiffness steps at the sample of 30.0 s, whose acceleration it changes at once.
        first["start"].as_f64().expect("start") >= CHANGE_AT && at < CHANGE_AT + 10.0,
        "{first}"
    );
    let named = names(&first["channels"]);
    assert!(!named.is_empty(), "{first}");
    for n in &named {
        assert!(
            channels.contains(&n.as_str()),
            "{n} is not measured: {first}"
        );
    }
    let floors: Vec<u64> = first["floors"]
        .as_array()
        .expect("floors")
        .iter()
        .map(|f| f.as_u64().expect("a floor"))
        .collect();
    let mut expected: Vec<u64> = named
        .iter()
        .map(|n| {
            n.trim_start_matches(char::is_alphabetic)
                .parse()
                .expect("floor")
        })
        .collect();
    expected.sort_unstable();
    expected.dedup();
    assert_eq!(floors, expected, "{first}");
    assert_eq!(
        first["nmse"].as_array().expect("nmse").len(),
        channels.len()
    );
    let end = alerts.last().expect("end");
    assert_eq!(names(&end["channels"]), channels);
    let worst = end["nmse"]
        .as_array()
        .expect("nmse")
        .iter()
        .map(|v| v.as_f64().expect("nmse"))
        .fold(0.0, f64::max);
    assert!(worst > 5.0, "{end}");
    at
}

#[test]
fn a_five_storey_building_under_ground_motion_is_watched_by_its_channels() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    let accs = ["acc1", "acc3", "acc5"];
    let same = stream(d, "same", "acc1,acc3,acc5", "acc=g", false);
    let changed = stream(d, "changed", "acc1,acc3,acc5", "acc=g", true);
    let header = std::fs::read_to_string(&changed).expect("record");
    assert!(header.starts_with("time,ground_acc,acc1 (g),acc3 (g),acc5 (g)\n"));

    assert_quiet(&watch(&twin, &same, &d.join("same.jsonl"), &[]), &accs);
    let alerts = watch(&twin, &changed, &d.join("changed.jsonl"), &[]);
    let at = assert_alerted(&alerts, &accs);
    println!(
        "acc1/3/5 in g: the first alert {:.2} s after the change",
        at - CHANGE_AT
    );

    // The same stream under other column names, mapped back by --columns: the same alerts.
    let renamed = d.join("renamed.csv");
    let text = header.replacen(
        "time,ground_acc,acc1 (g),acc3 (g),acc5 (g)",
        "t,ag,top (g),middle (g),bottom (g)",
        1,
    );
    std::fs::write(&renamed, text).expect("renamed");
    let map = d.join("map.json");
    std::fs::write(
        &map,
        r#"{"t": "time", "ag": "ground_acc", "top": "acc1", "middle": "acc3", "bottom": "acc5"}"#,
    )
    .expect("map");
    let mapped = watch(
        &twin,
        &renamed,
        &d.join("renamed.jsonl"),
        &["--columns", map.to_str().expect("utf-8")],
    );
    let strip = |alerts: &[Value]| -> Vec<Value> {
        alerts
            .iter()
            .map(|a| {
                let mut a = a.clone();
                if let Value::Object(m) = &mut a {
                    for key in [
                        "samples_per_second",
                        "real_time_factor",
                        "latency_median_us",
                        "latency_p99_us",
                    ] {
                        m.remove(key);
                    }
                }
                a
            })
            .collect()
    };
    assert_eq!(strip(&mapped), strip(&alerts));
}

#[test]
fn velocities_in_mm_per_s_and_an_accelerometer_are_watched_alike() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    let channels = ["vel2", "acc5"];
    let same = stream(d, "same", "vel2,acc5", "vel=mm/s", false);
    let changed = stream(d, "changed", "vel2,acc5", "vel=mm/s", true);
    assert!(std::fs::read_to_string(&same)
        .expect("record")
        .starts_with("time,ground_acc,vel2 (mm/s),acc5\n"));
    assert_quiet(&watch(&twin, &same, &d.join("same.jsonl"), &[]), &channels);
    let alerts = watch(&twin, &changed, &d.join("changed.jsonl"), &[]);
    let at = assert_alerted(&alerts, &channels);
    println!(
        "vel2 in mm/s, acc5: the first alert {:.2} s after the change",
        at - CHANGE_AT
    );
}

#[test]
fn a_floor_the_twin_lacks_or_the_wrong_excitation_is_refused_naming_the_column() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    for (header, needle) in [
        (
            "time,ground_acc,acc1,acc7 (g)",
            "column 'acc7' is for floor 7; the structure has floors 1 to 5",
        ),
        ("time,force,acc1", "column 'force' is a force"),
        ("time,ground_acc,acc1,speed3", "column 'speed3'"),
    ] {
        let source = d.join("bad.csv");
        std::fs::write(&source, format!("{header}\n0,0,0,0\n0.01,0,0,0\n")).expect("write");
        let alerts = d.join("bad.jsonl");
        let out = twin_cmd()
            .args(["watch", "--no-diagnosis", "--twin"])
            .arg(&twin)
            .arg("--source")
            .arg(&source)
            .arg("--alerts")
            .arg(&alerts)
            .output()
            .expect("twin watch");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{header}: accepted");
        assert!(stderr.contains(needle), "{header}: {stderr}");
        assert!(!alerts.exists(), "{header}: refused before any alert");
    }
}

/// A watcher stopped while the band's reference is still being taken (the first samples held,
/// the prior's sums under way: 400 samples, 7.8 s) and restarted on its checkpoint gives the
/// alerts of one uninterrupted run on the changed five-storey stream. (The first run reads its
/// part to the end; its `end` alert is taken out of the file, as if it had been killed there.)
#[test]
fn a_five_storey_watch_resumes_from_its_checkpoint_during_the_band_s_reference() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    let changed = stream(d, "changed", "acc1,acc3,acc5", "acc=g", true);
    let text = std::fs::read_to_string(&changed).expect("record");
    let lines: Vec<&str> = text.lines().collect();
    let part = d.join("part.csv");
    std::fs::write(&part, lines[..401].join("\n") + "\n").expect("write");
    let checkpoint = d.join("checkpoint.json");
    let alerts = d.join("resumed.jsonl");
    let args = ["--checkpoint", checkpoint.to_str().expect("utf-8")];
    let first = watch(&twin, &part, &alerts, &args);
    assert_eq!(first.len(), 1, "only the end: {first:?}");
    let saved: Value =
        serde_json::from_str(&std::fs::read_to_string(&checkpoint).expect("checkpoint"))
            .expect("json");
    assert_eq!(saved["samples"], 400);
    assert!(
        saved["held"].as_array().expect("held samples").len() > 100,
        "the samples wait for the band's reference"
    );
    std::fs::write(&alerts, "").expect("the end taken out");
    let resumed = watch(&twin, &changed, &alerts, &args);
    let once = watch(&twin, &changed, &d.join("once.jsonl"), &[]);
    let strip = |alerts: &[Value]| -> Vec<Value> {
        alerts
            .iter()
            .map(|a| {
                let mut a = a.clone();
                if let Value::Object(m) = &mut a {
                    for key in [
                        "samples_per_second",
                        "real_time_factor",
                        "latency_median_us",
                        "latency_p99_us",
                        "samples_this_run",
                    ] {
                        m.remove(key);
                    }
                }
                a
            })
            .collect()
    };
    assert!(!of_kind(&once, "failing").is_empty());
    assert_eq!(strip(&resumed), strip(&once));
    assert_eq!(resumed.last().expect("end")["samples_this_run"], 3072 - 400);
}

/// A mosquitto broker of the test's own on a free loopback port; stopped when dropped.
struct Broker {
    child: std::process::Child,
    port: u16,
}

impl Broker {
    fn start(dir: &Path) -> Broker {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let config = dir.join("mosquitto.conf");
        std::fs::write(
            &config,
            format!("listener {port} 127.0.0.1\nallow_anonymous true\nuser root\n"),
        )
        .expect("write the broker's config");
        let program = ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
            .into_iter()
            .find(|p| Path::new(p).exists())
            .expect("mosquitto is not installed: run scripts/prerequisites.sh as root");
        let child = Command::new(program)
            .arg("-c")
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start mosquitto");
        wait_for("mosquitto to listen", 10, || {
            std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
        });
        Broker { child, port }
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn wait_for(what: &str, seconds: u64, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(seconds);
    while !done() {
        assert!(Instant::now() < deadline, "waited {seconds} s for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A five-storey stream from a broker whose messages carry no header: the watcher takes
/// `time`, the excitation and an accelerometer on every floor (`time,ground_acc,acc1..acc5`),
/// and gives the alerts of the same record read from a file with its header.
#[test]
fn a_five_storey_stream_from_a_broker_without_a_header_has_every_floor_s_accelerometer() {
    use rumqttc::{Event, Packet, QoS};
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::Arc;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    let changed = stream(d, "changed", "acc1,acc2,acc3,acc4,acc5", "acc=m/s2", true);
    let text = std::fs::read_to_string(&changed).expect("record");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "time,ground_acc,acc1,acc2,acc3,acc4,acc5");
    let broker = Broker::start(d);
    let topic = "lab/five/samples";
    let alerts = d.join("broker.jsonl");
    let watcher = twin_cmd()
        .args(["watch", "--no-diagnosis", "--twin"])
        .arg(&twin)
        .arg("--source")
        .arg(format!("mqtt://127.0.0.1:{}/{topic}", broker.port))
        .arg("--alerts")
        .arg(&alerts)
        .args(["--idle", "4"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn twin watch");
    wait_for("the watcher to subscribe", 20, || {
        std::fs::read_to_string(&alerts).is_ok_and(|t| t.contains("\"state\":\"connected\""))
    });
    let mut options = rumqttc::MqttOptions::new("test-five-publisher", "127.0.0.1", broker.port);
    options.set_clean_session(false);
    let (publisher, mut connection) = rumqttc::Client::new(options, 100_000);
    let acked = Arc::new(AtomicU64::new(0));
    let counted = acked.clone();
    std::thread::spawn(move || loop {
        match connection.recv() {
            Ok(Ok(Event::Incoming(Packet::PubAck(_)))) => {
                counted.fetch_add(1, Ordering::SeqCst);
            }
            Ok(_) => {}
            Err(_) => return,
        }
    });
    // Messages of 16 data lines, none with a header.
    let messages: Vec<String> = lines[1..].chunks(16).map(|c| c.join("\n")).collect();
    for m in &messages {
        publisher
            .publish(topic, QoS::AtLeastOnce, false, m.clone())
            .expect("publish");
    }
    wait_for("the messages to be acknowledged", 30, || {
        acked.load(Ordering::SeqCst) >= messages.len() as u64
    });
    let out = watcher.wait_with_output().expect("twin watch");
    assert!(
        out.status.success(),
        "twin watch failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = |path: &Path| -> Vec<Value> {
        std::fs::read_to_string(path)
            .expect("alerts")
            .lines()
            .map(|l| serde_json::from_str(l).expect("JSON"))
            .collect()
    };
    let data = |alerts: &[Value]| -> Vec<Value> {
        alerts
            .iter()
            .filter(|a| a["kind"] != "connection")
            .map(|a| {
                let mut a = a.clone();
                if let Value::Object(m) = &mut a {
                    for key in [
                        "samples_per_second",
                        "real_time_factor",
                        "latency_median_us",
                        "latency_p99_us",
                        "mqtt",
                        "duplicates",
                        "alerts",
                    ] {
                        m.remove(key);
                    }
                }
                a
            })
            .collect()
    };
    let from_broker = read(&alerts);
    let from_file = watch(&twin, &changed, &d.join("file.jsonl"), &[]);
    assert!(!of_kind(&from_file, "failing").is_empty());
    assert_eq!(data(&from_broker), data(&from_file));
    let end = from_broker.last().expect("end");
    assert_eq!(
        names(&end["channels"]),
        ["acc1", "acc2", "acc3", "acc4", "acc5"]
    );
    assert_eq!(end["samples"], 3072);
}

/// The five-storey twin calibrated on the unchanged record (its noise variance per channel,
/// acc1/acc3/acc5, makes the band) and with a GP corrector trained on it (one GP per channel):
/// the watcher learns online per channel (a threshold per channel) and the alerts follow the
/// building, not the corrector — the unchanged stream raises none, the changed one a `failing`
/// alert after the change only.
#[test]
fn a_calibrated_five_storey_twin_with_its_corrector_watches_per_channel() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let twin = five_storey_twin(d);
    let accs = ["acc1", "acc3", "acc5"];
    let same = stream(d, "same", "acc1,acc3,acc5", "acc=g", false);
    let changed = stream(d, "changed", "acc1,acc3,acc5", "acc=g", true);
    let calibrated = d.join("K.ssp");
    run(twin_cmd()
        .args(["calibrate", "--starts", "1", "--twin"])
        .arg(&twin)
        .arg("--data")
        .arg(&same)
        .arg("--out")
        .arg(&calibrated));
    let corrected = d.join("C.ssp");
    run(twin_cmd()
        .args(["train", "--stride", "4", "--twin"])
        .arg(&calibrated)
        .arg("--data")
        .arg(&same)
        .arg("--out")
        .arg(&corrected));
    let quiet = watch(&corrected, &same, &d.join("same.jsonl"), &[]);
    assert_eq!(quiet.len(), 1, "only the end alert: {quiet:?}");
    let end = &quiet[0];
    assert_eq!(names(&end["channels"]), accs);
    assert_eq!(end["noise_source"], "twin (calibrated)");
    let learning = &end["learning"];
    assert_eq!(
        learning["threshold"].as_array().expect("thresholds").len(),
        3
    );
    assert!(
        learning["queries"].as_u64().expect("queries") > 0,
        "{learning}"
    );
    for v in end["nmse"].as_array().expect("nmse") {
        // Measured 0.085-0.093 %, against the 0.5 % tolerance.
        assert!(v.as_f64().expect("nmse") < 0.5, "{end}");
    }
    let alerts = watch(&corrected, &changed, &d.join("changed.jsonl"), &[]);
    let at = assert_alerted(&alerts, &accs);
    println!(
        "calibrated, with its corrector: the first alert {:.2} s after the change",
        at - CHANGE_AT
    );
}
