//! The page's events made from what a finished watch left: its alerts file (JSON lines), its
//! checkpoint and its diagnoses' reports, published once into a hub that `twin serve` serves.

use std::path::Path;
use std::sync::Arc;

use serde_json::{json, Value};

use super::hub::{Hub, Kind};
use super::live::run_id;

#[derive(Debug, thiserror::Error)]
pub enum FinishedError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} line {line}: not an alert ({message})")]
    BadLine {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{0}")]
    Other(String),
}

fn read(path: &Path) -> Result<String, FinishedError> {
    std::fs::read_to_string(path).map_err(|source| FinishedError::Read {
        path: path.display().to_string(),
        source,
    })
}

/// The alerts of a finished watch (and its checkpoint, if given) into `hub`: the meta (the
/// channels and tolerance from the `end` alert, else from the alerts that name channels), every
/// alert in order, the state from the `end` alert.
pub fn publish_watch(
    hub: &Arc<Hub>,
    alerts: &Path,
    checkpoint: Option<&Path>,
) -> Result<(), FinishedError> {
    let text = read(alerts)?;
    let mut list = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let value: Value = serde_json::from_str(line).map_err(|e| FinishedError::BadLine {
            path: alerts.display().to_string(),
            line: i + 1,
            message: e.to_string(),
        })?;
        list.push(value);
    }
    // Acknowledgements a page wrote beside the alerts.
    let stem = alerts
        .file_stem()
        .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
    let acks = alerts.with_file_name(format!("{stem}.acks.jsonl"));
    if acks.exists() {
        for line in read(&acks)?.lines() {
            if let Ok(v) = serde_json::from_str::<Value>(line) {
                list.push(v);
            }
        }
    }
    let end = list.iter().rev().find(|a| a["kind"] == "end").cloned();
    let channels = end
        .as_ref()
        .and_then(|e| e.get("channels").cloned())
        .or_else(|| {
            list.iter()
                .find_map(|a| a.get("channels").filter(|c| c.is_array()).cloned())
        })
        .unwrap_or_else(|| json!([]));
    let tolerance = end.as_ref().and_then(|e| e.get("tolerance").cloned());
    hub.publish(
        Kind::Meta,
        json!({"type": "meta", "mode": "finished", "title": format!("watch {}", alerts.display()),
               "run": run_id(), "channels": channels, "tolerance": tolerance,
               "window": null, "token": false}),
    );
    for alert in &list {
        hub.publish(Kind::Other, json!({"type": "alert", "alert": alert}));
    }
    let mut state = json!({"type": "state", "finished": true});
    if let (Value::Object(s), Some(Value::Object(e))) = (&mut state, &end) {
        for key in [
            "samples",
            "samples_per_second",
            "real_time_factor",
            "gaps",
            "missing_samples",
            "bad_lines",
            "duplicates",
            "mqtt",
        ] {
            if let Some(v) = e.get(key) {
                s.insert(key.into(), v.clone());
            }
        }
        s.insert("time".into(), e.get("time").cloned().unwrap_or(Value::Null));
        s.insert("nmse".into(), e.get("nmse").cloned().unwrap_or(Value::Null));
    }
    if let (Some(path), Value::Object(s)) = (checkpoint, &mut state) {
        let text = read(path)?;
        let saved: Value = serde_json::from_str(&text)
            .map_err(|e| FinishedError::Other(format!("{}: {e}", path.display())))?;
        s.insert(
            "checkpoint".into(),
            json!({"path": path.display().to_string(), "samples": saved.get("samples"),
                   "time": saved.get("last_time"),
                   "age": std::fs::metadata(path).ok().and_then(|m| m.modified().ok())
                       .and_then(|t| t.elapsed().ok()).map(|d| d.as_secs_f64())}),
        );
    }
    hub.publish(Kind::State, state);
    Ok(())
}

/// A record against its twin (`twin compare`'s series) into `hub`: per channel measured,
/// predicted and the ±3σ band, the rolling NMSE over `window` s, the failing windows shaded and
/// listed as alerts. At most `Limits::points` points (every k-th sample).
pub fn publish_comparison(
    hub: &Arc<Hub>,
    title: String,
    comparison: &crate::evaluation::compare::Comparison,
    window: f64,
) {
    let c = comparison;
    let n = c.time.len();
    let channels = c.names();
    hub.publish(
        Kind::Meta,
        json!({"type": "meta", "mode": "record", "title": title, "run": run_id(),
               "channels": channels, "tolerance": c.tolerance, "window": window,
               "token": false}),
    );
    let step = n.div_ceil(hub.limits().points.max(1)).max(1);
    let dt = if n > 1 {
        (c.time[n - 1] - c.time[0]) / (n - 1) as f64
    } else {
        1.0
    };
    let width = ((window / dt).round() as usize).max(2);
    let inside = |t: f64| c.failing_windows.iter().any(|w| t >= w.start && t <= w.end);
    for k in (0..n).step_by(step) {
        let t = c.time[k];
        let from = (k + 1).saturating_sub(width).max(c.first);
        let nmse: Vec<f64> = (0..channels.len())
            .map(|ch| {
                if k < c.first + 1 {
                    f64::NAN
                } else {
                    crate::evaluation::stats::nmse(
                        &c.measured[ch][from..=k],
                        &c.predicted[ch][from..=k],
                    )
                }
            })
            .collect();
        let y: Vec<f64> = (0..channels.len()).map(|ch| c.measured[ch][k]).collect();
        let p: Vec<f64> = (0..channels.len()).map(|ch| c.predicted[ch][k]).collect();
        let band: Vec<f64> = (0..channels.len()).map(|ch| 3.0 * c.sd_at(ch, k)).collect();
        hub.publish(
            Kind::Point,
            json!({"type": "point", "t": t, "y": super::live::floats(&y),
                   "p": super::live::floats(&p), "band": super::live::floats(&band),
                   "nmse": super::live::floats(&nmse), "open": inside(t)}),
        );
    }
    for (i, w) in c.failing_windows.iter().enumerate() {
        hub.publish(
            Kind::Other,
            json!({"type": "alert", "alert": {"seq": i + 1, "kind": "failing", "time": w.start,
                   "start": w.start, "end": w.end, "channels": w.channels,
                   "floors": w.floors, "nmse": super::live::floats(&w.nmse)}}),
        );
    }
    hub.publish(
        Kind::State,
        json!({"type": "state", "finished": true, "samples": n,
               "time": c.time.last().copied().unwrap_or(0.0),
               "nmse": super::live::floats(&c.nmse)}),
    );
}

/// One structure of a fleet report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FleetRow {
    pub name: String,
    /// `ok` (compare only, or a diagnosis of none), `attention` (any other action, or a mode
    /// that left its band), `error`.
    pub status: String,
    pub action: Option<String>,
    pub nmse: Option<f64>,
    pub frequency_shift: Option<f64>,
    /// Whether the structure has a view of its own (`?view=NAME`).
    pub view: bool,
}

/// The rows of a fleet report (`twin fleet`'s fleet.csv: structure, action, nmse_before,
/// frequency_shift, modes_moved, error).
pub fn read_fleet(path: &Path) -> Result<Vec<FleetRow>, FinishedError> {
    let text = read(path)?;
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let bad = |message: String| FinishedError::Other(format!("{}: {message}", path.display()));
    let headers = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let column = |name: &str| headers.iter().position(|h| h == name);
    let structure = column("structure")
        .ok_or_else(|| bad("no 'structure' column (is it twin fleet's fleet.csv?)".into()))?;
    let (action, nmse, shift, moved, error) = (
        column("action"),
        column("nmse_before"),
        column("frequency_shift"),
        column("modes_moved"),
        column("error"),
    );
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| bad(e.to_string()))?;
        let field = |i: Option<usize>| {
            i.and_then(|i| record.get(i))
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(str::to_owned)
        };
        let number = |i: Option<usize>| field(i).and_then(|s| s.parse::<f64>().ok());
        let action_text = field(action);
        let status = if field(error).is_some() {
            "error"
        } else if matches!(
            action_text.as_deref(),
            None | Some("compare") | Some("none")
        ) && field(moved).is_none()
        {
            "ok"
        } else {
            "attention"
        };
        rows.push(FleetRow {
            name: field(Some(structure)).unwrap_or_default(),
            status: status.into(),
            action: action_text,
            nmse: number(nmse),
            frequency_shift: number(shift),
            view: false,
        });
    }
    Ok(rows)
}

/// A fleet's table into `hub`.
pub fn publish_fleet(hub: &Arc<Hub>, title: String, rows: &[FleetRow]) {
    hub.publish(
        Kind::Meta,
        json!({"type": "meta", "mode": "fleet", "title": title, "run": run_id(),
               "channels": [], "tolerance": null, "window": null, "token": false}),
    );
    hub.publish(Kind::Other, json!({"type": "fleet", "rows": rows}));
}
