//! The page's routes: the assets, `GET /events` (server-sent events: the history, then what
//! comes), `GET /api/stats`, `GET /api/history`, and with a token `POST /api/ack` and
//! `POST /api/accept`. Errors are JSON objects `{"error": "..."}` naming the request.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use axum::extract::{Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use futures_util::StreamExt;
use serde_json::{json, Value};

use super::hub::{Hub, Kind, Published};

const INDEX: &str = include_str!("assets/index.html");
const SCRIPT: &str = include_str!("assets/page.js");
const STYLE: &str = include_str!("assets/page.css");

/// What the mutating endpoints may do.
#[derive(Debug, Clone, Default)]
pub struct Actions {
    /// The token `POST /api/ack` and `/api/accept` need (None: read-only).
    pub token: Option<String>,
    /// Where acknowledgements go, one JSON line each (beside the alerts).
    pub acks: Option<PathBuf>,
    /// The twin a diagnosis is accepted into (a new twin beside it).
    pub twin: Option<PathBuf>,
    /// The `twin` binary that runs `add-physics` (this one).
    pub binary: Option<PathBuf>,
}

pub struct App {
    /// The page's own view, and the fleet's structures by name (`/events?view=NAME`).
    pub hub: Arc<Hub>,
    pub views: BTreeMap<String, Arc<Hub>>,
    pub actions: Actions,
    acks: Mutex<()>,
    accepting: AtomicBool,
}

impl App {
    pub fn new(hub: Arc<Hub>, views: BTreeMap<String, Arc<Hub>>, actions: Actions) -> Self {
        App {
            hub,
            views,
            actions,
            acks: Mutex::new(()),
            accepting: AtomicBool::new(false),
        }
    }

    fn view(&self, name: Option<&str>) -> Option<&Arc<Hub>> {
        match name {
            None | Some("") => Some(&self.hub),
            Some(n) => self.views.get(n),
        }
    }
}

pub fn router(app: Arc<App>) -> Router {
    Router::new()
        .route("/", get(|| async { Html(INDEX) }))
        .route(
            "/page.js",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
                    SCRIPT,
                )
            }),
        )
        .route(
            "/page.css",
            get(|| async { ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE) }),
        )
        .route("/events", get(events))
        .route("/api/history", get(history))
        .route("/api/stats", get(stats))
        .route("/api/ack", post(ack))
        .route("/api/accept", post(accept))
        .fallback(|| async { error(StatusCode::NOT_FOUND, "no such page".into()) })
        .with_state(app)
}

fn error(status: StatusCode, message: String) -> Response {
    (status, Json(json!({"error": message}))).into_response()
}

#[derive(serde::Deserialize)]
struct ViewQuery {
    view: Option<String>,
}

fn unknown_view(request: &str, name: Option<&str>) -> Response {
    error(
        StatusCode::NOT_FOUND,
        format!("{request}: no view '{}'", name.unwrap_or_default()),
    )
}

/// The history, a marker that what follows is live, then the client's queue.
async fn events(State(app): State<Arc<App>>, Query(q): Query<ViewQuery>) -> Response {
    let Some(hub) = app.view(q.view.as_deref()) else {
        return unknown_view("GET /events", q.view.as_deref());
    };
    let Some(sub) = hub.subscribe() else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "GET /events: {} browsers are served already",
                hub.limits().clients
            ),
        );
    };
    let live_marker = Arc::new(Published {
        seq: 0,
        text: r#"{"type":"live"}"#.into(),
    });
    let history =
        futures_util::stream::iter(sub.history).chain(futures_util::stream::iter([live_marker]));
    let live = futures_util::stream::unfold(sub.live, |mut queue| async move {
        queue.recv().await.map(|event| (event, queue))
    });
    let stream = history
        .chain(live)
        .map(|p| Ok::<Event, Infallible>(Event::default().data(p.text.as_str())));
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}

/// The history as one JSON array (what a new browser gets first).
async fn history(State(app): State<Arc<App>>, Query(q): Query<ViewQuery>) -> Response {
    let Some(hub) = app.view(q.view.as_deref()) else {
        return unknown_view("GET /api/history", q.view.as_deref());
    };
    let Some(sub) = hub.subscribe() else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "GET /api/history: too many clients".into(),
        );
    };
    let mut text = String::from("[");
    for (i, p) in sub.history.iter().enumerate() {
        if i > 0 {
            text.push(',');
        }
        text.push_str(&p.text);
    }
    text.push(']');
    ([(header::CONTENT_TYPE, "application/json")], text).into_response()
}

async fn stats(State(app): State<Arc<App>>) -> Response {
    Json(json!(app.hub.stats())).into_response()
}

/// The token from `Authorization: Bearer T` or `X-Twin-Token: T`: 401 without one, 403 when
/// it is wrong or the page is read-only.
fn authorize(app: &App, headers: &HeaderMap, request: &str) -> Result<(), Box<Response>> {
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .or_else(|| headers.get("x-twin-token").and_then(|v| v.to_str().ok()));
    let Some(expected) = &app.actions.token else {
        return Err(Box::new(error(
            StatusCode::FORBIDDEN,
            format!("{request}: the page is read-only (start it with --token to allow this)"),
        )));
    };
    let Some(given) = given else {
        return Err(Box::new(error(
            StatusCode::UNAUTHORIZED,
            format!("{request}: no token (send it as 'Authorization: Bearer TOKEN')"),
        )));
    };
    // Compared without an early exit on the first differing byte.
    let same = given.len() == expected.len()
        && given
            .bytes()
            .zip(expected.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0;
    if !same {
        return Err(Box::new(error(
            StatusCode::FORBIDDEN,
            format!("{request}: wrong token"),
        )));
    }
    Ok(())
}

/// The body as a JSON object, or 400 naming the request.
fn json_object(
    body: &str,
    request: &str,
    expected: &str,
) -> Result<serde_json::Map<String, Value>, Box<Response>> {
    let bad = |why: String| {
        Box::new(error(
            StatusCode::BAD_REQUEST,
            format!("{request}: {why}; expected {expected}"),
        ))
    };
    if body.trim().is_empty() {
        return Ok(Default::default());
    }
    match serde_json::from_str::<Value>(body) {
        Ok(Value::Object(map)) => Ok(map),
        Ok(other) => Err(bad(format!("the body is JSON but not an object ({other})"))),
        Err(e) => Err(bad(format!("the body is not JSON ({e})"))),
    }
}

/// `POST /api/ack {"seq": N, "note": "..."}`: the alert `seq` acknowledged, a line in the
/// acknowledgements file and an `acknowledged` alert on the page.
async fn ack(State(app): State<Arc<App>>, headers: HeaderMap, body: String) -> Response {
    const REQUEST: &str = "POST /api/ack";
    const EXPECTED: &str = r#"{"seq": N, "note": "..."} with N an alert's sequence number"#;
    if let Err(r) = authorize(&app, &headers, REQUEST) {
        return *r;
    }
    let map = match json_object(&body, REQUEST, EXPECTED) {
        Ok(m) => m,
        Err(r) => return *r,
    };
    let Some(seq) = map.get("seq").and_then(Value::as_u64).filter(|&s| s > 0) else {
        return error(
            StatusCode::BAD_REQUEST,
            format!("{REQUEST}: \"seq\" is missing or not a positive integer; expected {EXPECTED}"),
        );
    };
    let note = match map.get("note") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(_) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!("{REQUEST}: \"note\" must be a string; expected {EXPECTED}"),
            )
        }
    };
    if !app.hub.has_alert(seq) {
        return error(
            StatusCode::NOT_FOUND,
            format!("{REQUEST}: no alert with seq {seq}"),
        );
    }
    let wall = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let line = json!({"kind": "acknowledged", "ack": seq, "note": note, "wall_time": wall});
    if let Some(path) = &app.actions.acks {
        let _guard = app
            .acks
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let written = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .and_then(|mut f| {
                f.write_all(format!("{line}\n").as_bytes())?;
                f.flush()
            });
        if let Err(e) = written {
            return error(
                StatusCode::INTERNAL_SERVER_ERROR,
                format!("{REQUEST}: cannot write {}: {e}", path.display()),
            );
        }
    }
    app.hub
        .publish(Kind::Other, json!({"type": "alert", "alert": line}));
    (StatusCode::OK, Json(json!({"acknowledged": seq}))).into_response()
}

/// A name beside `twin` for the accepted twin: `STEM.accepted-K.ssp` (then `-2`, `-3`, … if
/// taken).
fn accepted_path(twin: &Path, k: usize) -> PathBuf {
    let stem = twin
        .file_stem()
        .map_or_else(|| "twin".into(), |s| s.to_string_lossy().into_owned());
    let mut n = 1;
    loop {
        let name = if n == 1 {
            format!("{stem}.accepted-{k}.ssp")
        } else {
            format!("{stem}.accepted-{k}-{n}.ssp")
        };
        let path = twin.with_file_name(name);
        if !path.exists() {
            return path;
        }
        n += 1;
    }
}

/// `POST /api/accept {"diagnosis": K}` (default: the latest): add the diagnosis's physics with
/// `twin add-physics --diagnosis REPORT --data SAMPLES`, writing a new twin beside the old; it
/// runs in the background (202), its end an `accept` event on the page.
async fn accept(State(app): State<Arc<App>>, headers: HeaderMap, body: String) -> Response {
    if let Err(r) = authorize(&app, &headers, ACCEPT_REQUEST) {
        return *r;
    }
    let map = match json_object(&body, ACCEPT_REQUEST, ACCEPT_EXPECTED) {
        Ok(m) => m,
        Err(r) => return *r,
    };
    let (k, report, samples) = match chosen_diagnosis(&app, &map) {
        Ok(chosen) => chosen,
        Err(r) => return *r,
    };
    let (Some(twin), Some(binary)) = (&app.actions.twin, &app.actions.binary) else {
        return error(
            StatusCode::CONFLICT,
            format!("{ACCEPT_REQUEST}: the watch was started without a --twin file to add to"),
        );
    };
    if app.accepting.swap(true, Ordering::SeqCst) {
        return error(
            StatusCode::CONFLICT,
            format!("{ACCEPT_REQUEST}: an accepted diagnosis is being added already"),
        );
    }
    let out = accepted_path(twin, k);
    let mut command = std::process::Command::new(binary);
    command
        .arg("add-physics")
        .arg("--twin")
        .arg(twin)
        .arg("--diagnosis")
        .arg(report)
        .arg("--data")
        .arg(samples)
        .arg("--out")
        .arg(&out)
        .stdin(std::process::Stdio::null());
    let started = json!({"type": "accept", "status": "started", "diagnosis": k,
                         "out": out.display().to_string()});
    app.hub.publish(Kind::Other, started.clone());
    if let Err(e) = run_accept(app.clone(), command, k, out) {
        app.accepting.store(false, Ordering::SeqCst);
        return error(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("{ACCEPT_REQUEST}: cannot start add-physics: {e}"),
        );
    }
    (StatusCode::ACCEPTED, Json(started)).into_response()
}

const ACCEPT_REQUEST: &str = "POST /api/accept";
const ACCEPT_EXPECTED: &str = r#"{"diagnosis": K} with K a diagnosis's number (1, 2, …), or {}"#;

/// The diagnosis the request names (default: the latest): its number, its report and its
/// samples file; refused unless it landed and its action is add_physics.
fn chosen_diagnosis(
    app: &App,
    map: &serde_json::Map<String, Value>,
) -> Result<(usize, String, String), Box<Response>> {
    let refuse = |status, message: String| Box::new(error(status, message));
    let diagnoses = app.hub.diagnoses();
    let k = match map.get("diagnosis") {
        None | Some(Value::Null) => diagnoses.len(),
        Some(v) => match v.as_u64().filter(|&k| k > 0) {
            Some(k) => k as usize,
            None => {
                return Err(refuse(
                    StatusCode::BAD_REQUEST,
                    format!(
                        "{ACCEPT_REQUEST}: \"diagnosis\" must be a positive integer; expected {ACCEPT_EXPECTED}"
                    ),
                ))
            }
        },
    };
    if diagnoses.is_empty() {
        return Err(refuse(
            StatusCode::CONFLICT,
            format!("{ACCEPT_REQUEST}: no diagnosis has landed"),
        ));
    }
    let Some(d) = diagnoses.get(k - 1) else {
        return Err(refuse(
            StatusCode::NOT_FOUND,
            format!(
                "{ACCEPT_REQUEST}: no diagnosis {k} ({} landed)",
                diagnoses.len()
            ),
        ));
    };
    let action = d["action"].as_str().unwrap_or("none");
    if action != "add_physics" {
        return Err(refuse(
            StatusCode::CONFLICT,
            format!(
                "{ACCEPT_REQUEST}: diagnosis {k}'s action is '{action}'; only add_physics adds physics"
            ),
        ));
    }
    let (Some(report), Some(samples)) = (d["report"].as_str(), d["samples"].as_str()) else {
        return Err(refuse(
            StatusCode::CONFLICT,
            format!("{ACCEPT_REQUEST}: diagnosis {k} has no report or samples file"),
        ));
    };
    Ok((k, report.to_string(), samples.to_string()))
}

/// `command` (add-physics for diagnosis `k`, writing `out`) on a thread of its own; its end an
/// `accept` event, and the next accept allowed.
fn run_accept(
    app: Arc<App>,
    mut command: std::process::Command,
    k: usize,
    out: PathBuf,
) -> std::io::Result<()> {
    std::thread::Builder::new()
        .name("accept".into())
        .spawn(move || {
            let event = match command.output() {
                Ok(o) if o.status.success() => json!({"type": "accept", "status": "done",
                    "diagnosis": k, "out": out.display().to_string(),
                    "printout": String::from_utf8_lossy(&o.stdout)}),
                Ok(o) => json!({"type": "accept", "status": "failed", "diagnosis": k,
                    "error": String::from_utf8_lossy(&o.stderr)}),
                Err(e) => json!({"type": "accept", "status": "failed", "diagnosis": k,
                    "error": e.to_string()}),
            };
            app.hub.publish(Kind::Other, event);
            app.accepting.store(false, Ordering::SeqCst);
        })
        .map(|_| ())
}
