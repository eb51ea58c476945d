//! `twin watch` on streams: standard input and a file give the same alerts; the failing windows
//! found online are `twin compare`'s on the whole record, to the sample; a malformed line and a
//! gap are reported and the stream goes on; a watcher killed mid-stream and restarted on its
//! checkpoint gives, with the first run, the alerts and NMSE of one uninterrupted run.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use orchestrator::synth::{csv_text, EffectSpec};
use serde_json::Value;

mod common;
use common::{fmu_dir, hidden_change_record, hidden_change_twin, twin_cmd, HIDDEN_CHANGE_NOISE_SD};

/// The hidden-change twin without its parameter covariance, so `twin compare`'s band is the
/// noise band `twin watch` uses; written once per test binary.
fn twin_path() -> &'static Path {
    static PATH: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &PATH
        .get_or_init(|| {
            let dir = tempfile::tempdir().expect("tempdir");
            let mut twin = hidden_change_twin().duplicate();
            twin.parameter_covariance = None;
            let path = dir.path().join("twin.ssp");
            twin.write(&path).expect("write the twin");
            (dir, path)
        })
        .1
}

/// A 20 s record with contact between floors 2 and 3 (the force ×3 in 12–17 s), as CSV text.
fn contact_record() -> String {
    static TEXT: OnceLock<String> = OnceLock::new();
    TEXT.get_or_init(|| {
        let m = hidden_change_record(HIDDEN_CHANGE_NOISE_SD, |s| {
            s.effects.push(EffectSpec::Contact {
                lower: 2,
                gap: 5e-4,
                stiffness: 9000.0,
                side: 0,
            })
        });
        csv_text(&m)
    })
    .clone()
}

fn read_alerts(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .expect("alerts")
        .lines()
        .map(|l| serde_json::from_str(l).expect("an alert is JSON"))
        .collect()
}

/// `twin watch` on `source` (a path, or `-` with `stdin` piped in), without the background
/// diagnosis (its own test has it); its alerts.
fn watch(source: &str, stdin: Option<&str>, alerts: &Path, extra: &[&str]) -> Vec<Value> {
    let mut cmd = twin_cmd();
    cmd.args(["watch", "--no-diagnosis", "--twin"])
        .arg(twin_path())
        .args(["--source", source, "--alerts"])
        .arg(alerts)
        .args(extra)
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("spawn twin watch");
    if let Some(text) = stdin {
        let mut pipe = child.stdin.take().expect("stdin");
        pipe.write_all(text.as_bytes()).expect("write stdin");
    }
    let out = child.wait_with_output().expect("twin watch");
    assert!(
        out.status.success(),
        "twin watch failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_alerts(alerts)
}

/// Alerts without the figures that depend on the machine (speed, latency, this run's count).
fn comparable(alerts: &[Value]) -> Vec<Value> {
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
}

fn of_kind<'a>(alerts: &'a [Value], kind: &str) -> Vec<&'a Value> {
    alerts.iter().filter(|a| a["kind"] == kind).collect()
}

#[test]
fn standard_input_and_a_file_give_the_same_alerts() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("record.csv");
    let text = contact_record();
    std::fs::write(&csv, &text).expect("write");
    let from_file = watch(
        csv.to_str().expect("utf-8"),
        None,
        &dir.path().join("a.jsonl"),
        &[],
    );
    let from_stdin = watch("-", Some(&text), &dir.path().join("b.jsonl"), &[]);
    assert_eq!(comparable(&from_file), comparable(&from_stdin));
    let end = from_file.last().expect("an end alert");
    assert_eq!(end["kind"], "end");
    assert_eq!(end["samples"], 1024);
    assert!(end["samples_per_second"].as_f64().expect("a rate") > 0.0);
    assert!(
        end["latency_p99_us"].as_f64().expect("p99")
            >= end["latency_median_us"].as_f64().expect("median")
    );
}

#[test]
fn the_online_failing_windows_are_twin_compare_s() {
    // The twin's tolerance (0.5 %), none, 12.5 % (above the contact window's NMSE on floor 1,
    // 11.7 %, below floor 2's, 14.0 %) and 15 % (above all: no failing window).
    for tolerance in [None, Some("0"), Some("12.5"), Some("15")] {
        online_windows_equal_compare_s(tolerance);
    }
}

fn online_windows_equal_compare_s(tolerance: Option<&str>) {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("record.csv");
    std::fs::write(&csv, contact_record()).expect("write");
    let report = dir.path().join("report.json");
    let extra: Vec<&str> = tolerance.map_or(vec![], |t| vec!["--tolerance", t]);
    let out = twin_cmd()
        .args(["compare", "--twin"])
        .arg(twin_path())
        .arg("--data")
        .arg(&csv)
        .arg("--report")
        .arg(&report)
        .args(&extra)
        .output()
        .expect("twin compare");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let batch = report["failing_windows"]
        .as_array()
        .expect("windows")
        .clone();
    assert_eq!(
        batch.is_empty(),
        tolerance == Some("15"),
        "the contact gives a failing window below 14 %"
    );
    let alerts = watch(
        csv.to_str().expect("utf-8"),
        None,
        &dir.path().join("a.jsonl"),
        &extra,
    );
    let online: Vec<&Value> = of_kind(&alerts, "recovered")
        .into_iter()
        .filter(|a| a["withdrawn"] == false)
        .collect();
    assert_eq!(
        online.len(),
        batch.len(),
        "tolerance {tolerance:?}: {online:?}\n{batch:?}"
    );
    for (o, b) in online.iter().zip(&batch) {
        // The same samples: times as the CSV gives them, the same floors.
        assert_eq!(o["start"], b["start"], "{o} {b}");
        assert_eq!(o["end"], b["end"], "{o} {b}");
        assert_eq!(o["floors"], b["floors"], "{o} {b}");
        for f in 0..3 {
            let (x, y) = (
                o["nmse"][f].as_f64().expect("nmse"),
                b["nmse"][f].as_f64().expect("nmse"),
            );
            assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-12), "{x} {y}");
        }
    }
    // Each window announced was closed (withdrawn if on its whole extent it is below the
    // tolerance).
    assert_eq!(
        of_kind(&alerts, "failing").len(),
        of_kind(&alerts, "recovered").len()
    );
    let end = alerts.last().expect("end");
    assert_eq!(end["failing_windows"], batch.len());
    for f in 0..3 {
        let (x, y) = (
            end["nmse"][f].as_f64().expect("nmse"),
            report["nmse"][f].as_f64().expect("nmse"),
        );
        assert!((x - y).abs() <= 1e-9 * y.abs(), "{x} {y}");
    }
}

#[test]
fn a_malformed_line_and_a_gap_are_reported_and_the_stream_goes_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = contact_record();
    let lines: Vec<&str> = text.lines().collect();
    // Data line k is lines[k + 1]; drop samples 400..410, put a malformed line after sample 299.
    let mut edited: Vec<String> = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let k = i as i64 - 1;
        if (400..410).contains(&k) {
            continue;
        }
        edited.push((*line).to_owned());
        if k == 299 {
            edited.push("6.0,oops,0.1,0.2,0.3".into());
        }
    }
    let csv = dir.path().join("record.csv");
    std::fs::write(&csv, edited.join("\n") + "\n").expect("write");
    let alerts = watch(
        csv.to_str().expect("utf-8"),
        None,
        &dir.path().join("a.jsonl"),
        &[],
    );
    let bad = of_kind(&alerts, "bad_sample");
    assert_eq!(bad.len(), 1, "{alerts:?}");
    // Header line 1, samples 0..299 on lines 2..301: the malformed line is 302.
    assert_eq!(bad[0]["line"], 302);
    assert!(
        bad[0]["reason"].as_str().expect("reason").contains("force"),
        "{}",
        bad[0]
    );
    let gaps = of_kind(&alerts, "gap");
    assert_eq!(gaps.len(), 1, "{alerts:?}");
    assert_eq!(gaps[0]["missing"], 10);
    let t410: f64 = lines[411]
        .split(',')
        .next()
        .expect("time")
        .parse()
        .expect("t");
    assert_eq!(gaps[0]["time"].as_f64(), Some(t410));
    let end = alerts.last().expect("end");
    assert_eq!(end["kind"], "end");
    assert_eq!(end["samples"], 1024 - 10);
    assert_eq!(end["bad_lines"], 1);
    assert_eq!(end["gaps"], 1);
    assert_eq!(end["missing_samples"], 10);
    // After the gap the twin starts again at rest and the comparison goes on: the contact
    // (12–17 s, after the gap) is still found.
    assert!(!of_kind(&alerts, "failing").is_empty(), "{alerts:?}");
    assert!(end["nmse"][2].as_f64().expect("nmse") > 1.0);
}

#[test]
fn a_watcher_killed_mid_stream_resumes_from_its_checkpoint() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = contact_record();
    let lines: Vec<&str> = text.lines().collect();
    // The first part: the header and 820 samples (to 16.0 s): the contact's failing window
    // opens at 15.4 s, after the last checkpoint (768 samples, 15.0 s) and before the kill.
    let split = 821;
    let csv = dir.path().join("stream.csv");
    std::fs::write(&csv, lines[..split].join("\n") + "\n").expect("write");
    let checkpoint = dir.path().join("checkpoint.json");
    let alerts = dir.path().join("alerts.jsonl");
    let args = |follow: bool| {
        let mut a = vec![
            "--checkpoint".to_owned(),
            checkpoint.display().to_string(),
            "--checkpoint-every".into(),
            "64".into(),
        ];
        if follow {
            a.extend(["--follow".into(), "--idle".into(), "30".into()]);
        }
        a
    };
    let mut cmd = twin_cmd();
    cmd.args(["watch", "--no-diagnosis", "--twin"])
        .arg(twin_path())
        .args(["--source", csv.to_str().expect("utf-8"), "--alerts"])
        .arg(&alerts)
        .args(args(true))
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    let mut child = cmd.spawn().expect("spawn");
    // Wait until the checkpoint has advanced to 768 samples (it is written every 64).
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let samples = std::fs::read_to_string(&checkpoint)
            .ok()
            .and_then(|t| serde_json::from_str::<Value>(&t).ok())
            .and_then(|v| v["samples"].as_u64());
        if samples.is_some_and(|s| s >= 768) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the checkpoint never reached 768 samples"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Let it take the 52 samples after the checkpoint too, then kill it (SIGKILL).
    std::thread::sleep(Duration::from_millis(300));
    child.kill().expect("kill");
    child.wait().expect("wait");
    let before_kill = read_alerts(&alerts);
    assert!(
        before_kill.iter().all(|a| a["kind"] != "end"),
        "the first run did not end"
    );
    // The window opened after the checkpoint: the resumed run raises it again from the same
    // samples, and must not write it twice.
    assert_eq!(of_kind(&before_kill, "failing").len(), 1, "{before_kill:?}");
    let saved: Value =
        serde_json::from_str(&std::fs::read_to_string(&checkpoint).expect("checkpoint"))
            .expect("json");
    assert_eq!(saved["samples"], 768);
    // The rest of the stream arrives; a new watcher starts on the same checkpoint and source.
    let mut file = std::fs::OpenOptions::new()
        .append(true)
        .open(&csv)
        .expect("open");
    file.write_all((lines[split..].join("\n") + "\n").as_bytes())
        .expect("append");
    drop(file);
    let resumed = watch(
        csv.to_str().expect("utf-8"),
        None,
        &alerts,
        &args(false).iter().map(String::as_str).collect::<Vec<_>>(),
    );
    // One uninterrupted run on the whole stream.
    let whole = dir.path().join("whole.csv");
    std::fs::write(&whole, &text).expect("write");
    let once = watch(
        whole.to_str().expect("utf-8"),
        None,
        &dir.path().join("once.jsonl"),
        &[],
    );
    assert!(
        !of_kind(&once, "failing").is_empty(),
        "the record has a failing window"
    );
    assert_eq!(comparable(&resumed), comparable(&once));
    let (a, b) = (resumed.last().expect("end"), once.last().expect("end"));
    assert_eq!(a["nmse"], b["nmse"]);
    assert_eq!(a["samples"], 1024);
    assert!(a["samples_this_run"].as_u64().expect("count") < 1024);
}

#[test]
fn an_fmu_state_serialised_and_restored_gives_the_same_steps_and_is_refused_when_undeclared() {
    use orchestrator::cosim::import::{unpack, Fmu, Library, UnpackLimits};
    let path = fmu_dir().join("fmu_shear.fmu");
    let fmu = Fmu::open(&path).expect("open the shear FMU");
    let (force, acc) = (
        fmu.value_reference("force").expect("force"),
        ["acc1", "acc2", "acc3"].map(|n| fmu.value_reference(n).expect("acc")),
    );
    let run = |instance: &mut orchestrator::cosim::import::Instance, from: usize, to: usize| {
        let mut out = Vec::new();
        for k in from..to {
            let t = k as f64 / 51.2;
            instance
                .set_real(&[force], &[(3.0 * t).sin() * 50.0])
                .expect("set");
            instance.do_step(t, 1.0 / 51.2).expect("step");
            let mut y = [0.0; 3];
            instance.get_real(&acc, &mut y).expect("get");
            out.push(y);
        }
        out
    };
    let mut a = fmu.instantiate("a").expect("instantiate");
    a.setup_experiment(0.0, None).expect("setup");
    a.enter_initialization_mode().expect("init");
    a.exit_initialization_mode().expect("init");
    run(&mut a, 0, 100);
    let bytes = a.state_bytes().expect("serialise");
    let straight = run(&mut a, 100, 200);
    // Another instance put in the saved state steps on exactly as the first.
    let mut b = fmu.instantiate("b").expect("instantiate");
    b.setup_experiment(0.0, None).expect("setup");
    b.enter_initialization_mode().expect("init");
    b.exit_initialization_mode().expect("init");
    b.restore_state_bytes(&bytes).expect("deserialise");
    assert_eq!(run(&mut b, 100, 200), straight);

    // A library told nothing of the modelDescription's capabilities refuses, saying why.
    let unpacked = unpack(&path, UnpackLimits::default()).expect("unpack");
    let library = Library::load(
        &unpacked.path().join("binaries/linux64/fmu_shear.so"),
        &fmu.model_description.guid,
        &unpacked.path().join("resources"),
    )
    .expect("load");
    let mut c = library.instantiate("c").expect("instantiate");
    c.setup_experiment(0.0, None).expect("setup");
    c.enter_initialization_mode().expect("init");
    c.exit_initialization_mode().expect("init");
    let refused = c.state_bytes().expect_err("undeclared").to_string();
    assert!(refused.contains("canGetAndSetFMUstate"), "{refused}");
}

/// A mosquitto broker of the test's own on a free loopback port, with its persistence in a
/// temporary folder; stopped (SIGTERM, so it saves what it keeps) when dropped.
struct Broker {
    child: std::process::Child,
    config: PathBuf,
    port: u16,
}

impl Broker {
    fn start(dir: &Path) -> Broker {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let store = dir.join("mosquitto");
        std::fs::create_dir_all(&store).expect("mkdir");
        let config = dir.join("mosquitto.conf");
        std::fs::write(
            &config,
            format!(
                "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n\
                 persistence_location {}/\nmax_queued_messages 100000\nuser root\nlog_type all\nlog_dest file {}/log\n",
                store.display(), store.display()
            ),
        )
        .expect("write the broker's config");
        let child = Broker::spawn(&config, port);
        Broker {
            child,
            config,
            port,
        }
    }

    fn spawn(config: &Path, port: u16) -> std::process::Child {
        let program = ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
            .into_iter()
            .find(|p| Path::new(p).exists())
            .expect("mosquitto is not installed: run scripts/prerequisites.sh as root, or apt-get install mosquitto");
        let child = Command::new(program)
            .arg("-c")
            .arg(config)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start mosquitto");
        let deadline = Instant::now() + Duration::from_secs(10);
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                Instant::now() < deadline,
                "mosquitto did not listen on {port}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        child
    }

    /// SIGTERM and wait: the broker writes its sessions and queued messages to its store.
    fn stop(&mut self) {
        signal(self.child.id(), "TERM");
        self.child.wait().expect("wait for mosquitto");
    }

    fn restart(&mut self) {
        self.child = Broker::spawn(&self.config, self.port);
    }
}

impl Drop for Broker {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            self.stop();
        }
    }
}

fn signal(pid: u32, name: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{name}"), &pid.to_string()])
        .status()
        .expect("kill")
        .success();
    assert!(ok, "kill -{name} {pid}");
}

/// An MQTT client of the test's (QoS 1, a persistent session): its connection driven on a
/// thread that collects what arrives on `subscribe` and reconnects after errors.
fn mqtt_client(
    port: u16,
    id: &str,
    subscribe: Option<&str>,
) -> (
    rumqttc::Client,
    std::sync::Arc<std::sync::Mutex<Vec<String>>>,
    std::sync::Arc<std::sync::atomic::AtomicU64>,
) {
    use rumqttc::{Event, Packet, QoS};
    let mut options = rumqttc::MqttOptions::new(id, "127.0.0.1", port);
    options.set_clean_session(false);
    let (client, mut connection) = rumqttc::Client::new(options, 100_000);
    if let Some(topic) = subscribe {
        client
            .subscribe(topic, QoS::AtLeastOnce)
            .expect("subscribe");
    }
    let received = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let acked = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let (r, a) = (received.clone(), acked.clone());
    std::thread::spawn(move || loop {
        match connection.recv() {
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) => r
                .lock()
                .expect("lock")
                .push(String::from_utf8_lossy(&p.payload).into_owned()),
            Ok(Ok(Event::Incoming(Packet::PubAck(_)))) => {
                a.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
            Ok(Ok(_)) => {}
            Ok(Err(_)) => std::thread::sleep(Duration::from_millis(100)),
            Err(_) => return,
        }
    });
    (client, received, acked)
}

fn wait_for(what: &str, seconds: u64, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(seconds);
    while !done() {
        assert!(Instant::now() < deadline, "waited {seconds} s for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Samples arrive through a real broker (mosquitto) in messages of one to 16 lines, the
/// first with a header; the watcher is stopped (SIGSTOP) while a third of the stream is
/// published, so the broker keeps it, then the broker itself is stopped and restarted on its
/// store; the watcher reconnects, gets what the broker kept (QoS 1, its persistent session)
/// and the rest, and gives the alerts of one run over the whole record from a file. Its
/// alerts also arrive on the alerts topic.
#[test]
fn a_stream_from_a_broker_survives_the_broker_going_away() {
    use rumqttc::QoS;
    use std::sync::atomic::Ordering;
    let dir = tempfile::tempdir().expect("tempdir");
    // The record and the twin first: the watcher's --idle runs from its start.
    let text = contact_record();
    let twin = twin_path();
    let mut broker = Broker::start(dir.path());
    let topic = "lab/frame/samples";
    let (_listener, heard, _) =
        mqtt_client(broker.port, "test-alerts", Some("lab/frame/samples/alerts"));
    let alerts = dir.path().join("alerts.jsonl");
    let mut watcher = twin_cmd()
        .args(["watch", "--no-diagnosis", "--twin"])
        .arg(twin)
        .arg("--source")
        .arg(format!("mqtt://127.0.0.1:{}/{topic}", broker.port))
        .arg("--alerts")
        .arg(&alerts)
        .args(["--idle", "4"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn twin watch");
    let connected = |n: usize| {
        std::fs::read_to_string(&alerts).is_ok_and(|t| {
            t.lines()
                .filter(|l| l.contains("\"state\":\"connected\""))
                .count()
                >= n
        })
    };
    wait_for("the watcher to subscribe", 20, || connected(1));
    let lines: Vec<&str> = text.lines().collect();
    let (header, samples) = (lines[0], &lines[1..]);
    // Messages of 1, 2, …, 16 lines, the first with the header.
    let mut messages: Vec<String> = Vec::new();
    let mut at = 0;
    let mut size = 1;
    while at < samples.len() {
        let end = (at + size).min(samples.len());
        let mut body = samples[at..end].join("\n");
        if at == 0 {
            body = format!("{header}\n{body}");
        }
        messages.push(body);
        at = end;
        size = size % 16 + 1;
    }
    let (publisher, _, acked) = mqtt_client(broker.port, "test-publisher", None);
    let publish = |range: std::ops::Range<usize>| {
        for m in &messages[range] {
            publisher
                .publish(topic, QoS::AtLeastOnce, false, m.clone())
                .expect("publish");
        }
    };
    let third = messages.len() / 3;
    publish(0..third);
    wait_for("the first third to be acknowledged", 20, || {
        acked.load(Ordering::SeqCst) >= third as u64
    });
    // The watcher stops reading; the next third waits in the broker.
    signal(watcher.id(), "STOP");
    publish(third..2 * third);
    wait_for("the second third to be acknowledged", 20, || {
        acked.load(Ordering::SeqCst) >= 2 * third as u64
    });
    // The broker goes away with it and comes back from its store.
    broker.stop();
    broker.restart();
    signal(watcher.id(), "CONT");
    let deadline = Instant::now() + Duration::from_secs(30);
    while !connected(2) {
        if Instant::now() > deadline {
            let _ = watcher.kill();
            let out = watcher.wait_with_output().expect("twin watch");
            panic!(
                "the watcher did not reconnect; its alerts: {}\nits output: {}\nbroker: {}",
                std::fs::read_to_string(&alerts).unwrap_or_default(),
                std::fs::read_to_string(dir.path().join("mosquitto/log")).unwrap_or_default(),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    publish(2 * third..messages.len());
    let out = watcher.wait_with_output().expect("twin watch");
    assert!(
        out.status.success(),
        "twin watch failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let from_broker = read_alerts(&alerts);

    let once = watch("-", Some(&text), &dir.path().join("once.jsonl"), &[]);
    let data = |alerts: &[Value]| -> Vec<Value> {
        comparable(alerts)
            .into_iter()
            .filter(|a| a["kind"] != "connection")
            .map(|mut a| {
                if let Value::Object(m) = &mut a {
                    m.remove("mqtt");
                    m.remove("duplicates");
                    m.remove("alerts");
                }
                a
            })
            .collect()
    };
    assert!(!of_kind(&once, "failing").is_empty(), "the record fails");
    assert_eq!(data(&from_broker), data(&once));
    let end = from_broker.last().expect("end");
    assert_eq!(end["samples"], 1024);
    assert_eq!(end["bad_lines"], 0);
    assert_eq!(end["gaps"], 0);
    let mqtt = &end["mqtt"];
    eprintln!(
        "through the broker: {mqtt}, {} duplicate samples dropped",
        end["duplicates"]
    );
    assert!(mqtt["connections"].as_u64() >= Some(2), "{mqtt}");
    assert!(mqtt["disconnections"].as_u64() >= Some(1), "{mqtt}");
    assert!(
        mqtt["messages"].as_u64() >= Some(messages.len() as u64),
        "{mqtt}"
    );
    // Every numbered alert also reached the alerts topic (a listener on its own session).
    wait_for("the alerts on the topic", 10, || {
        heard
            .lock()
            .expect("lock")
            .iter()
            .any(|m| m.contains("\"kind\":\"end\""))
    });
    let numbered = |alerts: Vec<Value>| -> Vec<u64> {
        let mut seq: Vec<u64> = alerts.iter().filter_map(|a| a["seq"].as_u64()).collect();
        seq.sort_unstable();
        seq.dedup();
        seq
    };
    let heard: Vec<Value> = heard
        .lock()
        .expect("lock")
        .iter()
        .map(|m| serde_json::from_str(m).expect("an alert is JSON"))
        .collect();
    assert_eq!(numbered(heard), numbered(from_broker.clone()));
}

/// A failing window is diagnosed on a thread while the stream goes on, on the samples after
/// the change its opening located: the `diagnosis` alert names the contact between floors 2
/// and 3, and it is `twin diagnose`'s answer on the same samples, whose report is written
/// beside the alerts.
#[test]
fn a_failing_window_is_diagnosed_in_the_background_as_twin_diagnose_would() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("record.csv");
    std::fs::write(&csv, contact_record()).expect("write");
    let alerts = dir.path().join("alerts.jsonl");
    let out = twin_cmd()
        .args(["watch", "--twin"])
        .arg(twin_path())
        .arg("--source")
        .arg(&csv)
        .arg("--alerts")
        .arg(&alerts)
        .args(["--diagnosis-after", "2"])
        .output()
        .expect("twin watch");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let all = read_alerts(&alerts);
    let failing = of_kind(&all, "failing");
    let diagnosis = of_kind(&all, "diagnosis");
    assert_eq!(failing.len(), 1, "{all:?}");
    assert_eq!(diagnosis.len(), 1, "{all:?}");
    let (failing, diagnosis) = (failing[0], diagnosis[0]);
    assert_eq!(diagnosis["window_start"], failing["start"]);
    assert_eq!(diagnosis["action"], "add_physics", "{diagnosis}");
    let effect = &diagnosis["effects"][0];
    assert_eq!(effect["kind"], "contact", "{diagnosis}");
    assert_eq!(effect["location"], serde_json::json!([2, 3]), "{diagnosis}");
    // The samples it was run on: from the located change (less the 30 s warm-up, or the
    // stream's start) to the stream's end (the window stays open to it: one look); its fits
    // from the change on.
    let (from, to) = (
        diagnosis["from"].as_f64().expect("from"),
        diagnosis["to"].as_f64().expect("to"),
    );
    let change = failing["change"]["time"]
        .as_f64()
        .expect("a located change");
    assert_eq!(diagnosis["change_time"], failing["change"]["time"]);
    assert!(
        (from - (change - 30.0).max(0.0)).abs() <= 0.02,
        "{diagnosis}"
    );
    let fitted_from = diagnosis["fitted_from"].as_f64().expect("fitted_from");
    assert!((fitted_from - change).abs() <= 0.02, "{diagnosis}");
    assert!(
        to > failing["start"].as_f64().expect("start"),
        "{diagnosis}"
    );
    let text = contact_record();
    let cut: Vec<&str> = std::iter::once(text.lines().next().expect("header"))
        .chain(text.lines().skip(1).filter(|l| {
            let t: f64 = l
                .split(',')
                .next()
                .and_then(|t| t.parse().ok())
                .expect("time");
            from - 1e-9 <= t && t <= to + 1e-9
        }))
        .collect();
    let cut_csv = dir.path().join("cut.csv");
    std::fs::write(&cut_csv, cut.join("\n") + "\n").expect("write");
    let report = dir.path().join("diagnose.json");
    // After the change, as `--changed-at`.
    let status = twin_cmd()
        .args(["diagnose", "--twin"])
        .arg(twin_path())
        .arg("--data")
        .arg(&cut_csv)
        .args(["--changed-at", &format!("{change}")])
        .arg("--report")
        .arg(&report)
        .stdout(Stdio::null())
        .status()
        .expect("twin diagnose");
    assert!(status.success());
    let batch: Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let background: Value = serde_json::from_str(
        &std::fs::read_to_string(diagnosis["report"].as_str().expect("a report path"))
            .expect("the background report"),
    )
    .expect("json");
    for d in [&batch, &background] {
        assert_eq!(d["action"], diagnosis["action"]);
        assert_eq!(d["effects"][0]["label"], effect["label"]);
    }
    for (key, value) in effect["parameters"].as_object().expect("parameters") {
        let b = batch["effects"][0]["parameters"][key]
            .as_f64()
            .expect("a parameter");
        let v = value.as_f64().expect("a parameter");
        assert!(
            (b - v).abs() <= 1e-9 * b.abs().max(1e-12),
            "{key}: {v} against {b}"
        );
    }
    assert_eq!(
        of_kind(&all, "end")[0]["alerts"]["diagnosis"],
        1,
        "the end counts it"
    );
}

/// The twin of the bundled records: calibrated on dataset 1, with a GP corrector trained on
/// every second sample of it, written once per test binary.
fn corrected_twin_path() -> &'static Path {
    static PATH: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &PATH
        .get_or_init(|| {
            let dir = tempfile::tempdir().expect("tempdir");
            let calibrated = dir.path().join("calibrated.ssp");
            let path = dir.path().join("corrected.ssp");
            let dataset1 = common::workspace().join("data/dataset1.csv");
            for args in [
                vec!["calibrate".into(), "--out".into(), calibrated.clone()],
                vec![
                    "train".into(),
                    "--twin".into(),
                    calibrated.clone(),
                    "--stride".into(),
                    "2".into(),
                    "--out".into(),
                    path.clone(),
                ],
            ] {
                let status = twin_cmd()
                    .args(&args)
                    .arg("--data")
                    .arg(&dataset1)
                    .stdout(Stdio::null())
                    .status()
                    .expect("twin");
                assert!(status.success(), "twin {args:?}");
            }
            (dir, path)
        })
        .1
}

/// `twin watch` of the corrected twin on a bundled record with `extra` options: its alerts.
fn watch_corrected(record: &str, alerts: &Path, extra: &[&str]) -> Vec<Value> {
    let out = twin_cmd()
        .args(["watch", "--no-diagnosis", "--twin"])
        .arg(corrected_twin_path())
        .arg("--source")
        .arg(common::workspace().join("data").join(record)) // an absolute path stays itself
        .arg("--alerts")
        .arg(alerts)
        .args(extra)
        .output()
        .expect("twin watch");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_alerts(alerts)
}

/// The supervisor on the bundled records, with the corrector trained on dataset 1. Datasets 1
/// and 2 raise no `uncertain` alert (their largest V(f)/T measured 5.2 and 2.6, against the
/// alarm at 10). Dataset 3's contact raises one (V(f)/T reaches 70), before the failing window
/// opens; its samples are queried and learned within the budget, and what is learned online
/// cuts the worst floor's NMSE against watching only (measured 68.8 % → 55.0 %; asserted: at
/// least a tenth).
#[test]
fn the_corrector_queries_and_learns_online_within_its_budget() {
    let dir = tempfile::tempdir().expect("tempdir");
    for record in ["dataset1.csv", "dataset2.csv"] {
        let alerts = watch_corrected(record, &dir.path().join("quiet.jsonl"), &[]);
        let end = alerts.last().expect("end");
        assert!(
            of_kind(&alerts, "uncertain").is_empty(),
            "{record}: {alerts:?}"
        );
        let ratio = end["learning"]["largest_ratio"].as_f64().expect("ratio");
        // Measured 5.16 (dataset 1) and 2.59 (dataset 2) with the default budget of 256.
        assert!(ratio > 1.0 && ratio < 6.5, "{record}: {ratio}");
    }
    let learned = watch_corrected(
        "dataset3.csv",
        &dir.path().join("learned.jsonl"),
        &["--budget", "512"],
    );
    let watched = watch_corrected(
        "dataset3.csv",
        &dir.path().join("watched.jsonl"),
        &["--no-learning"],
    );
    let uncertain = of_kind(&learned, "uncertain");
    let failing = of_kind(&learned, "failing");
    assert_eq!(uncertain.len(), 1, "{learned:?}");
    assert_eq!(failing.len(), 1, "{learned:?}");
    let (u, f) = (
        uncertain[0]["time"].as_f64().expect("time"),
        failing[0]["time"].as_f64().expect("time"),
    );
    assert!(u < f, "uncertain at {u} s, failing at {f} s");
    let (l, w) = (
        &learned.last().expect("end")["learning"],
        &watched.last().expect("end")["learning"],
    );
    eprintln!("learning {l}\nwatching {w}");
    assert!(l["queries"].as_u64() > Some(100), "{l}");
    assert_eq!(l["training_points"], 512, "{l}");
    assert_eq!(l["learned"], true);
    assert_eq!(w["learned"], false);
    let trained = w["training_points"].as_i64().expect("points");
    assert!(trained > 100 && trained < 512, "{w}");
    let worst = |alerts: &[Value]| {
        alerts.last().expect("end")["nmse"]
            .as_array()
            .expect("nmse")
            .iter()
            .map(|v| v.as_f64().expect("a number"))
            .fold(0.0, f64::max)
    };
    let (with, without) = (worst(&learned), worst(&watched));
    eprintln!("worst-floor NMSE: learning {with:.2} %, watching {without:.2} %");
    assert!(with < 0.9 * without, "{with} against {without}");

    // Stopped after 600 samples and resumed from the checkpoint (the corrector's training set
    // and lag buffer in its FMU state, the supervisor's threshold and counts in the
    // checkpoint): the same queries, training set and NMSE as one run.
    let dataset3 =
        std::fs::read_to_string(common::workspace().join("data/dataset3.csv")).expect("dataset3");
    let head: Vec<&str> = dataset3.lines().take(601).collect();
    let head_csv = dir.path().join("head.csv");
    std::fs::write(&head_csv, head.join("\n") + "\n").expect("write");
    let alerts = dir.path().join("resumed.jsonl");
    let checkpoint = dir.path().join("checkpoint.json");
    let checkpoint_args = [
        "--budget",
        "512",
        "--checkpoint",
        checkpoint.to_str().expect("utf-8"),
    ];
    let first = watch_corrected(head_csv.to_str().expect("utf-8"), &alerts, &checkpoint_args);
    assert_eq!(first.last().expect("end")["samples"], 600);
    let resumed = watch_corrected("dataset3.csv", &alerts, &checkpoint_args);
    let (a, b) = (resumed.last().expect("end"), learned.last().expect("end"));
    assert_eq!(a["samples_this_run"], 424);
    assert_eq!(a["learning"]["queries"], b["learning"]["queries"]);
    assert_eq!(
        a["learning"]["training_points"],
        b["learning"]["training_points"]
    );
    for f in 0..3 {
        let (x, y) = (
            a["nmse"][f].as_f64().expect("nmse"),
            b["nmse"][f].as_f64().expect("nmse"),
        );
        assert!(
            (x - y).abs() <= 1e-9 * y,
            "floor {}: {x} against {y}",
            f + 1
        );
    }
}

/// A stream of the hidden-change twin's structure (seed `seed`, its sensor noise, `duration`
/// s at 51.2 Hz) with the parameter `parameter` (`k2`, `m3`, …) × `factor` from `at` s on
/// (no change without one), as CSV text.
fn changed_stream(seed: u64, duration: f64, change: Option<(&str, f64, f64)>) -> String {
    stream_with(seed, duration, change.as_slice())
}

/// A change time drawn at random (a fixed seed per case) in `from..to` s, on the sample grid.
fn random_time(seed: u64, from: f64, to: f64) -> f64 {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let t: f64 = rng.gen_range(from..to);
    (t * 51.2).round() / 51.2
}

/// A storey's stiffness lost and a floor's mass added at random times: the `failing` alert
/// locates the change within a second, its interval within 0.1 s of it; the stream then ends
/// still failing, which the `end` alert says — no `recovered` is written. The same stream
/// without a change raises nothing. Measured (release): k2 −15 % at 10.449 s located at
/// 10.449 s [10.430, 10.449]; m3 +20 % at 8.516 s at 8.574 s [8.535, 8.594]; k1 −10 % at
/// 9.004 s at 9.082 s [9.082, 9.082] — errors 0 to 0.08 s against the 1 s asked, but the
/// interval can miss the truth by up to 0.08 s (hence the 0.1 s slack): the residual grows
/// from zero as the two structures' responses part, so the step is a little late and sharp.
#[test]
fn a_change_is_located_and_a_stream_that_ends_failing_is_not_recovered() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (case, change) in [("k2", 0.85), ("m3", 1.2), ("k1", 0.9)]
        .into_iter()
        .enumerate()
    {
        let at = random_time(100 + case as u64, 6.0, 14.0);
        let csv = dir.path().join(format!("change{case}.csv"));
        let text = changed_stream(10 + case as u64, at + 8.0, Some((change.0, at, change.1)));
        std::fs::write(&csv, text).expect("write");
        let alerts = watch(
            csv.to_str().expect("utf-8"),
            None,
            &dir.path().join(format!("change{case}.jsonl")),
            &[],
        );
        let failing = of_kind(&alerts, "failing");
        assert!(!failing.is_empty(), "{change:?} at {at}: {alerts:?}");
        let first = failing[0];
        let c = &first["change"];
        let (time, low, high) = (
            c["time"].as_f64().expect("a change time"),
            c["low"].as_f64().expect("low"),
            c["high"].as_f64().expect("high"),
        );
        eprintln!(
            "{change:?} at {at:.3} s: failing from {} (alert at {}), change {time:.3} s [{low:.3}, {high:.3}], error {:+.3} s",
            first["start"], first["time"], time - at
        );
        assert!((time - at).abs() <= 1.0, "{change:?} at {at}: {first}");
        assert!(
            low <= at + 0.1 && at - 0.1 <= high,
            "{change:?} at {at}: {first}"
        );
        // No recovery of a structure that stays changed; the end says it still fails.
        assert!(of_kind(&alerts, "recovered").is_empty(), "{alerts:?}");
        let end = alerts.last().expect("end");
        assert_eq!(end["kind"], "end");
        let still = end["still_failing"].as_array().expect("still failing");
        assert_eq!(still.len(), 1, "{end}");
        assert_eq!(
            still[0]["start"],
            failing.last().expect("a window")["start"]
        );
    }
    // No change, the same length: no alert at all but the end, nothing still failing.
    let csv = dir.path().join("none.csv");
    std::fs::write(&csv, changed_stream(10, 22.0, None)).expect("write");
    let alerts = watch(
        csv.to_str().expect("utf-8"),
        None,
        &dir.path().join("none.jsonl"),
        &[],
    );
    assert_eq!(alerts.len(), 1, "{alerts:?}");
    assert_eq!(alerts[0]["still_failing"], serde_json::json!([]));
}

/// A stream of the hidden-change twin's structure (its sensor noise, 51.2 Hz), `edit`ed, as CSV.
fn stream_of(
    seed: u64,
    duration: f64,
    edit: impl FnOnce(&mut orchestrator::synth::Scenario),
) -> String {
    use orchestrator::synth::{synth_record, GroundMotion, NoiseLevel, Scenario};
    let mut s = Scenario {
        seed,
        duration,
        ground: GroundMotion::for_duration(duration),
        ..Scenario::default()
    };
    s.noise.level = NoiseLevel::Sd(vec![HIDDEN_CHANGE_NOISE_SD; 3]);
    edit(&mut s);
    csv_text(&synth_record(&s).expect("synth").0.measurement)
}

/// A stream whose structure changes at `changes` (parameter, time, factor), as CSV.
fn stream_with(seed: u64, duration: f64, changes: &[(&str, f64, f64)]) -> String {
    use orchestrator::synth::{Change, ChangeHow, ParamName};
    stream_of(seed, duration, |s| {
        for &(parameter, at, factor) in changes {
            s.changes.push(Change {
                at,
                parameter: ParamName::parse(parameter).expect("a parameter"),
                how: ChangeHow::Factor(factor),
            });
        }
    })
}

/// `twin watch` of `csv` with `extra` flags, alerts to `NAME.jsonl`, a checkpoint beside.
fn watch_named(dir: &Path, name: &str, csv: &Path, extra: &[&str]) -> Vec<Value> {
    let alerts = dir.join(format!("{name}.jsonl"));
    let out = twin_cmd()
        .args(["watch", "--twin"])
        .arg(twin_path())
        .args(extra)
        .arg("--source")
        .arg(csv)
        .arg("--alerts")
        .arg(&alerts)
        .arg("--checkpoint")
        .arg(dir.join(format!("{name}.checkpoint.json")))
        .output()
        .expect("twin watch");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_alerts(&alerts)
}

/// The `end` alert's NMSE over the last window (after an adoption, the adopted twin's), and
/// the tolerance.
fn rolling_at_end(all: &[Value]) -> (Vec<f64>, f64) {
    let end = of_kind(all, "end")[0];
    let rolling = end["rolling_nmse"]
        .as_array()
        .expect("rolling_nmse")
        .iter()
        .map(|x| x.as_f64().unwrap_or(f64::NAN))
        .collect();
    (rolling, end["tolerance"].as_f64().expect("tolerance"))
}

/// A physics parameter of a twin written at `path`.
fn parameter_of(path: &Path, name: &str) -> f64 {
    let twin = orchestrator::twin::Twin::load(Some(path)).expect("the twin loads");
    match twin
        .component(orchestrator::twin::PHYSICS)
        .and_then(|c| c.parameters.get(name))
    {
        Some(orchestrator::twin::ParameterValue::Real(x)) => *x,
        other => panic!("{name}: {other:?}"),
    }
}

/// Every diagnosis after a located change ran on what came after it: its change within a
/// second of one of `truth`, its fits from that change's sample on (from the state the twin
/// reached there on at most 30 s of warm-up), never `update_data_model`.
fn assert_diagnosed_after(all: &[Value], truth: &[f64]) {
    let diagnoses = of_kind(all, "diagnosis");
    assert!(!diagnoses.is_empty(), "{all:?}");
    for d in diagnoses {
        let change = d["change_time"].as_f64().expect("a located change");
        assert!(truth.iter().any(|t| (change - t).abs() <= 1.0), "{d}");
        let fitted_from = d["fitted_from"].as_f64().expect("fitted_from");
        assert!(
            fitted_from >= change - 1e-6 && fitted_from < change + 1.0 / 51.2,
            "{d}"
        );
        assert!(
            d["from"].as_f64().expect("from") >= change - 30.0 - 1e-6,
            "{d}"
        );
        assert_ne!(d["action"], "update_data_model", "{d}");
    }
}

/// Unattended operation, two changes in a row at random times: storey 2 loses 15 % of its
/// stiffness, and 23–25 s later floor 3 gains 20 % of mass. Replayed with `--diagnosis-wait
/// --adopt`, each change is located, diagnosed on what came after it (from the state the twin
/// reached there), and once a look is firm (by its evidence, or two agreeing) the recalibrated
/// twin is written beside the alerts and swapped in at that sample; the comparison starts anew with it, the second change
/// opens a window of its own, and its answer is adopted on top of the first. No window fails
/// after, the stream ends with none failing, the NMSE over its last 20 s is under the
/// tolerance, and the checkpoint lists both twins. Watched
/// without its diagnoses, the same stream ends failing.
#[test]
fn changes_in_a_row_are_each_diagnosed_after_they_happened_and_adopted() {
    let dir = tempfile::tempdir().expect("tempdir");
    let first = random_time(201, 10.0, 20.0);
    let second = first + random_time(202, 23.0, 25.0);
    let csv = dir.path().join("record.csv");
    let changes = [("k2", first, 0.85), ("m3", second, 1.2)];
    // The stream goes on 20 s after the second answer's adoption (at most 31 s after it),
    // the NMSE over the last 20 s the adopted twin's.
    std::fs::write(&csv, stream_with(21, second + 51.0, &changes)).expect("write");
    let all = watch_named(
        dir.path(),
        "adopt",
        &csv,
        &["--diagnosis-wait", "--adopt", "--window", "20"],
    );
    assert_diagnosed_after(&all, &[first, second]);
    let adopted = of_kind(&all, "adopted");
    for a in &adopted {
        eprintln!("changes at {first:.3} and {second:.3} s: {a}");
    }
    assert_eq!(adopted.len(), 2, "{all:?}");
    assert_eq!(adopted[0]["verdict"], "recalibrate:k2", "{all:?}");
    assert_eq!(adopted[1]["verdict"], "recalibrate:m3", "{all:?}");
    let twin = |a: &Value| PathBuf::from(a["twin"].as_str().expect("the twin's path"));
    let before = |name: &str| parameter_of(twin_path(), name);
    let k2 = parameter_of(&twin(adopted[0]), "k2") / before("k2");
    let (k2_then, m3) = (
        parameter_of(&twin(adopted[1]), "k2") / before("k2"),
        parameter_of(&twin(adopted[1]), "m3") / before("m3"),
    );
    eprintln!("k2 × {k2:.4}; then k2 × {k2_then:.4}, m3 × {m3:.4}");
    assert!((k2 - 0.85).abs() < 0.02, "k2 × {k2}");
    assert!((k2_then - 0.85).abs() < 0.02, "k2 × {k2_then}");
    assert!((m3 - 1.2).abs() < 0.03, "m3 × {m3}");
    for a in &adopted {
        assert_eq!(a["from"], "its state over the samples kept", "{a}");
    }
    let last = adopted[1]["time"].as_f64().expect("time");
    assert!(
        of_kind(&all, "failing")
            .iter()
            .all(|f| f["time"].as_f64().is_some_and(|t| t < last)),
        "{all:?}"
    );
    assert_eq!(
        of_kind(&all, "end")[0]["still_failing"],
        serde_json::json!([]),
        "{all:?}"
    );
    let (rolling, tolerance) = rolling_at_end(&all);
    // Measured 0.071 / 0.163 / 0.220 % against the 0.5 % tolerance.
    eprintln!("two changes in a row: NMSE over the last 20 s at the end {rolling:.3?} %");
    assert!(rolling.iter().all(|&x| x < tolerance), "{rolling:?}");
    let checkpoint: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("adopt.checkpoint.json")).expect("checkpoint"),
    )
    .expect("json");
    for (k, a) in adopted.iter().enumerate() {
        assert_eq!(checkpoint["adopted"][k]["twin"], a["twin"], "{checkpoint}");
    }

    let kept = watch_named(dir.path(), "keep", &csv, &["--no-diagnosis"]);
    assert!(of_kind(&kept, "adopted").is_empty());
    assert_ne!(
        of_kind(&kept, "end")[0]["still_failing"],
        serde_json::json!([]),
        "{kept:?}"
    );
}

/// A damping change fails the band on and off: storey 2's damping tripled at a random time
/// opens and closes several windows, all the one change's — its looks keep their schedule from
/// the change located first, two agree on c2, and it is adopted.
#[test]
fn a_change_that_fails_on_and_off_is_one_change_looked_at_to_its_answer() {
    let dir = tempfile::tempdir().expect("tempdir");
    let at = random_time(203, 10.0, 20.0);
    let csv = dir.path().join("record.csv");
    std::fs::write(&csv, stream_with(7, at + 40.0, &[("c2", at, 3.0)])).expect("write");
    let all = watch_named(
        dir.path(),
        "damping",
        &csv,
        &["--diagnosis-wait", "--adopt"],
    );
    eprintln!(
        "change at {at:.3} s: {} failing windows",
        of_kind(&all, "failing").len()
    );
    assert_diagnosed_after(&all, &[at]);
    let diagnoses = of_kind(&all, "diagnosis");
    assert!(
        diagnoses
            .iter()
            .all(|d| d["fitted_from"] == diagnoses[0]["fitted_from"]),
        "{all:?}"
    );
    let adopted = of_kind(&all, "adopted");
    assert_eq!(adopted.len(), 1, "{all:?}");
    assert_eq!(adopted[0]["verdict"], "recalibrate:c2", "{all:?}");
    let (rolling, tolerance) = rolling_at_end(&all);
    // Measured 0.078 / 0.440 / 0.327 % against the 0.5 % tolerance.
    eprintln!("damping: NMSE over the last window at the end {rolling:.3?} %");
    assert!(rolling.iter().all(|&x| x < tolerance), "{rolling:?}");
}

/// A contact that starts: from a random time the force triples and floors 2 and 3 begin to
/// touch (a bumper of 0.5 mm, 9000 N/m). The watch's firm `add_physics` verdict is adopted —
/// the contact switched on in the twin with its jointly fitted gap and stiffness — and no
/// window fails after it.
#[test]
fn a_contact_that_starts_is_added_and_adopted() {
    use orchestrator::synth::ForceWindow;
    let dir = tempfile::tempdir().expect("tempdir");
    let at = random_time(204, 10.0, 20.0);
    let csv = dir.path().join("record.csv");
    let text = stream_of(9, at + 40.0, |s| {
        s.force.windows.push(ForceWindow {
            start: at,
            end: at + 40.0,
            gain: 3.0,
            ramp: 0.5,
        });
        s.effects.push(EffectSpec::Contact {
            lower: 2,
            gap: 5e-4,
            stiffness: 9000.0,
            side: 0,
        });
    });
    std::fs::write(&csv, text).expect("write");
    let all = watch_named(
        dir.path(),
        "contact",
        &csv,
        &["--diagnosis-wait", "--adopt"],
    );
    print_looks("contact", &all);
    for f in of_kind(&all, "failing") {
        eprintln!(
            "contact from {at:.3} s: failing {} {}",
            f["start"], f["change"]
        );
    }
    for d in of_kind(&all, "diagnosis") {
        eprintln!(
            "contact from {at:.3} s: look {} from the change at {}, {} s after it: {} {}, firm {}",
            d["round"],
            d["change_time"],
            d["post_change_seconds"],
            d["action"],
            d["effects"],
            d["firm"]
        );
    }
    // The contact was there all along (the bumper did not appear: the force tripled): the
    // firm look says it fits the samples before the change as well as the twin does.
    let firm = of_kind(&all, "diagnosis")
        .into_iter()
        .find(|d| d["firm"] == true)
        .expect("a firm look");
    eprintln!("contact: before the change {}", firm["before_the_change"]);
    assert_eq!(firm["before_the_change"]["consistent"], true, "{firm}");
    let adopted = of_kind(&all, "adopted");
    assert_eq!(adopted.len(), 1, "{all:?}");
    let a = adopted[0];
    eprintln!("contact from {at:.3} s: {a}");
    assert_eq!(a["verdict"], "add_physics:contact@2-3:both", "{a}");
    let twin = PathBuf::from(a["twin"].as_str().expect("the twin's path"));
    let gap = parameter_of(&twin, "contact23_gap");
    let stiffness = parameter_of(&twin, "contact23_stiffness");
    eprintln!("gap {gap:.4e} m, stiffness {stiffness:.0} N/m");
    assert!((gap / 5e-4 - 1.0).abs() < 0.05, "gap {gap}");
    assert!(
        (stiffness / 9000.0 - 1.0).abs() < 0.2,
        "stiffness {stiffness}"
    );
    let swapped = a["time"].as_f64().expect("time");
    assert!(
        of_kind(&all, "failing")
            .iter()
            .all(|f| f["time"].as_f64().is_some_and(|t| t < swapped)),
        "{all:?}"
    );
    assert_eq!(
        of_kind(&all, "end")[0]["still_failing"],
        serde_json::json!([]),
        "{all:?}"
    );
    let (rolling, tolerance) = rolling_at_end(&all);
    // Measured 0.009 / 0.015 / 0.023 % against the 0.5 % tolerance.
    eprintln!("contact: NMSE over the last window at the end {rolling:.3?} %");
    assert!(rolling.iter().all(|&x| x < tolerance), "{rolling:?}");
}

/// A kind of change at a random time: how the stream is made, and what the watch should answer.
struct Kind {
    name: &'static str,
    /// The change's time drawn from this seed.
    seed: u64,
    /// The stream, given the change's time.
    stream: fn(f64) -> String,
    /// The firm verdict.
    verdict: &'static str,
    /// Whether `--adopt` swaps its answer in (a sensor's fault is no structural change).
    adopted: bool,
    /// An effect that appears at the change (not there before).
    appears: bool,
}

/// Figures of one kind's stream, as measured.
struct Figures {
    change_error: f64,
    firm_after: f64,
    verdict: String,
    nmse_before: Vec<f64>,
    nmse_after: Vec<f64>,
    rolling_at_end: Vec<f64>,
}

/// A stream whose floor `floor` (1..) accelerometer reads `gain` × from `at` on.
fn gain_drop_stream(seed: u64, duration: f64, floor: usize, at: f64, gain: f64) -> String {
    use orchestrator::synth::{synth_record, GroundMotion, NoiseLevel, Scenario};
    let mut s = Scenario {
        seed,
        duration,
        ground: GroundMotion::for_duration(duration),
        ..Scenario::default()
    };
    s.noise.level = NoiseLevel::Sd(vec![HIDDEN_CHANGE_NOISE_SD; 3]);
    let mut m = synth_record(&s).expect("synth").0.measurement;
    let time = m.time.clone();
    for (a, t) in m.acc_mut(floor - 1).iter_mut().zip(&time) {
        if *t >= at - 1e-9 {
            *a *= gain;
        }
    }
    csv_text(&m)
}

/// Seconds each kind's stream goes on after its change: the looks' 30 s at most, and then
/// more than the rolling NMSE's window with the adopted twin.
const AFTER_CHANGE: f64 = 50.0;

fn kinds() -> Vec<Kind> {
    vec![
        Kind {
            name: "stiffness loss (k2 × 0.85)",
            seed: 301,
            stream: |at| stream_with(31, at + AFTER_CHANGE, &[("k2", at, 0.85)]),
            verdict: "recalibrate:k2",
            adopted: true,
            appears: false,
        },
        Kind {
            name: "added mass (m2 × 1.2)",
            seed: 302,
            stream: |at| stream_with(32, at + AFTER_CHANGE, &[("m2", at, 1.2)]),
            verdict: "recalibrate:m2",
            adopted: true,
            appears: false,
        },
        Kind {
            name: "sensor gain drop (acc3 × 0.8)",
            seed: 303,
            stream: |at| gain_drop_stream(33, at + AFTER_CHANGE, 3, at, 0.8),
            verdict: "sensor_fault:acc3",
            adopted: false,
            appears: false,
        },
        Kind {
            name: "friction appears (floor 1, 0.05 N)",
            seed: 304,
            stream: |at| {
                stream_of(34, at + AFTER_CHANGE, |s| {
                    s.effects.push(EffectSpec::Friction {
                        floor: 1,
                        force: 0.05,
                        velocity_scale: 1e-3,
                    });
                    s.effects_from = at;
                })
            },
            verdict: "add_physics:friction@1",
            adopted: true,
            appears: true,
        },
    ]
}

/// One kind's stream watched with `--diagnosis-wait --adopt`; its figures, after the checks
/// every kind shares: the first failing alert locates the change within a second, every look
/// is at what came after it and none answers `update_data_model`, a look is firm on
/// the right action and site within [`MAX_POST`] s of post-change data; the answer is adopted
/// when it is structural, after which nothing fails and the NMSE over the last window is under
/// the tolerance; a sensor's fault is never adopted, and its channel ends over the tolerance.
fn watch_a_kind(dir: &Path, kind: &Kind) -> Figures {
    let at = random_time(kind.seed, 10.0, 20.0);
    let csv = dir.join(format!("{}.csv", kind.seed));
    std::fs::write(&csv, (kind.stream)(at)).expect("write");
    let name = kind.seed.to_string();
    // The rolling NMSE over the last 20 s (all after an adoption 20–30 s after the change).
    let all = watch_named(
        dir,
        &name,
        &csv,
        &["--diagnosis-wait", "--adopt", "--window", "20"],
    );
    let label = format!("{} at {at:.3} s", kind.name);
    print_looks(&label, &all);
    let failing = of_kind(&all, "failing");
    assert!(!failing.is_empty(), "{label}: {all:?}");
    let located = failing[0]["change"]["time"].as_f64().expect("located");
    assert!((located - at).abs() <= 1.0, "{label}: {}", failing[0]);
    assert_diagnosed_after(&all, &[at]);
    let diagnoses = of_kind(&all, "diagnosis");
    let firm = diagnoses
        .iter()
        .find(|d| d["firm"] == true)
        .unwrap_or_else(|| panic!("{label}: no firm verdict in {diagnoses:?}"));
    let firm_after = firm["post_change_seconds"].as_f64().expect("seconds");
    assert!(firm_after <= MAX_POST + 1.0, "{label}: {firm}");
    // The alert says how long it waited and why that was enough.
    let waited = firm["waited"].as_str().expect("waited");
    assert!(
        waited.starts_with(&format!("{firm_after:.1} s of post-change data, because ")),
        "{label}: {firm}"
    );
    let verdict = background_verdict(firm);
    let first_look = background_verdict(diagnoses[0]);
    if kind.appears {
        // An effect that appeared at the change does not fit the samples before it.
        eprintln!("{label}: before the change {}", firm["before_the_change"]);
        assert_eq!(
            firm["before_the_change"]["consistent"], false,
            "{label}: {firm}"
        );
    }
    assert_eq!(verdict, kind.verdict, "{label}: {firm}");
    let adopted = of_kind(&all, "adopted");
    let end = of_kind(&all, "end")[0];
    let floats = |v: &Value| -> Vec<f64> {
        v.as_array()
            .expect("an array")
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect()
    };
    let rolling_at_end = floats(&end["rolling_nmse"]);
    eprintln!(
        "{label}: located {:+.3} s off; first look {first_look} after {:.1} s, firm {verdict} \
         after {firm_after:.1} s; NMSE {} → {} %; adopted {}; at the end {} %",
        located - at,
        diagnoses[0]["post_change_seconds"],
        firm["nmse_before"],
        firm["nmse_after"],
        adopted.len(),
        end["rolling_nmse"]
    );
    if kind.adopted {
        assert_eq!(adopted.len(), 1, "{label}: {all:?}");
        assert_eq!(adopted[0]["verdict"], kind.verdict, "{label}");
        let swapped = adopted[0]["time"].as_f64().expect("time");
        assert!(
            failing
                .iter()
                .all(|f| f["time"].as_f64().is_some_and(|t| t < swapped)),
            "{label}: {all:?}"
        );
        assert_eq!(end["still_failing"], serde_json::json!([]), "{label}");
        // Measured (%): k2 0.060 / 0.163 / 0.142, m2 0.080 / 0.188 / 0.158, friction 0.129 /
        // 0.324 / 0.338 (each adopted after 10 s of post-change data) — the 0.5 % tolerance
        // is the bar.
        let tolerance = end["tolerance"].as_f64().expect("tolerance");
        assert!(
            rolling_at_end.iter().all(|&x| x < tolerance),
            "{label}: {end}"
        );
    } else {
        // Not adopted: the faulty channel's NMSE over the last window is still over the
        // tolerance at the end, where it was within it before the fault.
        assert!(adopted.is_empty(), "{label}: {all:?}");
        let tolerance = end["tolerance"].as_f64().expect("tolerance");
        assert!(
            rolling_at_end.iter().any(|&x| x > tolerance),
            "{label}: {end}"
        );
    }
    Figures {
        change_error: located - at,
        firm_after,
        verdict,
        nmse_before: floats(&firm["nmse_before"]),
        nmse_after: floats(&firm["nmse_after"]),
        rolling_at_end,
    }
}

/// Each look's amount of post-change data, evidence and why it was firm, printed.
fn print_looks(label: &str, all: &[Value]) {
    for d in of_kind(all, "diagnosis") {
        eprintln!(
            "{label}: look {} after {:.1} s: {} {}, evidence {}, firm {} ({})",
            d["round"],
            d["post_change_seconds"].as_f64().unwrap_or(f64::NAN),
            d["action"],
            d["effects"].as_array().map_or(0, Vec::len),
            d["evidence"],
            d["firm"],
            d["waited"]
        );
    }
}

/// A diagnosis alert's verdict as the watch names it (`background::verdict`), read from its
/// report: the action and where (the parameter recalibration moved most, the effects, the
/// faulty sensor).
fn background_verdict(d: &Value) -> String {
    let r: Value = serde_json::from_str(
        &std::fs::read_to_string(d["report"].as_str().expect("a report")).expect("the report"),
    )
    .expect("json");
    let action = r["action"].as_str().expect("an action");
    let site = match action {
        "recalibrate" => r["recalibration"]["parameters"][0]["name"]
            .as_str()
            .unwrap_or_default()
            .to_owned(),
        "add_physics" => d["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .map(|e| e["label"].as_str().unwrap_or_default().to_owned())
            .collect::<Vec<_>>()
            .join("+"),
        "sensor_fault" => r["sensor"]["channel"]
            .as_str()
            .unwrap_or_default()
            .to_owned(),
        _ => String::new(),
    };
    format!("{action}:{site}")
}

const MAX_POST: f64 = 30.0;

/// Every kind of change the library knows, each at a random time in a stream of its own (the
/// streams watched side by side): a storey's stiffness lost, a floor's mass added, a sensor's
/// gain dropped, friction that appears (a contact that starts has its own test above). Each
/// is located within a second, diagnosed on what came after it (the window the watch would
/// otherwise have taken — the last `--diagnosis-record` s — straddles the change), firm on the
/// right action and site within 30 s of post-change data, and adopted unless it is a sensor's
/// fault. The figures per kind are printed (`--nocapture`).
#[test]
fn every_kind_of_change_is_located_diagnosed_after_it_and_adopted_when_structural() {
    let dir = tempfile::tempdir().expect("tempdir");
    let kinds = kinds();
    let figures: Vec<Figures> = std::thread::scope(|scope| {
        let handles: Vec<_> = kinds
            .iter()
            .map(|k| scope.spawn(|| watch_a_kind(dir.path(), k)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a kind's checks"))
            .collect()
    });
    for (k, f) in kinds.iter().zip(&figures) {
        eprintln!(
            "{}: change located {:+.3} s off, firm {} after {:.1} s of post-change data, \
             NMSE {:.3?} → {:.3?} % on them, rolling NMSE at the end {:.3?} %",
            k.name,
            f.change_error,
            f.verdict,
            f.firm_after,
            f.nmse_before,
            f.nmse_after,
            f.rolling_at_end
        );
    }
}

/// Two hours of the unchanged structure, watched as in operation (the diagnosis on, `--adopt`):
/// no alert but the end — no failing window, no located change, no diagnosis, nothing adopted.
#[test]
fn two_hours_without_a_change_raise_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("record.csv");
    std::fs::write(&csv, stream_with(41, 7200.0, &[])).expect("write");
    let all = watch_named(dir.path(), "hours", &csv, &["--diagnosis-wait", "--adopt"]);
    let end = all.last().expect("an end alert");
    eprintln!("two hours unchanged: NMSE {} %", end["nmse"]);
    assert_eq!(all.len(), 1, "{all:?}");
    assert_eq!(end["kind"], "end");
    assert_eq!(end["samples"], 7200 * 512 / 10, "{end}");
    assert_eq!(end["failing_windows"], 0, "{end}");
    assert_eq!(end["still_failing"], serde_json::json!([]), "{end}");
}

/// Half an hour of the unchanged structure under each of two coloured forces, watched as in
/// operation (the diagnosis on, `--adopt`): a band-limited force (1–20 Hz) and a low-passed
/// one (below 5 Hz: most of its power at the first mode), each held linear between the samples
/// as the twin holds it. No alert but the end: no failing window, no diagnosis, nothing
/// adopted. (The same band-limited force smooth between the samples, as a shaker's is, opened a
/// window at 209.7 s, acc2 at 1.3 % NMSE: this twin was calibrated on a force held linear, and
/// the hold's error is outside its noise band. A twin calibrated on the stream's own first
/// minutes, as at commissioning, is not tested here.)
#[test]
fn half_hours_of_coloured_forces_without_a_change_raise_nothing() {
    use orchestrator::synth::BetweenSamples;
    let dir = tempfile::tempdir().expect("tempdir");
    let forces: [(&str, f64, Option<f64>, BetweenSamples); 2] = [
        (
            "band-limited 1-20 Hz",
            1.0,
            Some(20.0),
            BetweenSamples::Linear,
        ),
        ("low-passed 0-5 Hz", 0.0, Some(5.0), BetweenSamples::Linear),
    ];
    std::thread::scope(|scope| {
        for (k, (name, low, band, between)) in forces.into_iter().enumerate() {
            let dir = dir.path();
            scope.spawn(move || {
                let csv = dir.join(format!("coloured{k}.csv"));
                let text = stream_of(42 + k as u64, 1800.0, |s| {
                    s.force.low_hz = low;
                    s.force.band_hz = band;
                    s.force.between_samples = between;
                });
                std::fs::write(&csv, text).expect("write");
                let all = watch_named(
                    dir,
                    &format!("coloured{k}"),
                    &csv,
                    &["--diagnosis-wait", "--adopt"],
                );
                let end = all.last().expect("an end alert");
                eprintln!("{name}, half an hour unchanged: NMSE {} %", end["nmse"]);
                assert_eq!(all.len(), 1, "{name}: {all:?}");
                assert_eq!(end["kind"], "end", "{name}");
                assert_eq!(end["failing_windows"], 0, "{name}: {end}");
            });
        }
    });
}

/// The same band-limited force (1–20 Hz) smooth between the samples, as a shaker's is, and a
/// twin calibrated at commissioning on the stream's own first minute (`twin calibrate`): ten
/// minutes of the unchanged structure after it raise nothing but the end — the hold of the
/// force between samples is part of what a twin is calibrated on, so a twin calibrated on a
/// force held linear is not the one to watch this stream with (see the test above). Measured:
/// no failing window, NMSE 0.057 / 0.162 / 0.129 % at the end (tolerance 0.5 %).
#[test]
fn a_twin_calibrated_at_commissioning_watches_a_smooth_force_without_an_alarm() {
    use orchestrator::synth::BetweenSamples;
    let dir = tempfile::tempdir().expect("tempdir");
    let text = stream_of(43, 660.0, |s| {
        s.force.low_hz = 1.0;
        s.force.band_hz = Some(20.0);
        s.force.between_samples = BetweenSamples::BandLimited;
    });
    // The first minute (its header and 60 s × 51.2 Hz samples) to calibrate on.
    let minute: Vec<&str> = text.lines().take(1 + 3072).collect();
    let first = dir.path().join("first-minute.csv");
    std::fs::write(&first, minute.join("\n") + "\n").expect("write");
    let stream = dir.path().join("stream.csv");
    std::fs::write(&stream, &text).expect("write");
    let twin = dir.path().join("commissioned.ssp");
    let (first, twin_arg) = (
        first.to_str().expect("utf-8"),
        twin.to_str().expect("utf-8"),
    );
    common::twin_ok(&["calibrate", "--data", first, "--out", twin_arg]);
    let alerts = dir.path().join("alerts.jsonl");
    let out = twin_cmd()
        .args([
            "watch",
            "--diagnosis-wait",
            "--adopt",
            "--twin",
            twin_arg,
            "--source",
        ])
        .arg(&stream)
        .arg("--alerts")
        .arg(&alerts)
        .output()
        .expect("twin watch");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let all = read_alerts(&alerts);
    let end = all.last().expect("an end alert");
    eprintln!("smooth force, commissioned twin: NMSE {} %", end["nmse"]);
    assert_eq!(all.len(), 1, "{all:?}");
    assert_eq!(end["kind"], "end");
    assert_eq!(end["failing_windows"], 0, "{end}");
}

/// Alerts without what depends on the machine (speeds, latencies, a diagnosis's wall time, this
/// run's count) and with the files beside the alerts named relative to their directory.
fn comparable_in(alerts: &[Value], dir: &Path) -> Vec<Value> {
    let prefix = format!("{}/", dir.display());
    comparable(alerts)
        .into_iter()
        .map(|mut a| {
            if let Value::Object(m) = &mut a {
                m.remove("seconds");
                for value in m.values_mut() {
                    if let Some(path) = value.as_str().and_then(|s| s.strip_prefix(&prefix)) {
                        *value = Value::String(path.to_owned());
                    }
                }
            }
            a
        })
        .collect()
}

/// `twin watch` gives the same alerts with a live page as without one: a stream with a change
/// (its failing window, change location, diagnoses and adoption) watched from a file, and
/// piped into a watch serving its page on a loopback port with a client reading the page's
/// event stream from the middle of the stream on.
#[test]
fn a_watch_with_a_page_gives_the_alerts_of_one_without() {
    use std::io::{BufRead, BufReader, Read};
    let dir = tempfile::tempdir().expect("tempdir");
    let at = random_time(305, 10.0, 20.0);
    let text = stream_with(35, at + 35.0, &[("k2", at, 0.85)]);
    let plain_dir = dir.path().join("plain");
    let paged_dir = dir.path().join("paged");
    for d in [&plain_dir, &paged_dir] {
        std::fs::create_dir(d).expect("mkdir");
    }
    let csv = plain_dir.join("record.csv");
    std::fs::write(&csv, &text).expect("write");
    let flags = ["--diagnosis-wait", "--adopt"];
    let plain = watch_named(&plain_dir, "alerts", &csv, &flags);

    let mut child = twin_cmd()
        .args(["watch", "--twin"])
        .arg(twin_path())
        .args(flags)
        .args(["--serve", "127.0.0.1:0", "--source", "-", "--alerts"])
        .arg(paged_dir.join("alerts.jsonl"))
        .arg("--checkpoint")
        .arg(paged_dir.join("alerts.checkpoint.json"))
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn twin watch --serve");
    let mut stderr = BufReader::new(child.stderr.take().expect("stderr"));
    let mut line = String::new();
    stderr.read_line(&mut line).expect("the serving line");
    let addr = line
        .trim()
        .strip_prefix("serving http://")
        .and_then(|s| s.strip_suffix('/'))
        .unwrap_or_else(|| panic!("no serving line: {line:?}"))
        .to_owned();
    let drain = std::thread::spawn(move || {
        let mut rest = String::new();
        let _ = stderr.read_to_string(&mut rest);
        rest
    });
    let lines: Vec<&str> = text.lines().collect();
    let half = lines.len() / 2;
    let mut stdin = child.stdin.take().expect("stdin");
    stdin
        .write_all((lines[..half].join("\n") + "\n").as_bytes())
        .expect("the first half");
    let client = std::thread::spawn(move || {
        let mut stream = std::net::TcpStream::connect(&addr).expect("connect to the page");
        stream
            .set_read_timeout(Some(Duration::from_secs(120)))
            .expect("timeout");
        write!(
            stream,
            "GET /events HTTP/1.1\r\nHost: {addr}\r\nAccept: text/event-stream\r\n\r\n"
        )
        .expect("request");
        let mut seen = String::new();
        let _ = stream.read_to_string(&mut seen);
        seen
    });
    // The client is connected before the rest of the stream comes.
    std::thread::sleep(Duration::from_millis(500));
    stdin
        .write_all((lines[half..].join("\n") + "\n").as_bytes())
        .expect("the second half");
    drop(stdin);
    let status = child.wait().expect("twin watch --serve");
    let errors = drain.join().expect("stderr");
    assert!(status.success(), "{errors}");
    let seen = client.join().expect("the page's client");
    let paged = read_alerts(&paged_dir.join("alerts.jsonl"));
    assert!(
        seen.contains("adopted"),
        "the page saw the adoption: {seen:.2000}"
    );
    assert!(!of_kind(&plain, "adopted").is_empty(), "{plain:?}");
    assert_eq!(
        comparable_in(&plain, &plain_dir),
        comparable_in(&paged, &paged_dir)
    );
}

/// A second change in the middle of the looks at a first — in what would otherwise be the
/// first's diagnosis window: storey 2 loses 15 % of its stiffness at a random time, and floor 3
/// gains 20 % of mass 13–17 s later, after the first look (10 s) and before the second (20 s),
/// whose samples would mix the two structures (a mixed window answered `update_data_model`,
/// firm, and the stream ended failing). Either the first look is firm by its own evidence and
/// its answer adopted before the second change, which is then located as a change of its own;
/// or the second look finds the second change in the residuals of the first look's answer and
/// answers on the samples before it, and the second change is looked at on its own once the
/// first answer is adopted. Both answers adopted, nothing fails after, and the NMSE over the
/// last 20 s is back under the tolerance. Measured: the first look, at 10 s, firm on k2 (its
/// log evidence 1334 over the best effect's, k2 moved 71.5 posterior sd, 61× any other, its sd
/// 0.24 %), adopted at 28.301 s; the second change located at 31.895 s for 31.895 s, m3 firm
/// at its first look; k2 × 0.8523, m3 × 1.2090, the NMSE over the last 20 s 0.082 / 0.135 /
/// 0.216 % (tolerance 0.5 %). (With two agreeing looks required, the second look had found the
/// second change at 31.895 s; with the first answer run from rest over samples of the old
/// structure, m3 had come out × 1.212 and the NMSE 0.17 / 0.76 / 1.53 %.)
#[test]
fn a_change_in_the_middle_of_the_looks_at_another_is_found_and_looked_at_on_its_own() {
    let dir = tempfile::tempdir().expect("tempdir");
    let first = random_time(206, 10.0, 20.0);
    let second = first + random_time(207, 13.0, 17.0);
    let csv = dir.path().join("record.csv");
    let changes = [("k2", first, 0.85), ("m3", second, 1.2)];
    std::fs::write(&csv, stream_with(26, second + 45.0, &changes)).expect("write");
    let all = watch_named(
        dir.path(),
        "middle",
        &csv,
        &["--diagnosis-wait", "--adopt", "--window", "20"],
    );
    print_looks("middle", &all);
    assert_diagnosed_after(&all, &[first, second]);
    let cut: Vec<&Value> = of_kind(&all, "diagnosis")
        .into_iter()
        .filter(|d| !d["second_change"].is_null())
        .collect();
    let adopted = of_kind(&all, "adopted");
    assert!(cut.len() <= 1, "{all:?}");
    if let Some(cut) = cut.first() {
        // Found inside the looks at the first.
        let found = cut["second_change"]["time"].as_f64().expect("a time");
        eprintln!(
            "changes at {first:.3} and {second:.3} s: the second found at {found:.3} s by look {}",
            cut["round"]
        );
        assert!((found - second).abs() <= 1.0, "{cut}");
        assert!(cut["to"].as_f64().expect("to") < second, "{cut}");
    } else {
        // The first answer was firm and adopted before it: located as a change of its own.
        let swapped = adopted[0]["time"].as_f64().expect("time");
        assert!(swapped < second, "{all:?}");
        let located: Vec<f64> = of_kind(&all, "failing")
            .iter()
            .filter_map(|f| f["change"]["time"].as_f64())
            .collect();
        eprintln!(
            "changes at {first:.3} and {second:.3} s: the first adopted at {swapped:.3} s, \
             changes located at {located:.3?} s"
        );
        assert!(located.iter().any(|t| (t - second).abs() <= 1.0), "{all:?}");
    }
    assert_eq!(adopted.len(), 2, "{all:?}");
    assert_eq!(adopted[0]["verdict"], "recalibrate:k2", "{all:?}");
    assert_eq!(adopted[1]["verdict"], "recalibrate:m3", "{all:?}");
    let twin = |a: &Value| PathBuf::from(a["twin"].as_str().expect("the twin's path"));
    let before = |name: &str| parameter_of(twin_path(), name);
    let (k2, m3) = (
        parameter_of(&twin(adopted[1]), "k2") / before("k2"),
        parameter_of(&twin(adopted[1]), "m3") / before("m3"),
    );
    let end = of_kind(&all, "end")[0];
    eprintln!(
        "k2 × {k2:.4}, m3 × {m3:.4}; NMSE over the last 20 s {} %",
        end["rolling_nmse"]
    );
    // Measured errors 0.0023 and 0.0090: bars about twice those.
    assert!((k2 - 0.85).abs() < 0.005, "k2 × {k2}");
    assert!((m3 - 1.2).abs() < 0.02, "m3 × {m3}");
    let last = adopted[1]["time"].as_f64().expect("time");
    assert!(
        of_kind(&all, "failing")
            .iter()
            .all(|f| f["time"].as_f64().is_some_and(|t| t < last)),
        "{all:?}"
    );
    assert_eq!(end["still_failing"], serde_json::json!([]), "{end}");
    // Under the tolerance on every floor (measured worst 0.216 % against 0.5 %).
    let tolerance = end["tolerance"].as_f64().expect("tolerance");
    assert!(
        end["rolling_nmse"]
            .as_array()
            .expect("nmse")
            .iter()
            .all(|x| x.as_f64().is_some_and(|x| x < tolerance)),
        "{end}"
    );
}
