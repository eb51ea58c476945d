//! What a caller of [`super::watch`] sees while it runs: the status now and then, the live view's
//! [`Observer`] (`twin watch --serve`) told of the samples, alerts and state, and the summary the
//! `end` alert carries.

use super::mqtt::ConnectionStats;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::time::SystemTime;

/// What the progress display shows.
#[derive(Debug, Clone)]
pub struct Status {
    pub samples: u64,
    pub time: f64,
    pub samples_per_second: f64,
    /// The measured channels, and the rolling NMSE of each.
    pub channels: Vec<String>,
    pub rolling_nmse: Vec<f64>,
    /// Whether a failing window is open.
    pub open_window: bool,
    /// Whether a diagnosis runs in the background.
    pub diagnosing: bool,
}

/// A live view of the watch (the page's hub, `twin watch --serve`). Every call must return at
/// once: the watcher calls them on its own thread between samples and never waits for a reader.
/// A panic in an observer is caught; the watch goes on without it.
///
/// Call order: `start` once; per good sample `due`, and when it says so `point`; every alert as it is written
/// `alert`; the state now and then (as the progress display) and once at the end `state`.
pub trait Observer {
    /// The watch begins: the measured channels (in the order of every per-channel list), the
    /// tolerance (NMSE %) and the rolling window (s).
    fn start(&mut self, channels: &[String], tolerance: f64, window: f64);
    /// Whether the sample at `time` (s of the stream) is to be shown: the observer decimates.
    fn due(&mut self, time: f64) -> bool;
    /// A shown sample.
    fn point(&mut self, point: &Point<'_>);
    /// An alert, as written to the alerts file.
    fn alert(&mut self, alert: &Value);
    fn state(&mut self, state: &LiveState);
}

/// One shown sample: per measured channel (the order of [`Status::channels`]).
pub struct Point<'a> {
    pub time: f64,
    /// When the watcher read the sample's line.
    pub read_at: SystemTime,
    pub measured: &'a [f64],
    /// The twin's prediction (the corrected one with a GP corrector).
    pub predicted: &'a [f64],
    /// The band's half-width, 3 sds of the noise (None until the noise variances are known).
    pub band: Option<Vec<f64>>,
    /// The corrector's latent sd √V(f), with a GP corrector.
    pub latent_sd: Option<Vec<f64>>,
    /// The rolling NMSE % (NaN until the comparison starts).
    pub rolling_nmse: Vec<f64>,
    pub open_window: bool,
}

/// The watcher's state for a live view.
#[derive(Debug, Clone, Serialize)]
pub struct LiveState {
    pub samples: u64,
    /// The last sample's time, s of the stream.
    pub time: f64,
    pub samples_per_second: f64,
    /// Stream seconds per wall second (NaN before the sampling interval is known).
    pub real_time_factor: f64,
    pub gaps: u64,
    pub missing_samples: u64,
    pub bad_lines: u64,
    pub duplicates: u64,
    /// The broker connection (an MQTT source only).
    pub mqtt: Option<ConnectionStats>,
    /// Seconds since the last checkpoint was saved (None: none saved, or no --checkpoint).
    pub checkpoint_age: Option<f64>,
    pub diagnosing: bool,
    pub open_window: bool,
    /// The stream has ended.
    pub finished: bool,
}

/// The `end` alert's figures.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub samples: u64,
    pub samples_this_run: u64,
    pub bad_lines: u64,
    /// Samples whose time was not after the last one's, from an MQTT source (a message the
    /// broker delivered again): dropped, not counted as bad.
    pub duplicates: u64,
    pub gaps: u64,
    pub missing_samples: u64,
    pub alerts: BTreeMap<String, u64>,
    pub failing_windows: u64,
    /// The broker connection (an MQTT source only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mqtt: Option<ConnectionStats>,
    /// The corrector's supervisor (a twin with a GP corrector only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub learning: Option<LearningSummary>,
    /// The measured channels, in the order of `nmse` (and of every alert's per-channel list).
    pub channels: Vec<String>,
    pub nmse: Vec<f64>,
    /// Where the band's noise variances came from: the twin's, or the stream's prior.
    pub noise_source: String,
    pub samples_per_second: f64,
    pub real_time_factor: f64,
    pub latency_median_us: f64,
    pub latency_p99_us: f64,
    pub tolerance: f64,
    /// The failing windows still open when the stream ended (the residual never came back
    /// into its band: not recovered).
    pub still_failing: Vec<crate::evaluation::compare::FailingWindow>,
}

/// What the active-learning supervisor did over the stream.
#[derive(Debug, Clone, Serialize)]
pub struct LearningSummary {
    pub queries: u64,
    /// Whether the queried samples were learned.
    pub learned: bool,
    pub training_points: Option<i32>,
    /// None: the corrector's FMU takes no budget (its own limit, 2048, holds).
    pub budget: Option<u32>,
    /// Per measured channel (None while the reference samples come).
    pub threshold: Option<Vec<f64>>,
    /// The largest V(f) / threshold over the stream.
    pub largest_ratio: f64,
}
