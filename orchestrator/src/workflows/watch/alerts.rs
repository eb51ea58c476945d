//! The alerts: JSON lines written and flushed (with their latency), the detector's events and
//! the connection's turned into alerts.

use super::mqtt::ConnectionEvent;
use super::online::{names_and_floors, Detector, Event};
use super::watcher::Watcher;
use super::{io, WatchError};
use serde_json::{json, Value};
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::Path;

/// Per-sample processing times in logarithmic bins (5 % wide, from 10 ns): constant memory.
pub(super) struct Latency {
    pub(super) bins: Vec<u64>,
    pub(super) n: u64,
}

pub(super) const LATENCY_BASE: f64 = 1e-8;
pub(super) const LATENCY_RATIO: f64 = 1.05;

impl Latency {
    pub(super) fn new() -> Self {
        Latency {
            bins: vec![0; 520],
            n: 0,
        }
    }
    pub(super) fn add(&mut self, seconds: f64) {
        let i = ((seconds.max(LATENCY_BASE) / LATENCY_BASE).ln() / LATENCY_RATIO.ln()) as usize;
        let i = i.min(self.bins.len() - 1);
        self.bins[i] += 1;
        self.n += 1;
    }
    /// The `q` quantile (s): the upper edge of its bin; NaN without samples.
    pub(super) fn quantile(&self, q: f64) -> f64 {
        if self.n == 0 {
            return f64::NAN;
        }
        let target = (q * self.n as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, &c) in self.bins.iter().enumerate() {
            seen += c;
            if seen >= target {
                return LATENCY_BASE * LATENCY_RATIO.powi(i as i32 + 1);
            }
        }
        f64::NAN
    }
}

/// The alerts file: one JSON object a line, each written and flushed at once. On a resumed
/// run, alerts the file already holds (those raised after the checkpoint by the run that
/// stopped, raised again now by the same samples) are not written twice.
pub(super) struct Alerts {
    pub(super) file: File,
    /// Alerts with a sequence number up to this are in the file already.
    pub(super) written: u64,
    /// The diagnoses (their window's start and round) the file holds already.
    pub(super) diagnosed: Vec<(f64, u32)>,
}

impl Alerts {
    pub(super) fn open(path: &Path, resuming: bool) -> Result<Self, WatchError> {
        let what = || format!("cannot write the alerts {}", path.display());
        if !resuming {
            let file = File::create(path).map_err(io(what()))?;
            return Ok(Alerts {
                file,
                written: 0,
                diagnosed: Vec::new(),
            });
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .read(true)
            .append(true)
            .open(path)
            .map_err(io(what()))?;
        let mut text = String::new();
        file.read_to_string(&mut text).map_err(io(what()))?;
        // A line cut short by a killed writer is dropped.
        let complete = text.rfind('\n').map_or(0, |i| i + 1);
        if complete < text.len() {
            file.set_len(complete as u64).map_err(io(what()))?;
            file.seek(std::io::SeekFrom::End(0)).map_err(io(what()))?;
        }
        let alerts: Vec<Value> = text[..complete]
            .lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .collect();
        let written = alerts
            .iter()
            .filter_map(|v| v.get("seq").and_then(Value::as_u64))
            .max()
            .unwrap_or(0);
        let diagnosed = alerts
            .iter()
            .filter(|v| v["kind"] == "diagnosis")
            .filter_map(|v| {
                let round = v["round"].as_u64().unwrap_or(1) as u32;
                v["window_start"].as_f64().map(|s| (s, round))
            })
            .collect();
        Ok(Alerts {
            file,
            written,
            diagnosed,
        })
    }

    /// Write `alert` unless the file holds it already; whether it was written. An alert without
    /// a sequence number (a connection change) is always written.
    pub(super) fn write(&mut self, alert: &Value) -> Result<bool, WatchError> {
        let seq = alert.get("seq").and_then(Value::as_u64).unwrap_or(0);
        if seq <= self.written && seq != 0 {
            return Ok(false);
        }
        let mut line = alert.to_string();
        line.push('\n');
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.flush())
            .map_err(io("cannot write an alert"))?;
        self.written = self.written.max(seq);
        Ok(true)
    }
}

/// Windows as JSON (NaN NMSE as null).
pub(super) fn window_values(windows: Vec<crate::evaluation::compare::FailingWindow>) -> Value {
    Value::Array(
        windows
            .into_iter()
            .map(|w| {
                json!({"start": w.start, "end": w.end, "floors": w.floors,
                       "channels": w.channels, "nmse": floats(&w.nmse)})
            })
            .collect(),
    )
}

/// NaN as JSON null.
pub(super) fn floats(x: impl AsRef<[f64]>) -> Value {
    let x: Vec<Option<f64>> = x
        .as_ref()
        .iter()
        .map(|v| v.is_finite().then_some(*v))
        .collect();
    json!(x)
}

impl Watcher<'_> {
    pub(super) fn alert(
        &mut self,
        time: Option<f64>,
        kind: &str,
        mut body: Value,
    ) -> Result<(), WatchError> {
        self.state.seq += 1;
        *self.state.alerts.entry(kind.to_owned()).or_default() += 1;
        if let Value::Object(map) = &mut body {
            map.insert("seq".into(), json!(self.state.seq));
            map.insert("time".into(), json!(time));
            map.insert("kind".into(), json!(kind));
        }
        self.send(&body)
    }

    /// To the alerts file and, from an MQTT source, to the alerts topic.
    pub(super) fn send(&mut self, body: &Value) -> Result<(), WatchError> {
        if self.alerts.write(body)? {
            if let Some(m) = self.reader.mqtt() {
                m.publish_alert(body.to_string())?;
            }
            self.observe(|o| o.alert(body));
            (self.on_alert)(body).map_err(WatchError::Callback)?;
        }
        Ok(())
    }

    /// The broker connection's changes as `connection` alerts (without a sequence number: a
    /// resumed run's connections are its own).
    pub(super) fn connection_alerts(&mut self) -> Result<(), WatchError> {
        let Some(m) = self.reader.mqtt() else {
            return Ok(());
        };
        let events = m.take_events();
        self.report_connection(events)
    }

    /// Connection changes as `connection` alerts.
    pub(super) fn report_connection(
        &mut self,
        events: Vec<ConnectionEvent>,
    ) -> Result<(), WatchError> {
        let Some(m) = self.reader.mqtt() else {
            return Ok(());
        };
        let broker = format!("{}:{}", m.url().host, m.url().port);
        for event in events {
            let body = match event {
                ConnectionEvent::Connected { session_present } => json!({
                    "time": self.state.last_time, "kind": "connection", "state": "connected",
                    "broker": broker, "session_present": session_present}),
                ConnectionEvent::Lost { reason } => json!({
                    "time": self.state.last_time, "kind": "connection", "state": "lost",
                    "broker": broker, "reason": reason}),
            };
            *self
                .state
                .alerts
                .entry("connection".to_owned())
                .or_default() += 1;
            self.send(&body)?;
        }
        Ok(())
    }

    pub(super) fn events(&mut self, time: f64, events: Vec<Event>) -> Result<(), WatchError> {
        for event in events {
            match event {
                Event::Opened {
                    start,
                    channels,
                    nmse,
                    change,
                } => {
                    if let Some(b) = &mut self.background {
                        b.opened(start, time, change.clone());
                    }
                    let rolling = self
                        .state
                        .detector
                        .as_ref()
                        .map_or_else(|| self.nan(), Detector::rolling_nmse);
                    let (channels, floors) = names_and_floors(&self.state.channels, &channels);
                    let change = change.map(|c| {
                        json!({"time": c.time, "low": c.low, "high": c.high,
                               "log_likelihood_ratio": c.log_likelihood_ratio,
                               "variance_ratio": floats(&c.variance_ratio),
                               "inflation": c.inflation})
                    });
                    self.alert(
                        Some(time),
                        "failing",
                        json!({"start": start, "floors": floors, "channels": channels,
                               "nmse": floats(nmse), "rolling_nmse": floats(rolling),
                               "change": change}),
                    )?;
                }
                Event::Closed {
                    window,
                    failing,
                    was_opened,
                    cut,
                } => {
                    if let Some(b) = &mut self.background {
                        b.closed(window.start, window.end, failing);
                    }
                    if failing && !was_opened {
                        self.alert(
                            Some(time),
                            "failing",
                            json!({"start": window.start, "floors": window.floors,
                                   "channels": window.channels, "nmse": floats(&window.nmse)}),
                        )?;
                    }
                    if cut {
                        // The segment ended with the window open: no return to the band. The
                        // gap's or the end's alert carries it.
                        if failing || was_opened {
                            self.cut_windows.push(window);
                        }
                    } else if failing || was_opened {
                        let rolling = self
                            .state
                            .detector
                            .as_ref()
                            .map_or_else(|| self.nan(), Detector::rolling_nmse);
                        self.alert(
                            Some(time),
                            "recovered",
                            json!({"start": window.start, "end": window.end,
                                   "floors": window.floors, "channels": window.channels,
                                   "nmse": floats(&window.nmse), "withdrawn": !failing,
                                   "in_band_for": self.state.options.merge_gap,
                                   "rolling_nmse": floats(rolling)}),
                        )?;
                    }
                }
            }
        }
        Ok(())
    }
}
