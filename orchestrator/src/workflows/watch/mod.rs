//! `twin watch`: the operational twin on a live stream. Samples arrive as CSV lines (standard
//! input, a file that grows, an MQTT topic) whose header names the columns as a record's does
//! (`time`, `force` or `ground_acc`, any of `acc<i>`, `vel<i>`, `disp<i>`, units converted to
//! SI, `--columns` maps), checked against the twin's structure before any work; per sample the
//! twin's FMUs step once (their state carried from sample to sample), the prediction is
//! compared with each measured channel (a rolling NMSE per channel, the ±3σ band of the twin's
//! noise variances — or, for a channel the twin holds none for, [`PRIOR_NOISE_FRACTION`] of its
//! measured variance over the [`NOISE_REFERENCE`] seconds after the transient — failing
//! windows found online by `twin compare`'s rule), and alerts go out as JSON lines, each
//! flushed. A checkpoint (stream
//! position, comparison state, counters, the FMUs' serialised states) lets a restarted watcher
//! resume exactly where the last one saved.

pub mod background;
pub mod firm;
pub mod modes;
pub mod mqtt;
pub mod online;
mod second;
pub mod stepper;
pub mod supervise;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use crate::workflows::diagnose::Action;
use ::structure::channel::Channel;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::cosim::import::ImportError;
use crate::evaluation::compare::CompareOptions;
use crate::fsutil::{write_text_atomically, WriteError};
pub use crate::record::nominal_step;
use crate::record::{default_header, ColumnMap, LineLayout};
use crate::twin::run::{Tolerance, PRIOR_NOISE_FRACTION};
use crate::twin::{ParameterValue, Twin, TwinError};
use background::{Background, Columns, DiagnosisOptions, Finished};
use mqtt::{ConnectionEvent, ConnectionStats, MqttSource, MqttUrl};
use online::{names_and_floors, Detector, Event, Options};
use stepper::{NodeState, Stepper};
use supervise::{Decision, LearnOptions, Supervisor};

#[derive(Debug, thiserror::Error)]
pub enum WatchError {
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error("{what}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error("the stream's header: {0}")]
    Header(String),
    #[error(
        "{0}: the twin has no noise variances for the ±3σ band; calibrate it first (twin calibrate)"
    )]
    NoNoise(String),
    #[error("checkpoint {path}: {message}")]
    BadCheckpoint { path: PathBuf, message: String },
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("the twin's FMUs were used before they were started")]
    NotStarted,
    #[error("{0}")]
    Options(String),
    #[error("the alert callback: {0}")]
    Callback(String),
}

impl From<crate::workflows::options::InvalidOption> for WatchError {
    fn from(e: crate::workflows::options::InvalidOption) -> Self {
        WatchError::Options(e.0)
    }
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> WatchError {
    let what = what.into();
    move |source| WatchError::Io { what, source }
}

/// Where the samples come from.
#[derive(Debug, Clone)]
pub enum StreamSource {
    /// Standard input, read to its end.
    Stdin,
    /// A CSV file; with `follow`, read as it grows (polled every 100 ms) until `idle` passes
    /// without a new line.
    File {
        path: PathBuf,
        follow: bool,
        idle: Duration,
    },
    /// An MQTT topic (QoS 1, a persistent session); the stream ends after `idle` without a
    /// message (None: never).
    Mqtt {
        url: MqttUrl,
        client_id: Option<String>,
        idle: Option<Duration>,
    },
}

#[derive(Debug, Clone)]
pub struct WatchOptions {
    pub source: StreamSource,
    pub alerts: PathBuf,
    pub checkpoint: Option<PathBuf>,
    pub checkpoint_every: u64,
    /// Rolling NMSE window, s.
    pub window: f64,
    /// NMSE %; None: the twin's default ([`Tolerance::resolve`]).
    pub tolerance: Option<f64>,
    pub transient: f64,
    /// Sampling rate, Hz; None: from the first two samples.
    pub rate: Option<f64>,
    /// The background diagnosis of failing windows (None: off).
    pub diagnosis: Option<DiagnosisOptions>,
    /// The active-learning supervisor of a twin with a GP corrector.
    pub learning: LearnOptions,
    /// Header names the stream uses for the twin's (`--columns MAP.json`).
    pub columns: ColumnMap,
    /// Frequency tracking on a sliding window (None: off).
    pub modes: Option<modes::TrackOptions>,
    /// Adopt a firm `recalibrate` or `add_physics` verdict: the twin it names written beside
    /// the alerts and swapped into the running watch ([`Adopted`]).
    pub adopt: bool,
}

/// `--checkpoint-every`'s default, samples.
pub const CHECKPOINT_EVERY: u64 = 512;
/// `--window`'s default, s.
pub const WINDOW: f64 = 2.0;
/// `--idle`'s default for a followed file, s (an MQTT source waits for ever by default).
pub const FILE_IDLE: f64 = 10.0;
/// Seconds after the transient whose measured variance gives the band of a channel the twin
/// holds no noise variance for ([`PRIOR_NOISE_FRACTION`] of it, as `twin compare`'s prior);
/// the comparison of the stream's first samples waits for it.
pub const NOISE_REFERENCE: f64 = 10.0;

impl WatchOptions {
    /// The defaults for `source`, alerts to `alerts`: checkpoints every 512 samples (none
    /// without a path), a 2 s rolling NMSE, the twin's tolerance, the 2 s transient, the rate
    /// from the samples, the background diagnosis and the corrector's learning on.
    pub fn new(source: StreamSource, alerts: PathBuf) -> Self {
        WatchOptions {
            source,
            alerts,
            checkpoint: None,
            checkpoint_every: CHECKPOINT_EVERY,
            window: WINDOW,
            tolerance: None,
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            rate: None,
            diagnosis: Some(DiagnosisOptions::default()),
            learning: LearnOptions::default(),
            columns: ColumnMap::default(),
            modes: None,
            adopt: false,
        }
    }

    /// The options `watch` does not check itself (it checks the window, the checkpoint
    /// interval, the rate and the budget).
    pub fn validate(&self) -> Result<(), WatchError> {
        crate::workflows::options::check_tolerance(self.tolerance)?;
        if let Some(d) = &self.diagnosis {
            for (name, value) in [
                ("--diagnosis-record", d.record),
                ("--diagnosis-after", d.after),
            ] {
                if !(value >= 0.0 && value.is_finite()) {
                    return Err(WatchError::Options(format!(
                        "{name} must be a non-negative number of seconds, was {value}"
                    )));
                }
            }
            if !(d.post > 0.0 && d.post <= background::MAX_POST) {
                return Err(WatchError::Options(format!(
                    "--diagnosis-post must be a number of seconds in (0, {}], was {}",
                    background::MAX_POST,
                    d.post
                )));
            }
        }
        if let Some(t) = self.learning.threshold {
            if !(t > 0.0 && t.is_finite()) {
                return Err(WatchError::Options(format!(
                    "--query-threshold must be a positive variance (m²/s⁴), was {t}"
                )));
            }
        }
        Ok(())
    }
}

impl StreamSource {
    /// `--source`: `-` (standard input), `mqtt://HOST[:PORT]/TOPIC`, else a CSV file; with
    /// `--follow`, `--idle` (s; a followed file's default 10 s, a broker's: never) and
    /// `--client-id` (MQTT only).
    pub fn parse(
        text: &str,
        follow: bool,
        idle: Option<f64>,
        client_id: Option<String>,
    ) -> Result<StreamSource, WatchError> {
        if let Some(idle) = idle {
            if !(idle >= 0.0 && idle.is_finite()) {
                return Err(WatchError::Options(format!(
                    "--idle must be a non-negative number of seconds, was {idle}"
                )));
            }
        }
        let mqtt = MqttUrl::parse(text).transpose()?;
        if client_id.is_some() && mqtt.is_none() {
            return Err(WatchError::Options(
                "--client-id is for an mqtt:// source".into(),
            ));
        }
        Ok(if let Some(url) = mqtt {
            if follow {
                return Err(WatchError::Options(
                    "--follow is for a file source; an MQTT source is followed anyway".into(),
                ));
            }
            StreamSource::Mqtt {
                url,
                client_id,
                idle: idle.map(Duration::from_secs_f64),
            }
        } else if text == "-" {
            if follow {
                return Err(WatchError::Options(
                    "--follow is for a file source; standard input is read to its end".into(),
                ));
            }
            StreamSource::Stdin
        } else {
            StreamSource::File {
                path: PathBuf::from(text),
                follow,
                idle: Duration::from_secs_f64(idle.unwrap_or(FILE_IDLE)),
            }
        })
    }
}

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

/// A checkpoint's format version (2: any channels).
const CHECKPOINT_VERSION: u32 = 2;
/// A time step above this × the nominal one is a gap.
pub const GAP_FACTOR: f64 = 1.5;
const POLL: Duration = Duration::from_millis(100);

/// Everything a restarted watcher needs to go on exactly.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct State {
    version: u32,
    options: Options,
    /// Nominal sampling interval, s (None before the second sample).
    dt: Option<f64>,
    /// Data lines read (after the header), good or bad.
    lines: u64,
    samples: u64,
    last_time: Option<f64>,
    /// The current segment's first time and its samples so far (its FMU clock).
    segment_start: Option<f64>,
    segment_count: u64,
    /// The stream's excitation and measured channels (its first header's).
    excitation: Channel,
    channels: Vec<Channel>,
    /// The last header line of an MQTT stream (a resumed watcher reads the broker's lines with
    /// it).
    header: Option<String>,
    /// The band's noise variance per channel, once known.
    noise_variance: Option<Vec<f64>>,
    /// The sums over the reference stretch for the channels the twin holds no noise variance
    /// for.
    reference: Welford,
    /// Samples (time, measured, predicted) held until the detector can judge them: the
    /// stream's first until the second gives the sampling interval, and those before the
    /// noise variances are known.
    held: Vec<(f64, Vec<f64>, Vec<f64>)>,
    detector: Option<Detector>,
    bad_lines: u64,
    #[serde(default)]
    duplicates: u64,
    gaps: u64,
    missing_samples: u64,
    /// Alerts raised so far (their sequence numbers run on from here), by kind.
    seq: u64,
    alerts: BTreeMap<String, u64>,
    fmu: Vec<NodeState>,
    fmu_last: Option<(f64, f64)>,
    #[serde(default)]
    background: background::Saved,
    #[serde(default)]
    supervisor: Option<Supervisor>,
    /// The twins the watch adopted, in order: the last is live.
    #[serde(default)]
    adopted: Vec<Adopted>,
}

/// A twin the watch adopted: live from `at` (s of the stream), written to `twin`, on the
/// verdict of the diagnosis `report`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Adopted {
    pub at: f64,
    pub twin: PathBuf,
    pub verdict: String,
    pub report: PathBuf,
}

/// Lines of the stream: from standard input or a file (a partial last line of a growing file
/// held until it is complete), or from an MQTT topic's messages.
enum LineReader {
    Text {
        reader: Box<dyn BufRead>,
        follow: Option<Duration>,
        partial: String,
    },
    Mqtt(Box<MqttSource>),
}

impl LineReader {
    fn open(source: &StreamSource) -> Result<Self, WatchError> {
        Ok(match source {
            StreamSource::Stdin => LineReader::Text {
                reader: Box::new(BufReader::new(std::io::stdin())),
                follow: None,
                partial: String::new(),
            },
            StreamSource::File { path, follow, idle } => LineReader::Text {
                reader: Box::new(BufReader::new(
                    File::open(path).map_err(io(format!("cannot open {}", path.display())))?,
                )),
                follow: follow.then_some(*idle),
                partial: String::new(),
            },
            StreamSource::Mqtt {
                url,
                client_id,
                idle,
            } => LineReader::Mqtt(Box::new(MqttSource::open(
                url.clone(),
                client_id.clone(),
                *idle,
            )?)),
        })
    }

    fn mqtt(&mut self) -> Option<&mut MqttSource> {
        match self {
            LineReader::Mqtt(m) => Some(m),
            LineReader::Text { .. } => None,
        }
    }

    /// The next line without its line break; None at the end.
    fn next(&mut self) -> Result<Option<String>, WatchError> {
        let (reader, follow, partial) = match self {
            LineReader::Mqtt(m) => return m.next_line(),
            LineReader::Text {
                reader,
                follow,
                partial,
            } => (reader, follow, partial),
        };
        let mut idle_since = Instant::now();
        loop {
            let n = reader
                .read_line(partial)
                .map_err(io("cannot read the stream"))?;
            if partial.ends_with('\n') {
                let line = std::mem::take(partial);
                return Ok(Some(line.trim_end_matches(['\n', '\r']).to_owned()));
            }
            if n > 0 {
                idle_since = Instant::now();
            }
            match follow {
                Some(idle) if idle_since.elapsed() < *idle => std::thread::sleep(POLL),
                _ => {
                    // The end: a last line without a line break still counts.
                    return Ok((!partial.is_empty())
                        .then(|| std::mem::take(partial).trim_end_matches('\r').to_owned()));
                }
            }
        }
    }
}

/// Running mean and variance per channel (Welford), for the band's prior.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
struct Welford {
    n: u64,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Welford {
    fn add(&mut self, values: &[f64]) {
        if self.mean.len() != values.len() {
            self.mean = vec![0.0; values.len()];
            self.m2 = vec![0.0; values.len()];
        }
        self.n += 1;
        for (c, &y) in values.iter().enumerate() {
            let d = y - self.mean[c];
            self.mean[c] += d / self.n as f64;
            self.m2[c] += d * (y - self.mean[c]);
        }
    }

    /// Channel `c`'s variance (population, as `compare`'s prior takes it).
    fn variance(&self, c: usize) -> f64 {
        self.m2[c] / self.n as f64
    }
}

/// The stream's columns, as the record module reads a header line, checked against the twin:
/// its excitation the one the structure takes, every response a channel of a floor it has.
struct Header(LineLayout);

impl Header {
    fn parse(
        line: &str,
        columns: &ColumnMap,
        structure: &::structure::Structure,
        twin: &str,
    ) -> Result<Self, String> {
        let layout = LineLayout::parse_with(line, columns)?;
        for channel in
            std::iter::once(layout.excitation()).chain(layout.responses().iter().copied())
        {
            channel.check(&channel.name(), structure).map_err(|e| {
                format!(
                    "{e} (the twin: {twin}, {} storey(s) under {})",
                    structure.storeys(),
                    structure.excitation.describe()
                )
            })?;
        }
        Ok(Header(layout))
    }

    /// The stream's columns: the same excitation, the channels in `channels`' order.
    fn for_stream(self, excitation: Channel, channels: &[Channel]) -> Result<Self, String> {
        if self.0.excitation() != excitation {
            return Err(format!(
                "the header's excitation '{}' is not the stream's '{}'",
                self.0.excitation().name(),
                excitation.name()
            ));
        }
        self.0.in_order(channels).map(Header)
    }
}

/// Per-sample processing times in logarithmic bins (5 % wide, from 10 ns): constant memory.
struct Latency {
    bins: Vec<u64>,
    n: u64,
}

const LATENCY_BASE: f64 = 1e-8;
const LATENCY_RATIO: f64 = 1.05;

impl Latency {
    fn new() -> Self {
        Latency {
            bins: vec![0; 520],
            n: 0,
        }
    }
    fn add(&mut self, seconds: f64) {
        let i = ((seconds.max(LATENCY_BASE) / LATENCY_BASE).ln() / LATENCY_RATIO.ln()) as usize;
        let i = i.min(self.bins.len() - 1);
        self.bins[i] += 1;
        self.n += 1;
    }
    /// The `q` quantile (s): the upper edge of its bin; NaN without samples.
    fn quantile(&self, q: f64) -> f64 {
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
struct Alerts {
    file: File,
    /// Alerts with a sequence number up to this are in the file already.
    written: u64,
    /// The diagnoses (their window's start and round) the file holds already.
    diagnosed: Vec<(f64, u32)>,
}

impl Alerts {
    fn open(path: &Path, resuming: bool) -> Result<Self, WatchError> {
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
    fn write(&mut self, alert: &Value) -> Result<bool, WatchError> {
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
fn window_values(windows: Vec<crate::evaluation::compare::FailingWindow>) -> Value {
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
fn floats(x: impl AsRef<[f64]>) -> Value {
    let x: Vec<Option<f64>> = x
        .as_ref()
        .iter()
        .map(|v| v.is_finite().then_some(*v))
        .collect();
    json!(x)
}

struct Watcher<'a> {
    /// Told of every alert written (its JSON object); an error stops the watch.
    on_alert: &'a mut dyn FnMut(&Value) -> Result<(), String>,
    state: State,
    stepper: Stepper,
    /// The twin live now: the one watched, or the last adopted.
    live: Twin,
    alerts: Alerts,
    reader: LineReader,
    /// A line read before the watch began (an MQTT stream's first), given out first.
    pushed_back: Option<String>,
    background: Option<Background>,
    /// The twin's noise variance per measured channel, where it holds one.
    twin_noise: Vec<Option<f64>>,
    options: &'a WatchOptions,
    /// The sample's measured values and the twin's predictions (per channel; reused).
    measured: Vec<f64>,
    predicted: Vec<f64>,
    /// The twin's modes while the tracker waits for the sampling interval, then the tracker.
    twin_modes: Option<crate::workflows::modal::TwinModes>,
    tracker: Option<modes::Tracker>,
    /// The live view (`--serve`), dropped if it panics.
    observer: Option<&'a mut dyn Observer>,
    /// When the checkpoint was last saved.
    saved_at: Option<Instant>,
    /// Windows open when their segment ended (a gap, the stream's end), for the gap's or the
    /// end's alert.
    cut_windows: Vec<crate::evaluation::compare::FailingWindow>,
}

impl Watcher<'_> {
    fn alert(&mut self, time: Option<f64>, kind: &str, mut body: Value) -> Result<(), WatchError> {
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
    fn send(&mut self, body: &Value) -> Result<(), WatchError> {
        if self.alerts.write(body)? {
            if let Some(m) = self.reader.mqtt() {
                m.publish_alert(body.to_string())?;
            }
            self.observe(|o| o.alert(body));
            (self.on_alert)(body).map_err(WatchError::Callback)?;
        }
        Ok(())
    }

    /// Tell the live view, if any; a panic in it drops the view, never the watch.
    fn observe<R>(&mut self, call: impl FnOnce(&mut dyn Observer) -> R) -> Option<R> {
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
    fn show(&mut self, time: f64, began: Instant) {
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
    fn show_state(&mut self, this_run: u64, elapsed: f64, finished: bool) {
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

    /// The broker connection's changes as `connection` alerts (without a sequence number: a
    /// resumed run's connections are its own).
    fn connection_alerts(&mut self) -> Result<(), WatchError> {
        let Some(m) = self.reader.mqtt() else {
            return Ok(());
        };
        let events = m.take_events();
        self.report_connection(events)
    }

    /// Connection changes as `connection` alerts.
    fn report_connection(&mut self, events: Vec<ConnectionEvent>) -> Result<(), WatchError> {
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

    /// The next line of the stream, the connection's changes reported.
    fn next_line(&mut self) -> Result<Option<String>, WatchError> {
        if let Some(line) = self.pushed_back.take() {
            return Ok(Some(line));
        }
        let line = self.reader.next();
        self.connection_alerts()?;
        line
    }

    fn events(&mut self, time: f64, events: Vec<Event>) -> Result<(), WatchError> {
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

    fn save(&mut self) -> Result<(), WatchError> {
        let Some(path) = &self.options.checkpoint else {
            return Ok(());
        };
        if self.state.segment_start.is_some() {
            self.state.fmu = self.stepper.save()?;
            self.state.fmu_last = self.stepper.last();
        }
        if let Some(b) = &self.background {
            self.state.background = b.saved.clone();
        }
        let text = serde_json::to_string(&self.state)
            .map_err(|e| WatchError::Checkpoint(e.to_string()))?;
        write_text_atomically(path, &text)?;
        self.saved_at = Some(Instant::now());
        Ok(())
    }

    /// NaN for every measured channel.
    fn nan(&self) -> Vec<f64> {
        vec![f64::NAN; self.state.channels.len()]
    }

    /// The band's noise variances once known: the twin's for every channel it holds one for;
    /// for the others, [`PRIOR_NOISE_FRACTION`] of the measured variance over the
    /// [`NOISE_REFERENCE`] seconds after the segment's transient (summed as they come;
    /// `since`: the sample's time after the segment's start). Whether they are known (in
    /// `self.state.noise_variance`).
    fn noise_known(&mut self, since: f64) -> bool {
        if self.state.noise_variance.is_some() {
            return true;
        }
        if self.twin_noise.iter().all(Option::is_some) {
            self.state.noise_variance = Some(self.twin_noise.iter().flatten().copied().collect());
            return true;
        }
        let transient = self.options.transient;
        if since >= transient && since < transient + NOISE_REFERENCE {
            self.state.reference.add(&self.measured);
            return false;
        }
        if since < transient + NOISE_REFERENCE || self.state.reference.n < 2 {
            return false;
        }
        let reference = &self.state.reference;
        let v: Vec<f64> = self
            .twin_noise
            .iter()
            .enumerate()
            .map(|(c, own)| own.unwrap_or_else(|| PRIOR_NOISE_FRACTION * reference.variance(c)))
            .collect();
        self.state.noise_variance = Some(v);
        true
    }

    /// Where the band's noise variances come from, in words.
    fn noise_source(&self) -> String {
        let (own, prior): (Vec<usize>, Vec<usize>) =
            (0..self.twin_noise.len()).partition(|&c| self.twin_noise[c].is_some());
        let names = |c: &[usize]| {
            c.iter()
                .map(|&c| self.state.channels[c].name())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let prior_words = format!(
            "prior: {} % of the measured variance over the {NOISE_REFERENCE} s after the transient",
            100.0 * PRIOR_NOISE_FRACTION
        );
        match (own.is_empty(), prior.is_empty()) {
            (false, true) => "twin (calibrated)".to_owned(),
            (true, _) => prior_words,
            (false, false) => format!(
                "twin (calibrated) for {}; {prior_words} for {}",
                names(&own),
                names(&prior)
            ),
        }
    }

    /// One good sample: its time and excitation; its measured values in `self.measured`.
    fn sample(&mut self, time: f64, excitation: f64) -> Result<(), WatchError> {
        if let (None, Some(last)) = (self.state.dt, self.state.last_time) {
            // The second sample gives the interval (unless --rate did).
            let dt = self
                .options
                .rate
                .map_or_else(|| nominal_step(time - last), |r| 1.0 / r);
            self.state.dt = Some(dt);
            if let Some(b) = &mut self.background {
                b.set_dt(dt);
            }
        }
        if let (Some(last), Some(dt)) = (self.state.last_time, self.state.dt) {
            let step = time - last;
            if step > GAP_FACTOR * dt {
                let missing = ((step / dt).round() as u64).saturating_sub(1);
                if let Some(d) = &mut self.state.detector {
                    let events = d.finish_segment();
                    self.events(last, events)?;
                }
                self.state.gaps += 1;
                self.state.missing_samples += missing;
                let cut = window_values(std::mem::take(&mut self.cut_windows));
                self.alert(
                    Some(time),
                    "gap",
                    json!({"after": last, "missing": missing,
                           "step": step, "nominal_step": dt, "still_failing": cut}),
                )?;
                // Re-synchronise: the twin at rest from here, the comparison's transient anew
                // (and the band's reference, if it was not complete).
                if let Some(b) = &mut self.background {
                    b.gap();
                }
                if let Some(s) = &mut self.state.supervisor {
                    s.gap();
                }
                if let Some(t) = &mut self.tracker {
                    t.gap();
                }
                self.state.segment_start = None;
                self.state.held.clear();
                if self.state.noise_variance.is_none() {
                    self.state.reference = Welford::default();
                }
            }
        }
        if self.state.segment_start.is_none() {
            self.stepper.start(time)?;
            self.state.segment_start = Some(time);
            self.state.segment_count = 0;
        }
        let start = self.state.segment_start.unwrap_or(time);
        let grid = match self.state.dt {
            Some(dt) => start + self.state.segment_count as f64 * dt,
            None => time,
        };
        self.stepper
            .advance(grid, excitation, &mut self.predicted)?;
        self.state.segment_count += 1;
        if let Some(b) = &mut self.background {
            b.push(time, excitation, &self.measured);
        }
        self.track(time)?;
        self.state.samples += 1;
        self.state.last_time = Some(time);
        let known = self.noise_known(time - start);
        let (Some(dt), true) = (self.state.dt, known) else {
            // The stream's first sample waits for the second to give the interval, and the
            // first samples for the band's reference.
            self.state
                .held
                .push((time, self.measured.clone(), self.predicted.clone()));
            return Ok(());
        };
        let mut events = Vec::new();
        let channels = &self.state.channels;
        let options = self.state.options;
        let noise = self.state.noise_variance.as_deref().unwrap_or_default();
        let detector = self
            .state
            .detector
            .get_or_insert_with(|| Detector::new(options, channels.clone(), noise, dt));
        for (t, y, p) in self.state.held.drain(..) {
            events.extend(detector.push(t, &y, &p));
        }
        events.extend(detector.push(time, &self.measured, &self.predicted));
        self.events(time, events)?;
        if self.state.supervisor.is_some() && time - start >= self.options.transient {
            self.supervise(time)?;
        }
        if let Some(finished) = self.background.as_mut().and_then(|b| b.poll(time)) {
            self.diagnosed(finished)?;
        }
        Ok(())
    }

    /// The modes on the sliding window: a `modes` alert per identification, `frequency` when a
    /// twin mode leaves its band (`frequency_back` when it returns), `modes_failed` when the
    /// window could not be identified.
    fn track(&mut self, time: f64) -> Result<(), WatchError> {
        if self.tracker.is_none() {
            if let (Some(dt), Some(options)) = (self.state.dt, self.options.modes) {
                if let Some(twin) = self.twin_modes.take() {
                    self.tracker = Some(modes::Tracker::new(
                        options,
                        twin,
                        self.state.channels.clone(),
                        dt,
                    ));
                }
            }
        }
        let Some(tracker) = &mut self.tracker else {
            return Ok(());
        };
        let Some(result) = tracker.push(time, &self.measured) else {
            return Ok(());
        };
        match result {
            Ok(tracked) => {
                for mode in &tracked.left {
                    let m = &tracked.modes[mode - 1];
                    self.alert(
                        Some(time),
                        "frequency",
                        json!({"mode": mode, "twin_frequency": m.twin_frequency,
                               "frequency": m.frequency, "shift_percent": m.shift_percent,
                               "shift_sd": m.shift_sd, "band": m.band}),
                    )?;
                }
                for mode in &tracked.returned {
                    let m = &tracked.modes[mode - 1];
                    self.alert(
                        Some(time),
                        "frequency_back",
                        json!({"mode": mode, "twin_frequency": m.twin_frequency,
                               "frequency": m.frequency}),
                    )?;
                }
                let body = serde_json::to_value(&tracked).unwrap_or(Value::Null);
                self.alert(Some(time), "modes", body)?;
            }
            Err(reason) => {
                self.alert(Some(time), "modes_failed", json!({"reason": reason}))?;
            }
        }
        Ok(())
    }

    /// The corrector's latent variances against the thresholds: a query learns the sample,
    /// an excursion is an `uncertain` alert, its end a `certain` one.
    fn supervise(&mut self, time: f64) -> Result<(), WatchError> {
        let Some(v) = self.stepper.latent_variance()? else {
            return Ok(());
        };
        let Some(supervisor) = &mut self.state.supervisor else {
            return Ok(());
        };
        let decision = supervisor.decide(time, &v, self.options.window);
        let threshold = supervisor.threshold.clone();
        let queries = supervisor.queries;
        match decision {
            Decision::Quiet => {}
            Decision::Query { floors, alarm } => {
                if self.options.learning.learn {
                    self.stepper.learn_current(&self.measured)?;
                }
                if alarm {
                    let positions: Vec<usize> = floors.iter().map(|f| f - 1).collect();
                    let (channels, floors) = names_and_floors(&self.state.channels, &positions);
                    self.alert(
                        Some(time),
                        "uncertain",
                        json!({"floors": floors, "channels": channels,
                               "latent_variance": floats(v), "threshold": threshold.map(floats)}),
                    )?;
                }
            }
            Decision::Closes { since, peak } => {
                self.alert(
                    Some(time),
                    "certain",
                    json!({"since": since, "queries": queries, "peak_ratio": peak}),
                )?;
            }
        }
        Ok(())
    }

    /// A background diagnosis finished: its report beside the alerts, and a `diagnosis`
    /// alert (without a sequence number: when it comes depends on the machine).
    fn diagnosed(&mut self, finished: Finished) -> Result<(), WatchError> {
        *self.state.alerts.entry("diagnosis".to_owned()).or_default() += 1;
        let job = &finished.job;
        if self
            .alerts
            .diagnosed
            .contains(&(job.window_start, job.round))
        {
            // Reported before a restart.
            return Ok(());
        }
        let mut body = self.diagnosis_body(&finished);
        let mut adoption = None;
        match &finished.result {
            Ok(d) => {
                let path = self.write_diagnosis(d, job)?;
                if self.options.adopt && finished.firm {
                    adoption = answer(d).map(|p| (p, background::verdict(d), path.clone()));
                }
                if let Value::Object(m) = &mut body {
                    answer_fields(m, d, &path);
                }
            }
            Err(error) => {
                if let Value::Object(m) = &mut body {
                    m.insert("error".into(), json!(error));
                }
            }
        }
        self.alerts.diagnosed.push((job.window_start, job.round));
        self.send(&body)?;
        let Some((parameters, verdict, report)) = adoption else {
            return Ok(());
        };
        self.adopt(&parameters, verdict, report)?;
        if let (Some(c), Some(b)) = (&finished.second, &mut self.background) {
            b.second(c);
        }
        Ok(())
    }

    /// The diagnosis alert's body before its answer: the samples it used (all from `from` to
    /// `to`; after a located change, those from the change on are the ones its error measures
    /// score) and, after a change, whether it is firm, its evidence, what it waited for.
    fn diagnosis_body(&self, finished: &Finished) -> Value {
        let job = &finished.job;
        let (from, to) = job.span();
        let width = job.columns.width();
        let mut body = json!({
            "time": self.state.last_time, "kind": "diagnosis", "window_start": job.window_start,
            "from": from, "to": to, "samples_used": job.samples.len() / width,
            "seconds": finished.seconds, "round": job.round,
        });
        if let (Some(change), Value::Object(m)) = (job.change, &mut body) {
            m.insert("change_time".into(), json!(change));
            m.insert("post_change_seconds".into(), json!(to - change));
            m.insert("firm".into(), json!(finished.firm));
            if let Some(w) = &finished.weight {
                m.insert("evidence".into(), json!(w));
            }
            if let Some(b) = &finished.before {
                // Its effects against the samples before the change: there all along?
                m.insert("before_the_change".into(), json!(b));
            }
            if let Some(why) = &finished.because {
                // How much post-change data it waited for, and why that was enough.
                m.insert(
                    "waited".into(),
                    json!(format!(
                        "{:.1} s of post-change data, because {why}",
                        to - change
                    )),
                );
            }
            if let Some(c) = &finished.second {
                // It answered on the samples before a second change found in them.
                m.insert(
                    "second_change".into(),
                    json!({"time": c.time, "low": c.low, "high": c.high}),
                );
            }
        }
        body
    }

    /// The diagnosis report written beside the alerts, and the samples it ran on (for `twin
    /// add-physics --diagnosis R --data R.csv`, the live page's accept); the report's path.
    fn write_diagnosis(
        &self,
        d: &crate::workflows::diagnose::Diagnosis,
        job: &background::Job,
    ) -> Result<PathBuf, WatchError> {
        let k = self.background.as_ref().map_or(0, |b| b.saved.reported);
        let path = background::report_path(&self.options.alerts, k);
        let text =
            serde_json::to_string_pretty(d).map_err(|e| WatchError::Checkpoint(e.to_string()))?;
        write_text_atomically(&path, &text)?;
        let samples = path.with_extension("csv");
        if let Ok(m) = background::record(job) {
            write_text_atomically(&samples, &crate::record::csv_text(&m))?;
        }
        Ok(path)
    }

    /// Adopt the twin a firm verdict names ([`answer`]): written beside the alerts, swapped in
    /// at the current point,
    /// the live twin of later diagnoses; an `adopted` alert, and the checkpoint records it. Its
    /// physics goes on from the state it reaches over the samples kept (from rest 70 s back
    /// with the defaults: what is left of the start is e^(−ζωt), far below the noise), not from
    /// the old twin's, which has been failing since the change; over the kept samples before
    /// that change the twins live then run instead ([`Background::reached`]: a structure that
    /// changed twice is not the second answer's before the first change). No sample is lost.
    fn adopt(
        &mut self,
        parameters: &[(String, ParameterValue)],
        verdict: String,
        report: PathBuf,
    ) -> Result<(), WatchError> {
        let Some((time, excitation)) = self.stepper.last() else {
            return Ok(());
        };
        let adopted = answered(&self.live, parameters)?;
        let path = adopted_path(&self.options.alerts, self.state.adopted.len() + 1);
        adopted.write(&path)?;
        let (mut stepper, _) = open_stepper(
            &adopted,
            self.state.excitation,
            &self.state.channels,
            &self.options.learning,
        )?;
        let state = match self.background.as_ref().map(|b| (b, b.kept())) {
            Some((b, Ok(kept))) => b
                .reached(&adopted, &kept)
                .map_err(|e| WatchError::Twin(TwinError::Message(e.to_string())))?,
            _ => None,
        };
        match &state {
            Some(state) => stepper.start_from(time, state)?,
            None => stepper.start(time)?,
        }
        stepper.advance(time, excitation, &mut self.predicted)?;
        self.stepper = stepper;
        if let Some(b) = &mut self.background {
            b.adopted(&adopted);
        }
        // The comparison starts anew with the adopted twin (a segment of its own, the stream's
        // NMSE and window count going on): the windows open now are the change's, resolved
        // by it, and a further change opens a window (and an episode) of its own.
        let events = match &mut self.state.detector {
            Some(d) => d.finish_segment(),
            None => Vec::new(),
        };
        let open = self.cut_windows.len();
        self.events(time, events)?;
        let resolved = window_values(self.cut_windows.split_off(open));
        self.live = adopted;
        self.state.adopted.push(Adopted {
            at: time,
            twin: path.clone(),
            verdict: verdict.clone(),
            report: report.clone(),
        });
        self.alert(
            Some(time),
            "adopted",
            json!({"twin": path, "verdict": verdict, "report": report, "resolves": resolved,
                   "from": if state.is_some() { "its state over the samples kept" } else { "rest" },
                   "parameters": parameters.iter().map(|(n, v)| json!({"name": n, "value": match v {
                       ParameterValue::Real(x) => json!(x),
                       ParameterValue::Integer(i) => json!(i),
                       ParameterValue::Boolean(b) => json!(b),
                   }})).collect::<Vec<_>>()}),
        )
    }
}

/// The stepper of `twin` (wired to give out every one of `channels`), its corrector's learning
/// parameters set; with the training-set budget when the corrector's FMU takes one.
fn open_stepper(
    twin: &Twin,
    excitation: Channel,
    channels: &[Channel],
    learning: &LearnOptions,
) -> Result<(Stepper, Option<u32>), WatchError> {
    let wired = stepper::wired(twin, channels);
    let mut stepper = Stepper::new(wired.as_ref().unwrap_or(twin), excitation, channels)?;
    let mut budget = Some(learning.budget);
    if stepper.has_learner() {
        if !(1..=2048).contains(&learning.budget) {
            return Err(WatchError::Options(format!(
                "--budget must be between 1 and 2048 points, was {}",
                learning.budget
            )));
        }
        if !stepper.set_learner_parameter("budget", learning.budget as i32) {
            budget = None;
        }
        stepper.set_learner_parameter("refit_every", learning.refit_every as i32);
    }
    Ok((stepper, budget))
}

/// A diagnosis alert's answer: the diagnosis's action, reason, effects and scores, where its
/// fits started, and its report's and samples' paths.
fn answer_fields(
    m: &mut serde_json::Map<String, Value>,
    d: &crate::workflows::diagnose::Diagnosis,
    path: &Path,
) {
    m.insert("action".into(), json!(d.action));
    m.insert("reason".into(), json!(d.reason));
    m.insert("effects".into(), json!(d.effects));
    m.insert("channels".into(), json!(d.channels));
    m.insert("nmse_before".into(), floats(&d.nmse_before));
    m.insert("nmse_after".into(), floats(&d.nmse_after));
    if let Some(at) = d.changed_at {
        // Its fits started there, from the state the twin reached on the samples before;
        // those after are the ones it scored.
        m.insert("fitted_from".into(), json!(at));
    }
    m.insert("report".into(), json!(path.display().to_string()));
    m.insert(
        "samples".into(),
        json!(path.with_extension("csv").display().to_string()),
    );
}

/// The physics parameters a firm verdict sets: a recalibration's every parameter; the
/// library effects `add_physics` names, switched on with their jointly fitted values, and the
/// physics that moved with them. None for any other verdict, and for a discovered effect (its
/// twin comes from `twin add-physics`, which refits its terms).
fn answer(d: &crate::workflows::diagnose::Diagnosis) -> Option<Vec<(String, ParameterValue)>> {
    use crate::workflows::diagnose::Candidate;
    let real = |(name, value): (String, f64)| (name, ParameterValue::Real(value));
    match d.action {
        Action::Recalibrate => Some(
            d.recalibration
                .as_ref()?
                .parameters
                .iter()
                .map(|p| real((p.name.clone(), p.after)))
                .collect(),
        ),
        Action::AddPhysics if !d.effects.is_empty() => {
            let mut set = Vec::new();
            for e in &d.effects {
                let c = Candidate::parse(&e.name.label, structure::MAX_STOREYS).ok()?;
                set.extend(c.switches());
                for (name, short) in c.parameter_names() {
                    set.push(real((name, *e.parameters.get(short)?)));
                }
            }
            set.extend(
                d.physics_moved
                    .iter()
                    .map(|p| real((p.name.clone(), p.after))),
            );
            Some(set)
        }
        _ => None,
    }
}

/// The twin a firm verdict names ([`answer`]): `live` with those physics parameters, its noise
/// variances and posterior kept (the stream's noise did not change).
fn answered(live: &Twin, parameters: &[(String, ParameterValue)]) -> Result<Twin, WatchError> {
    let mut twin = live.duplicate();
    let physics = twin.component_mut(crate::twin::PHYSICS).ok_or_else(|| {
        WatchError::Twin(TwinError::Message(format!(
            "{} has no physics component",
            live.describe()
        )))
    })?;
    for (name, value) in parameters {
        physics.parameters.insert(name.clone(), value.clone());
    }
    twin.source = None;
    Ok(twin)
}

/// Where the `k`-th adopted twin goes: beside the alerts, `ALERTS.twin-k.ssp`.
fn adopted_path(alerts: &Path, k: usize) -> PathBuf {
    let stem = alerts
        .file_stem()
        .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
    alerts.with_file_name(format!("{stem}.twin-{k}.ssp"))
}

/// Watch the stream `options.source` with `twin`, alerts to `options.alerts`; `progress` gets
/// a status now and then. Returns the `end` alert's summary.
pub fn watch(
    twin: &Twin,
    options: &WatchOptions,
    progress: impl FnMut(&Status),
) -> Result<Summary, WatchError> {
    watch_with_alerts(twin, options, progress, &mut |_| Ok(()))
}

/// [`watch`], with `on_alert` told of each alert as it is written (the Python package's
/// callback); an error it returns ends the watch with [`WatchError::Callback`].
pub fn watch_with_alerts(
    twin: &Twin,
    options: &WatchOptions,
    progress: impl FnMut(&Status),
    on_alert: &mut dyn FnMut(&Value) -> Result<(), String>,
) -> Result<Summary, WatchError> {
    watch_observed(twin, options, progress, on_alert, None)
}

/// [`watch_with_alerts`], with a live view told of the samples, alerts and state as they come
/// (`twin watch --serve`); it never holds the stream up.
pub fn watch_observed(
    twin: &Twin,
    options: &WatchOptions,
    mut progress: impl FnMut(&Status),
    on_alert: &mut dyn FnMut(&Value) -> Result<(), String>,
    observer: Option<&mut dyn Observer>,
) -> Result<Summary, WatchError> {
    let structure = twin.structure()?;
    check_options(options)?;
    let tolerance = Tolerance::resolve(twin, options.tolerance);
    let detector_options = Options::new(
        CompareOptions {
            transient: options.transient,
            tolerance: tolerance.value,
            ..CompareOptions::default()
        },
        options.window,
    );
    let saved = match &options.checkpoint {
        Some(path) if path.exists() => Some(read_checkpoint(path, detector_options)?),
        _ => None,
    };
    // A watch that adopted a twin goes on with the last one it adopted.
    let resumed = match saved.as_ref().and_then(|s| s.adopted.last()) {
        Some(a) => Some(Twin::load(Some(&a.twin))?),
        None => None,
    };
    let twin = resumed.as_ref().unwrap_or(twin);
    let mut reader = LineReader::open(&options.source)?;
    let from_broker = matches!(reader, LineReader::Mqtt(_));
    let Opening {
        header_line,
        early_events,
        pushed_back,
    } = opening(&mut reader, saved.as_ref(), &structure)?;
    let describe = twin.describe();
    let (mut header, excitation, channels) =
        stream_header(&header_line, options, &structure, &describe, saved.as_ref())?;
    let (mut stepper, budget) = open_stepper(twin, excitation, &channels, &options.learning)?;
    let resuming = saved.is_some();
    let mut state = start_state(&mut stepper, saved, detector_options, excitation, &channels)?;
    if from_broker {
        state.header = Some(header_line.clone());
    }
    if stepper.has_learner() && state.supervisor.is_none() {
        state.supervisor = Some(Supervisor::new(options.learning.threshold, channels.len()));
    }
    let alerts = Alerts::open(&options.alerts, resuming)?;
    let background = background_of(twin, options, &state, excitation, &channels);
    let twin_noise = channels
        .iter()
        .map(|&c| twin.noise_variance_of(c))
        .collect();
    let twin_modes = match &options.modes {
        Some(track) => Some(modes_to_track(twin, track)?),
        None => None,
    };
    let mut w = Watcher {
        on_alert,
        state,
        stepper,
        live: twin.duplicate(),
        alerts,
        reader,
        pushed_back,
        background,
        twin_noise,
        options,
        measured: vec![0.0; channels.len()],
        predicted: vec![0.0; channels.len()],
        twin_modes,
        tracker: None,
        // A shorter borrow of the observer (its object lifetime shortened with it).
        observer: match observer {
            Some(o) => Some(o as &mut dyn Observer),
            None => None,
        },
        saved_at: None,
        cut_windows: Vec::new(),
    };
    let names: Vec<String> = channels.iter().map(Channel::name).collect();
    w.observe(|o| o.start(&names, tolerance.value, options.window));
    w.report_connection(early_events)?;
    let stream = Stream {
        structure: &structure,
        describe: &describe,
        excitation,
        channels: &channels,
        from_broker,
        live: from_broker || matches!(options.source, StreamSource::File { follow: true, .. }),
    };
    let run = read_stream(&mut w, &stream, &mut header, &mut progress)?;
    end(&mut w, &run, &channels, &tolerance, budget, &mut progress)
}

/// The stream's header and its channels: its first header's, or those of the run a checkpoint
/// saved (a header that does not fit them: the checkpoint was made on another stream).
fn stream_header(
    header_line: &str,
    options: &WatchOptions,
    structure: &::structure::Structure,
    describe: &str,
    saved: Option<&State>,
) -> Result<(Header, Channel, Vec<Channel>), WatchError> {
    let header = Header::parse(header_line, &options.columns, structure, describe)
        .map_err(WatchError::Header)?;
    let (excitation, channels) = match saved {
        Some(state) => (state.excitation, state.channels.clone()),
        None => (header.0.excitation(), header.0.responses().to_vec()),
    };
    let header = header
        .for_stream(excitation, &channels)
        .map_err(|message| match &options.checkpoint {
            Some(path) => WatchError::BadCheckpoint {
                path: path.clone(),
                message: format!("made on another stream: {message}"),
            },
            None => WatchError::Header(message),
        })?;
    Ok((header, excitation, channels))
}

/// The watch's state: the checkpoint's, its segment's FMU state restored in `stepper`, or a
/// fresh one.
fn start_state(
    stepper: &mut Stepper,
    saved: Option<State>,
    detector_options: Options,
    excitation: Channel,
    channels: &[Channel],
) -> Result<State, WatchError> {
    Ok(match saved {
        Some(state) => {
            if let Some(start) = state.segment_start {
                stepper.start(start)?;
                stepper.restore(&state.fmu, state.fmu_last)?;
            }
            state
        }
        None => State::fresh(detector_options, excitation, channels.to_vec()),
    })
}

/// The background diagnosis, when the watch runs one.
fn background_of(
    twin: &Twin,
    options: &WatchOptions,
    state: &State,
    excitation: Channel,
    channels: &[Channel],
) -> Option<Background> {
    options.diagnosis.map(|o| {
        let diagnose = crate::workflows::diagnose::DiagnoseOptions {
            transient: options.transient,
            tolerance: options.tolerance,
            ..Default::default()
        };
        let columns = Columns {
            excitation,
            channels: channels.to_vec(),
        };
        let mut b = Background::new(twin, o, diagnose, state.background.clone(), columns);
        if let Some(dt) = state.dt {
            b.set_dt(dt);
        }
        b
    })
}

/// The stream's opening: its header line, the broker's connection events before it, and a
/// first line read past it (an MQTT stream's first sample).
struct Opening {
    header_line: String,
    early_events: Vec<ConnectionEvent>,
    pushed_back: Option<String>,
}

/// The header: a file or standard input starts with its own; an MQTT stream's is the one its
/// last run saw (`saved`), else its first line if that is a header, else time, the excitation
/// and an accelerometer on every floor (the paper rig's `time,force,acc1,acc2,acc3`).
fn opening(
    reader: &mut LineReader,
    saved: Option<&State>,
    structure: &::structure::Structure,
) -> Result<Opening, WatchError> {
    let mut early_events = Vec::new();
    let mut pushed_back = None;
    let header_line = if matches!(reader, LineReader::Mqtt(_)) {
        match saved.and_then(|s| s.header.clone()) {
            Some(h) => h,
            None => loop {
                match reader.next()? {
                    None => {
                        break default_header(structure_excitation(structure), structure.storeys())
                    }
                    Some(line) if line.trim().is_empty() => {
                        if let Some(m) = reader.mqtt() {
                            early_events.extend(m.take_events());
                        }
                    }
                    Some(line) => {
                        let header = is_header(&line).then(|| line.clone());
                        pushed_back = Some(line);
                        break header.unwrap_or_else(|| {
                            default_header(structure_excitation(structure), structure.storeys())
                        });
                    }
                }
            },
        }
    } else {
        loop {
            match reader.next()? {
                None => return Err(WatchError::Header("the stream is empty".into())),
                Some(line) if line.trim().is_empty() => continue,
                Some(line) => break line,
            }
        }
    };
    Ok(Opening {
        header_line,
        early_events,
        pushed_back,
    })
}

/// What the stream is read against: the structure and twin its headers are checked with, its
/// channels, and where it comes from.
struct Stream<'s> {
    structure: &'s ::structure::Structure,
    describe: &'s str,
    excitation: Channel,
    channels: &'s [Channel],
    from_broker: bool,
    /// A followed file or a broker: the time spent waiting for it is left out of the speed.
    live: bool,
}

/// What reading the stream measured: this run's samples and their latencies, when it began
/// and how long it waited for a live source.
struct Run {
    samples: u64,
    latency: Latency,
    started: Instant,
    waited: Duration,
}

impl Run {
    /// Seconds spent on the samples, the waits for a live source left out.
    fn seconds(&self) -> f64 {
        self.started
            .elapsed()
            .saturating_sub(self.waited)
            .as_secs_f64()
    }
}

/// The stream read to its end: each line a header (a broker's), a bad sample or a sample
/// watched; the checkpoint saved every `checkpoint_every` samples, `progress` and the live view
/// told five times a second.
fn read_stream(
    w: &mut Watcher,
    stream: &Stream,
    header: &mut Header,
    progress: &mut impl FnMut(&Status),
) -> Result<Run, WatchError> {
    let options = w.options;
    let mut position = Position {
        // Lines and samples the checkpoint has consumed are skipped (a broker does not
        // replay: there only the samples' times tell what was seen).
        skip_lines: if stream.from_broker { 0 } else { w.state.lines },
        skip_until: w.state.last_time,
        line_number: 0,
        this_run: 0,
    };
    let mut latency = Latency::new();
    let started = Instant::now();
    let mut since_save: u64 = 0;
    let mut last_status = Instant::now();
    // Time spent waiting for a live source (a followed file, a broker), left out of the speed.
    let mut waited = Duration::ZERO;
    loop {
        let asked = Instant::now();
        let Some(line) = w.next_line()? else {
            break;
        };
        if stream.live {
            waited += asked.elapsed();
        }
        if line.trim().is_empty() {
            // A file's blank line still counts for the line numbers; a broker's empty line is
            // only a connection change.
            if !stream.from_broker {
                position.line_number += 1;
            }
            continue;
        }
        position.line_number += 1;
        if stream.from_broker && is_header(&line) {
            broker_header(w, stream, header, line, position.line_number)?;
            continue;
        }
        let began = Instant::now();
        match seen(w, stream, header, &line, &mut position) {
            Seen::Skipped => {}
            Seen::Bad(reason) => {
                w.state.bad_lines += 1;
                let time = w.state.last_time;
                // A file's line numbers count the header as line 1; a broker's count the lines
                // of its messages from 1.
                let line = if stream.from_broker {
                    position.line_number
                } else {
                    position.line_number + 1
                };
                w.alert(time, "bad_sample", json!({"line": line, "reason": reason}))?;
            }
            Seen::Sample(time, excitation) => {
                w.sample(time, excitation)?;
                w.show(time, began);
                position.this_run += 1;
                latency.add(began.elapsed().as_secs_f64());
                since_save += 1;
                if since_save >= options.checkpoint_every {
                    since_save = 0;
                    w.save()?;
                }
                if last_status.elapsed() > Duration::from_millis(200) {
                    last_status = Instant::now();
                    progress(&status(w, position.this_run, started));
                    let elapsed = started.elapsed().saturating_sub(waited).as_secs_f64();
                    w.show_state(position.this_run, elapsed, false);
                }
            }
        }
    }
    Ok(Run {
        samples: position.this_run,
        latency,
        started,
        waited,
    })
}

/// Where the stream is: the line read last, the samples this run took, and what a checkpoint
/// consumed already (skipped).
struct Position {
    skip_lines: u64,
    skip_until: Option<f64>,
    line_number: u64,
    this_run: u64,
}

/// What a data line is to the watch.
enum Seen {
    /// Consumed by the run a checkpoint saved, or a broker's duplicate.
    Skipped,
    Bad(String),
    /// A sample's time and excitation (its responses in the watcher's `measured`).
    Sample(f64, f64),
}

/// A broker's header line mid-stream: the header from then on, or a bad sample when it does not
/// fit the stream.
fn broker_header(
    w: &mut Watcher,
    stream: &Stream,
    header: &mut Header,
    line: String,
    line_number: u64,
) -> Result<(), WatchError> {
    match Header::parse(&line, &w.options.columns, stream.structure, stream.describe)
        .and_then(|h| h.for_stream(stream.excitation, stream.channels))
    {
        Ok(h) => {
            *header = h;
            w.state.header = Some(line);
        }
        Err(e) => {
            w.state.bad_lines += 1;
            let time = w.state.last_time;
            w.alert(
                time,
                "bad_sample",
                json!({"line": line_number, "reason": e.to_string()}),
            )?;
        }
    }
    Ok(())
}

/// A data line read into the watcher's `measured`: skipped when a checkpoint consumed it or a
/// broker sent it twice, bad when it does not parse or its time does not increase.
fn seen(
    w: &mut Watcher,
    stream: &Stream,
    header: &Header,
    line: &str,
    position: &mut Position,
) -> Seen {
    let sample = header.0.sample_into(line, &mut w.measured);
    if position.line_number <= position.skip_lines {
        return Seen::Skipped;
    }
    if let (Ok((t, ..)), Some(until)) = (&sample, position.skip_until) {
        if position.this_run == 0 && *t <= until {
            w.state.lines = position.line_number;
            return Seen::Skipped;
        }
    }
    w.state.lines = position.line_number;
    if let (true, Ok((t, ..)), Some(last)) = (stream.from_broker, &sample, w.state.last_time) {
        if *t <= last {
            w.state.duplicates += 1;
            return Seen::Skipped;
        }
    }
    match (sample, w.state.last_time) {
        (Ok((t, _)), Some(last)) if t <= last => {
            Seen::Bad(format!("time {t} does not increase (previous {last})"))
        }
        (Ok((time, excitation)), _) => Seen::Sample(time, excitation),
        (Err(reason), _) => Seen::Bad(reason),
    }
}

/// The stream's end: the checkpoint saved, the open segment finished, the diagnoses still
/// running awaited, and the `end` alert with the run's summary.
fn end(
    w: &mut Watcher,
    run: &Run,
    channels: &[Channel],
    tolerance: &Tolerance,
    budget: Option<u32>,
    progress: &mut impl FnMut(&Status),
) -> Result<Summary, WatchError> {
    let options = w.options;
    // Saved before the stream's end is judged: a watcher restarted on a source that grew goes
    // on from here.
    w.save()?;
    let elapsed = run.seconds();
    let this_run = run.samples;
    let last = w.state.last_time;
    // The NMSE over the last window at the end (after an adoption: the live twin's).
    let rolling = w
        .state
        .detector
        .as_ref()
        .map_or_else(|| w.nan(), Detector::rolling_nmse);
    if let Some(d) = &mut w.state.detector {
        let events = d.finish_segment();
        w.events(last.unwrap_or(0.0), events)?;
    }
    progress(&status(w, this_run, run.started));
    let finished = w.background.as_mut().map(Background::finish);
    for f in finished.into_iter().flatten() {
        w.diagnosed(f)?;
    }
    let rate = this_run as f64 / elapsed.max(1e-9);
    let real_time = w.state.dt.map_or(f64::NAN, |dt| rate * dt);
    let summary = Summary {
        samples: w.state.samples,
        samples_this_run: this_run,
        bad_lines: w.state.bad_lines,
        duplicates: w.state.duplicates,
        gaps: w.state.gaps,
        missing_samples: w.state.missing_samples,
        alerts: w.state.alerts.clone(),
        failing_windows: w.state.detector.as_ref().map_or(0, |d| d.failing_windows),
        mqtt: w.reader.mqtt().map(|m| m.stats),
        learning: match &w.state.supervisor {
            Some(s) => Some(LearningSummary {
                queries: s.queries,
                learned: options.learning.learn,
                training_points: if w.state.segment_start.is_some() {
                    w.stepper.training_points()?
                } else {
                    None
                },
                budget,
                threshold: s.threshold.clone(),
                largest_ratio: s.largest_ratio,
            }),
            None => None,
        },
        channels: channels.iter().map(Channel::name).collect(),
        nmse: w
            .state
            .detector
            .as_ref()
            .map_or_else(|| w.nan(), |d| d.overall.nmse()),
        noise_source: w.noise_source(),
        samples_per_second: rate,
        real_time_factor: real_time,
        latency_median_us: 1e6 * run.latency.quantile(0.5),
        latency_p99_us: 1e6 * run.latency.quantile(0.99),
        tolerance: tolerance.value,
        still_failing: std::mem::take(&mut w.cut_windows),
    };
    let mut body =
        serde_json::to_value(&summary).map_err(|e| WatchError::Checkpoint(e.to_string()))?;
    if let Value::Object(map) = &mut body {
        map.insert("nmse".into(), floats(&summary.nmse));
        map.insert("rolling_nmse".into(), floats(&rolling));
        map.insert("tolerance_source".into(), json!(tolerance.source));
        map.insert(
            "still_failing".into(),
            window_values(summary.still_failing.clone()),
        );
    }
    w.alert(last, "end", body)?;
    w.show_state(this_run, elapsed, true);
    if let Some(m) = w.reader.mqtt() {
        m.close(Duration::from_secs(5));
    }
    Ok(summary)
}

/// The options `watch_observed` checks itself: the window, the checkpoint interval, the rate.
fn check_options(options: &WatchOptions) -> Result<(), WatchError> {
    if !(options.window > 0.0 && options.window.is_finite()) {
        return Err(WatchError::Options(format!(
            "--window must be a positive number of seconds, was {}",
            options.window
        )));
    }
    if options.checkpoint_every == 0 {
        return Err(WatchError::Options(
            "--checkpoint-every must be at least 1".into(),
        ));
    }
    if let Some(r) = options.rate {
        if !(r > 0.0 && r.is_finite()) {
            return Err(WatchError::Options(format!(
                "--rate must be positive, was {r}"
            )));
        }
    }
    Ok(())
}

/// A checkpoint's state, refused (naming the file) when it is of another format version or
/// was made with other comparison options.
fn read_checkpoint(path: &Path, detector_options: Options) -> Result<State, WatchError> {
    let bad = |message: String| WatchError::BadCheckpoint {
        path: path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let version = serde_json::from_str::<Value>(&text)
        .ok()
        .and_then(|v| v.get("version").and_then(Value::as_u64));
    if version != Some(u64::from(CHECKPOINT_VERSION)) {
        return Err(bad(format!(
            "format version {}, this twin writes {CHECKPOINT_VERSION}",
            version.map_or("unknown".into(), |v| v.to_string())
        )));
    }
    let state: State = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    if state.options != detector_options {
        return Err(bad(format!(
            "made with other comparison options ({:?}) than these ({:?})",
            state.options, detector_options
        )));
    }
    Ok(state)
}

/// The twin's modes for `--track-modes` (its options checked first).
fn modes_to_track(
    twin: &Twin,
    track: &modes::TrackOptions,
) -> Result<crate::workflows::modal::TwinModes, WatchError> {
    track.validate().map_err(WatchError::Options)?;
    crate::workflows::modal::twin_modes(
        twin,
        &crate::workflows::modal::ModalOptions {
            samples: 0,
            ..Default::default()
        },
    )
    .map_err(|e| WatchError::Options(format!("the twin's modes: {e}")))
}

impl State {
    /// A new watch's state: nothing read yet.
    fn fresh(options: Options, excitation: Channel, channels: Vec<Channel>) -> Self {
        State {
            version: CHECKPOINT_VERSION,
            options,
            dt: None,
            lines: 0,
            samples: 0,
            last_time: None,
            segment_start: None,
            segment_count: 0,
            excitation,
            channels,
            header: None,
            noise_variance: None,
            reference: Welford::default(),
            held: Vec::new(),
            detector: None,
            bad_lines: 0,
            duplicates: 0,
            gaps: 0,
            missing_samples: 0,
            seq: 0,
            alerts: BTreeMap::new(),
            fmu: Vec::new(),
            fmu_last: None,
            background: background::Saved::default(),
            supervisor: None,
            adopted: Vec::new(),
        }
    }
}

/// Whether a line of an MQTT stream is a header (it starts with a letter, as a column name
/// does and a time does not).
fn is_header(line: &str) -> bool {
    line.trim_start()
        .starts_with(|c: char| c.is_ascii_alphabetic())
}

/// The excitation column of `structure`: `force` or `ground_acc`.
fn structure_excitation(structure: &::structure::Structure) -> Channel {
    Channel::Excitation(::structure::channel::ExcitationKind::of(
        &structure.excitation,
    ))
}

fn status(w: &Watcher<'_>, this_run: u64, started: Instant) -> Status {
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
