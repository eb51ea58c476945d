//! The watch's side of the page: [`LiveView`], the watcher's [`Observer`], decimates the
//! samples and publishes points, alerts and state into the [`Hub`].
//!
//! Decimation: a point is shown when at least [`POINT_STEP`] s of stream have passed since the
//! last shown one (the sample then, as it is) and the wall-time budget allows it: a token bucket
//! of [`WALL_BURST`] points refilled at [`WALL_RATE`] a second. A kHz stream at hundreds of times
//! real time reaches the hub as at most `WALL_RATE` points a second (after a first burst), each
//! carrying every channel; a stream that comes in bursts (a pipe's chunks) keeps its points as
//! long as the average stays under the rate.

use std::sync::Arc;
use std::time::{Instant, UNIX_EPOCH};

use serde_json::{json, Value};

use super::hub::{Hub, Kind};
use crate::workflows::watch::{LiveState, Observer, Point};

/// Stream seconds between shown points (50 a second of stream).
pub const POINT_STEP: f64 = 0.02;
/// Points a second of wall time, at most, on average.
pub const WALL_RATE: f64 = 250.0;
/// Points shown at once before the wall-time rate holds.
pub const WALL_BURST: f64 = 50.0;

pub struct LiveView {
    hub: Arc<Hub>,
    /// The page's title, whether the mutating endpoints are on, this run's id (the page starts
    /// afresh when it changes).
    title: String,
    token: bool,
    run: String,
    point_step: f64,
    wall_rate: f64,
    /// The bucket: points it allows now, as of `last_wall`.
    tokens: f64,
    last_time: f64,
    last_wall: Option<Instant>,
    /// Points shown and samples seen, for the benchmark and the tests.
    pub shown: u64,
    pub seen: u64,
}

impl LiveView {
    /// Other decimation than [`POINT_STEP`] and [`WALL_RATE`] (infinite: no wall-time limit).
    pub fn with_steps(mut self, point_step: f64, wall_rate: f64) -> Self {
        self.point_step = point_step;
        self.wall_rate = wall_rate;
        self
    }

    pub fn new(hub: Arc<Hub>, title: String, token: bool) -> Self {
        LiveView {
            hub,
            title,
            token,
            run: run_id(),
            point_step: POINT_STEP,
            wall_rate: WALL_RATE,
            tokens: WALL_BURST,
            last_time: f64::NEG_INFINITY,
            last_wall: None,
            shown: 0,
            seen: 0,
        }
    }
}

/// NaN and infinities as JSON null.
pub fn floats(x: &[f64]) -> Value {
    Value::Array(
        x.iter()
            .map(|v| if v.is_finite() { json!(v) } else { Value::Null })
            .collect(),
    )
}

impl Observer for LiveView {
    fn start(&mut self, channels: &[String], tolerance: f64, window: f64) {
        self.hub.publish(
            Kind::Meta,
            json!({"type": "meta", "mode": "watch", "title": self.title, "run": self.run,
                   "channels": channels, "tolerance": tolerance, "window": window,
                   "token": self.token}),
        );
    }

    fn due(&mut self, time: f64) -> bool {
        self.seen += 1;
        // A gap's restart or a resumed stream may go back in time: show it at once.
        // (Less a part in a million: times summed from a step fall just short of it.)
        if time >= self.last_time && time - self.last_time < self.point_step * (1.0 - 1e-6) {
            return false;
        }
        // A bucket of stream time is over: shown if the wall-time budget allows, else skipped
        // (either way the clock is read once a bucket, not once a sample).
        self.last_time = time;
        if !self.wall_rate.is_finite() {
            return true;
        }
        let now = Instant::now();
        if let Some(last) = self.last_wall {
            let refill = now.duration_since(last).as_secs_f64() * self.wall_rate;
            self.tokens = (self.tokens + refill).min(WALL_BURST);
        }
        self.last_wall = Some(now);
        if self.tokens < 1.0 {
            return false;
        }
        self.tokens -= 1.0;
        true
    }

    fn point(&mut self, p: &Point<'_>) {
        self.shown += 1;
        let wall = p
            .read_at
            .duration_since(UNIX_EPOCH)
            .map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
        let mut event = json!({
            "type": "point",
            "t": p.time,
            "wall": wall,
            "y": floats(p.measured),
            "p": floats(p.predicted),
            "nmse": floats(&p.rolling_nmse),
            "open": p.open_window,
        });
        if let Value::Object(map) = &mut event {
            if let Some(band) = &p.band {
                map.insert("band".into(), floats(band));
            }
            if let Some(sd) = &p.latent_sd {
                map.insert("latent_sd".into(), floats(sd));
            }
        }
        self.hub.publish(Kind::Point, event);
    }

    fn alert(&mut self, alert: &Value) {
        self.hub
            .publish(Kind::Other, json!({"type": "alert", "alert": alert}));
    }

    fn state(&mut self, state: &LiveState) {
        let mut event = serde_json::to_value(state).unwrap_or(Value::Null);
        if let Value::Object(map) = &mut event {
            map.insert("type".into(), json!("state"));
            for key in ["samples_per_second", "real_time_factor", "checkpoint_age"] {
                if map
                    .get(key)
                    .and_then(Value::as_f64)
                    .is_some_and(|v| !v.is_finite())
                {
                    map.insert(key.into(), Value::Null);
                }
            }
            map.insert("hub".into(), json!(self.hub.stats()));
            map.insert("points_shown".into(), json!(self.shown));
        }
        self.hub.publish(Kind::State, event);
    }
}

/// An id for this run of the server: its start in ms since 1970 and the process id.
pub fn run_id() -> String {
    let ms = std::time::SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    format!("{ms}-{}", std::process::id())
}
