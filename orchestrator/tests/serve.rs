//! The live page's server without a watch: the hub stays bounded and never waits on a browser
//! (a stalled one is dropped), the decimation keeps 50 points a second of stream, and the
//! HTTP side answers bad requests with JSON errors (401 without a token, 403 with a wrong one
//! or on a read-only page, 400 for a malformed body) and keeps serving.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use orchestrator::serve::http::Actions;
use orchestrator::serve::hub::{Hub, Kind, Limits};
use orchestrator::serve::live::{LiveView, WALL_BURST, WALL_RATE};
use orchestrator::workflows::watch::{Observer, Point};
use serde_json::{json, Value};

fn small_limits() -> Limits {
    Limits {
        points: 100,
        events: 20,
        queue: 64,
        clients: 8,
    }
}

fn point(t: f64) -> Value {
    json!({"type": "point", "t": t, "y": [t], "p": [t], "nmse": [0.1], "open": false})
}

#[test]
fn the_history_is_bounded_and_starts_with_the_meta() {
    let hub = Hub::new(small_limits());
    hub.publish(Kind::Meta, json!({"type": "meta", "channels": ["acc1"]}));
    for k in 0..1000 {
        hub.publish(Kind::Point, point(k as f64));
    }
    for k in 0..50 {
        hub.publish(
            Kind::Other,
            json!({"type": "alert", "alert": {"seq": k + 1, "kind": "gap"}}),
        );
    }
    hub.publish(Kind::State, json!({"type": "state", "samples": 1}));
    hub.publish(Kind::State, json!({"type": "state", "samples": 2}));
    let sub = hub.subscribe().expect("a client");
    let texts: Vec<Value> = sub
        .history
        .iter()
        .map(|p| serde_json::from_str(&p.text).expect("JSON"))
        .collect();
    assert_eq!(texts[0]["type"], "meta");
    let count = |kind: &str| texts.iter().filter(|v| v["type"] == kind).count();
    assert_eq!(count("point"), 100);
    assert_eq!(count("alert"), 20);
    assert_eq!(count("state"), 1, "the latest state only");
    // The newest kept, in order.
    let last_point = texts
        .iter()
        .rev()
        .find(|v| v["type"] == "point")
        .expect("a point");
    assert_eq!(last_point["t"], 999.0);
    let seqs: Vec<u64> = sub.history.iter().skip(1).map(|p| p.seq).collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "in sequence");
    assert!(
        hub.has_alert(50) && !hub.has_alert(1),
        "the last alerts are known for /api/ack"
    );
}

#[test]
fn a_client_that_never_reads_is_dropped_and_never_blocks_the_publisher() {
    let hub = Hub::new(small_limits());
    let stalled = hub.subscribe().expect("a client");
    let mut reader = hub.subscribe().expect("another");
    // 100 000 events with a client that never reads: the publisher goes on; the stalled
    // client's queue (64) fills and it is dropped, once.
    let mut delivered = 0;
    for k in 0..100_000 {
        hub.publish(Kind::Point, point(k as f64));
        while reader.live.try_recv().is_ok() {
            delivered += 1;
        }
    }
    let stats = hub.stats();
    assert_eq!(stats.published, 100_000);
    assert_eq!(stats.dropped_clients, 1, "{stats:?}");
    assert_eq!(stats.clients, 1, "the reading client stays");
    assert_eq!(delivered, 100_000, "the reading client got everything");
    drop(stalled);
}

#[test]
fn no_more_clients_than_the_limit() {
    let hub = Hub::new(small_limits());
    let held: Vec<_> = (0..8).map(|_| hub.subscribe().expect("a client")).collect();
    assert!(hub.subscribe().is_none());
    drop(held);
    assert!(
        hub.subscribe().is_some(),
        "closed clients free their places"
    );
}

fn shown_points(view: &mut LiveView, rate: f64, seconds: f64) -> u64 {
    let measured = [0.0, 1.0];
    let predicted = [0.0, 1.0];
    let n = (rate * seconds) as usize;
    let mut shown = 0;
    for k in 0..n {
        let t = k as f64 / rate;
        if view.due(t) {
            shown += 1;
            view.point(&Point {
                time: t,
                read_at: SystemTime::now(),
                measured: &measured,
                predicted: &predicted,
                band: Some(vec![0.1, 0.1]),
                latent_sd: None,
                rolling_nmse: vec![0.1, f64::NAN],
                open_window: false,
            });
        }
    }
    shown
}

#[test]
fn a_khz_stream_is_decimated_to_50_points_a_second_of_stream() {
    let hub = Hub::new(Limits::default());
    let mut view = LiveView::new(hub.clone(), "test".into(), false).with_steps(0.02, f64::INFINITY);
    // 10 s at 1 kHz: one point per 20 ms of stream (the first sample shown too).
    let shown = shown_points(&mut view, 1000.0, 10.0);
    assert!((499..=501).contains(&shown), "{shown} points");
    assert_eq!(hub.stats().published, shown);
    let sub = hub.subscribe().expect("client");
    let p: Value = serde_json::from_str(&sub.history.last().expect("a point").text).expect("JSON");
    assert_eq!(p["nmse"][1], Value::Null, "NaN is null");
    assert!(
        p["wall"].as_f64().is_some_and(|w| w > 1.6e12),
        "the wall time in ms: {p}"
    );
}

#[test]
fn a_stream_faster_than_the_wall_rate_is_decimated_by_wall_time() {
    let hub = Hub::new(Limits::default());
    // The page's defaults: 20 ms of stream between points, 250 points a second of wall time
    // after a burst of 50.
    let mut view = LiveView::new(hub.clone(), "test".into(), false);
    let started = Instant::now();
    // 1000 s of a 1 kHz stream, as fast as the loop goes (far above real time).
    let shown = shown_points(&mut view, 1000.0, 1000.0);
    let elapsed = started.elapsed().as_secs_f64();
    let bound = (elapsed * WALL_RATE).ceil() as u64 + WALL_BURST as u64 + 1;
    assert!(
        shown <= bound,
        "{shown} points in {elapsed:.3} s: above {bound}"
    );
    assert!(shown < 50_000, "fewer than 50 a second of stream: {shown}");
}

// The HTTP side.

fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, Value) {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .expect("timeout");
    let mut text = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        text.push_str(&format!("{k}: {v}\r\n"));
    }
    text.push_str("\r\n");
    text.push_str(body);
    stream.write_all(text.as_bytes()).expect("send");
    let mut answer = String::new();
    stream.read_to_string(&mut answer).expect("read");
    let status: u16 = answer
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("a status line");
    let body = answer.split("\r\n\r\n").nth(1).unwrap_or_default();
    if let Ok(value) = serde_json::from_str(body.trim()) {
        return (status, value);
    }
    // A chunked body's JSON sits between its size lines.
    let json = body
        .find('{')
        .and_then(|a| body.rfind('}').map(|b| &body[a..=b]))
        .or_else(|| {
            body.find('[')
                .and_then(|a| body.rfind(']').map(|b| &body[a..=b]))
        })
        .unwrap_or("null");
    (status, serde_json::from_str(json).unwrap_or(Value::Null))
}

struct Served {
    hub: Arc<Hub>,
    server: orchestrator::serve::Server,
    acks: PathBuf,
    _dir: tempfile::TempDir,
}

fn serve(token: Option<&str>) -> Served {
    serve_with(token, small_limits())
}

fn serve_with(token: Option<&str>, limits: Limits) -> Served {
    let dir = tempfile::tempdir().expect("tempdir");
    let acks = dir.path().join("alerts.acks.jsonl");
    let hub = Hub::new(limits);
    hub.publish(
        Kind::Meta,
        json!({"type": "meta", "channels": ["acc1"], "run": "test"}),
    );
    hub.publish(
        Kind::Other,
        json!({"type": "alert", "alert": {"seq": 3, "kind": "failing", "time": 12.5}}),
    );
    let actions = Actions {
        token: token.map(str::to_owned),
        acks: Some(acks.clone()),
        twin: None,
        binary: None,
    };
    let server = orchestrator::serve::start(
        "127.0.0.1:0".parse().expect("address"),
        hub.clone(),
        Default::default(),
        actions,
    )
    .expect("serve");
    Served {
        hub,
        server,
        acks,
        _dir: dir,
    }
}

#[test]
fn the_mutating_endpoints_want_the_token_and_a_well_formed_body() {
    let s = serve(Some("sesame"));
    let addr = s.server.addr;
    let good = [
        ("Authorization", "Bearer sesame"),
        ("Content-Type", "application/json"),
    ];
    let (status, body) = request(addr, "POST", "/api/ack", &[], r#"{"seq": 3}"#);
    assert_eq!(status, 401, "{body}");
    assert!(
        body["error"]
            .as_str()
            .is_some_and(|e| e.contains("POST /api/ack: no token")),
        "{body}"
    );
    let (status, body) = request(
        addr,
        "POST",
        "/api/ack",
        &[("Authorization", "Bearer open")],
        r#"{"seq": 3}"#,
    );
    assert_eq!(status, 403, "{body}");
    assert!(
        body["error"]
            .as_str()
            .is_some_and(|e| e.contains("wrong token")),
        "{body}"
    );
    for (bad, why) in [
        ("{not json", "the body is not JSON"),
        ("[1, 2]", "not an object"),
        (
            r#"{"seq": "three"}"#,
            "\"seq\" is missing or not a positive integer",
        ),
        (r#"{"seq": 3, "note": 5}"#, "\"note\" must be a string"),
    ] {
        let (status, body) = request(addr, "POST", "/api/ack", &good, bad);
        assert_eq!(status, 400, "{bad}: {body}");
        let e = body["error"].as_str().unwrap_or_default();
        assert!(
            e.starts_with("POST /api/ack: ") && e.contains(why),
            "{bad}: {e}"
        );
    }
    let (status, body) = request(addr, "POST", "/api/ack", &good, r#"{"seq": 99}"#);
    assert_eq!(status, 404, "{body}");
    let (status, body) = request(addr, "POST", "/api/accept", &good, r#"{"diagnosis": "x"}"#);
    assert_eq!(status, 400, "{body}");
    let (status, body) = request(addr, "POST", "/api/accept", &good, "{}");
    assert_eq!(status, 409, "no diagnosis yet: {body}");
    // After all that, the page still serves, and a good acknowledgement is written.
    let (status, body) = request(
        addr,
        "POST",
        "/api/ack",
        &good,
        r#"{"seq": 3, "note": "seen"}"#,
    );
    assert_eq!((status, &body["acknowledged"]), (200, &json!(3)), "{body}");
    let line: Value = serde_json::from_str(
        std::fs::read_to_string(&s.acks)
            .expect("the acks file")
            .lines()
            .next()
            .expect("a line"),
    )
    .expect("JSON");
    assert_eq!(
        (&line["kind"], &line["ack"], &line["note"]),
        (&json!("acknowledged"), &json!(3), &json!("seen"))
    );
    let (status, history) = request(addr, "GET", "/api/history", &[], "");
    assert_eq!(status, 200);
    let kinds: Vec<&str> = history
        .as_array()
        .expect("an array")
        .iter()
        .filter_map(|e| e["alert"]["kind"].as_str())
        .collect();
    assert_eq!(kinds, ["failing", "acknowledged"]);
    assert_eq!(s.hub.stats().dropped_clients, 0);
}

#[test]
fn a_read_only_page_refuses_changes_and_unknown_routes_are_404() {
    let s = serve(None);
    let addr = s.server.addr;
    let (status, body) = request(
        addr,
        "POST",
        "/api/ack",
        &[("Authorization", "Bearer x")],
        r#"{"seq": 3}"#,
    );
    assert_eq!(status, 403, "{body}");
    assert!(
        body["error"]
            .as_str()
            .is_some_and(|e| e.contains("read-only")),
        "{body}"
    );
    let (status, _) = request(addr, "GET", "/nothing", &[], "");
    assert_eq!(status, 404);
    let (status, body) = request(addr, "GET", "/events?view=nobody", &[], "");
    assert_eq!(status, 404, "{body}");
    assert!(!s.acks.exists());
}

/// Ten event streams, one of them a socket that never reads: the publisher goes on, the
/// stalled one is dropped, a reading one gets the last event.
#[test]
fn a_stalled_browser_does_not_hold_up_the_others() {
    let s = serve_with(
        None,
        Limits {
            clients: 16,
            ..small_limits()
        },
    );
    let addr = s.server.addr;
    let open = |addr: SocketAddr| {
        std::thread::sleep(Duration::from_millis(20));
        let mut stream = TcpStream::connect(addr).expect("connect");
        stream
            .write_all(format!("GET /events HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes())
            .expect("send");
        stream
    };
    let stalled = open(addr);
    let mut reader = open(addr);
    reader
        .set_read_timeout(Some(Duration::from_secs(60)))
        .expect("timeout");
    let readers: Vec<TcpStream> = (0..8).map(|_| open(addr)).collect();
    // Wait until the server has all ten clients.
    let deadline = Instant::now() + Duration::from_secs(60);
    while s.hub.stats().clients < 10 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(s.hub.stats().clients, 10);
    drop(readers);
    // Big events, so the stalled socket's buffers fill and its queue (64) with them. The
    // publisher waits for the reading browser after every 32 events (half its queue), so that
    // browser is never the slow one however loaded the machine; the stalled one falls behind
    // by the whole stream. `seen` is the largest point number the reader has read.
    let filler = "x".repeat(4096);
    let seen = Arc::new(std::sync::atomic::AtomicI64::new(-1));
    let reader_seen = seen.clone();
    let reading = std::thread::spawn(move || {
        let mut tail = Vec::new();
        let mut buffer = [0u8; 65536];
        loop {
            match reader.read(&mut buffer) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    tail.extend_from_slice(&buffer[..n]);
                    let text = String::from_utf8_lossy(&tail).into_owned();
                    if text.contains("\"last\":true") {
                        return true;
                    }
                    // Points are written {"filler":…,"t":K,"type":"point"}: the last whole K.
                    if let Some(at) = text.rfind(",\"type\":\"point\"") {
                        if let Some(start) = text[..at].rfind("\"t\":") {
                            if let Ok(k) = text[start + 4..at].parse::<i64>() {
                                reader_seen.fetch_max(k, std::sync::atomic::Ordering::SeqCst);
                            }
                        }
                    }
                    if tail.len() > 1 << 16 {
                        tail.drain(..tail.len() - 8192);
                    }
                }
            }
        }
        false
    });
    let events: i64 = 20_000;
    for k in 0..events {
        s.hub.publish(
            Kind::Point,
            json!({"type": "point", "t": k, "filler": filler}),
        );
        if k % 32 == 31 {
            let deadline = Instant::now() + Duration::from_secs(60);
            while seen.load(std::sync::atomic::Ordering::SeqCst) < k && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(1));
            }
            assert!(
                seen.load(std::sync::atomic::Ordering::SeqCst) >= k,
                "the reading browser did not get point {k} within 60 s"
            );
        }
    }
    s.hub
        .publish(Kind::Other, json!({"type": "end", "last": true}));
    assert!(
        reading.join().expect("reader"),
        "the reading browser got the last event"
    );
    let stats = s.hub.stats();
    assert!(
        stats.dropped_clients >= 1,
        "the stalled browser was dropped: {stats:?}"
    );
    drop(stalled);
}
