//! The alerts file: JSON lines written and flushed, none twice on a resumed run; the per-sample
//! latency; windows and floats as JSON. The watcher ([`super::watcher`]) makes the alerts.

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
