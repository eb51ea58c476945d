//! What a caller of [`super::watch`] sees while it runs: the status now and then, the live view's
//! [`Observer`] (`twin watch --serve`) told of the samples, alerts and state, and the summary the
//! `end` alert carries.

use super::background::Background;
use super::mqtt::ConnectionStats;
use super::online::Detector;
use super::watcher::Watcher;
use ::structure::channel::Channel;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::time::{Instant, SystemTime};

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

pub(super) fn status(w: &Watcher<'_>, this_run: u64, started: Instant) -> Status {
    Status {
        samples: w.state.samples,
        time: w.state.last_time.unwrap_or(0.0),
        samples_per_second: this_run as f64 / started.elapsed().as_secs_f64().max(1e-9),
        channels: w.state.channels.iter().map(Channel::name).collect(),
        rolling_nmse: w
            .state
            .detector
            .as_ref()
            .map_or_else(|| w.nan(), Detector::rolling_nmse),
        open_window: w.state.detector.as_ref().is_some_and(Detector::window_open),
        diagnosing: w.background.as_ref().is_some_and(Background::busy),
    }
}

impl Watcher<'_> {
    /// Tell the live view, if any; a panic in it drops the view, never the watch.
    pub(super) fn observe<R>(&mut self, call: impl FnOnce(&mut dyn Observer) -> R) -> Option<R> {
        let observer = self.observer.as_deref_mut()?;
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| call(observer))) {
            Ok(r) => Some(r),
            Err(_) => {
                eprintln!("the live page failed; the watch goes on without it");
                self.observer = None;
                None
            }
        }
    }

    /// The sample just processed (its line read at `began`), to the live view when it is due.
    pub(super) fn show(&mut self, time: f64, began: Instant) {
        if self.observer.is_none() || !self.observe(|o| o.due(time)).unwrap_or(false) {
            return;
        }
        // The wall time it was read at, from the instant the loop took anyway: no clock read
        // per sample for the page.
        let read_at = SystemTime::now()
            .checked_sub(began.elapsed())
            .unwrap_or(SystemTime::UNIX_EPOCH);
        let band = self
            .state
            .noise_variance
            .as_ref()
            .map(|v| v.iter().map(|v| 3.0 * v.sqrt()).collect());
        let latent_sd = if self.stepper.has_learner() && self.state.segment_start.is_some() {
            self.stepper
                .latent_variance()
                .ok()
                .flatten()
                .map(|v| v.iter().map(|v| v.max(0.0).sqrt()).collect())
        } else {
            None
        };
        let (rolling_nmse, open_window) = match &self.state.detector {
            Some(d) => (d.rolling_nmse(), d.window_open()),
            None => (self.nan(), false),
        };
        let measured = std::mem::take(&mut self.measured);
        let predicted = std::mem::take(&mut self.predicted);
        let point = Point {
            time,
            read_at,
            measured: &measured,
            predicted: &predicted,
            band,
            latent_sd,
            rolling_nmse,
            open_window,
        };
        self.observe(|o| o.point(&point));
        self.measured = measured;
        self.predicted = predicted;
    }

    /// The state, to the live view.
    pub(super) fn show_state(&mut self, this_run: u64, elapsed: f64, finished: bool) {
        if self.observer.is_none() {
            return;
        }
        let samples_per_second = this_run as f64 / elapsed.max(1e-9);
        let state = LiveState {
            samples: self.state.samples,
            time: self.state.last_time.unwrap_or(0.0),
            samples_per_second,
            real_time_factor: self.state.dt.map_or(f64::NAN, |dt| samples_per_second * dt),
            gaps: self.state.gaps,
            missing_samples: self.state.missing_samples,
            bad_lines: self.state.bad_lines,
            duplicates: self.state.duplicates,
            mqtt: self.reader.mqtt().map(|m| m.stats),
            checkpoint_age: self.saved_at.map(|t| t.elapsed().as_secs_f64()),
            diagnosing: self.background.as_ref().is_some_and(Background::busy),
            open_window: self
                .state
                .detector
                .as_ref()
                .is_some_and(Detector::window_open),
            finished,
        };
        self.observe(|o| o.state(&state));
    }
}
