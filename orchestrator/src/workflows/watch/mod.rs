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

// The watch's own files in layers: data and rules (adopt, alerts, checkpoint, observe, options,
// stream) below the watcher that uses them, the run over the stream on top.
mod adopt;
mod alerts;
mod checkpoint;
mod observe;
mod options;
mod run;
mod stream;
mod watcher;

use std::path::PathBuf;

use ::structure::channel::Channel;
use serde_json::Value;

use crate::cosim::import::ImportError;
use crate::evaluation::compare::CompareOptions;
use crate::fsutil::WriteError;
pub use crate::record::nominal_step;
use crate::twin::run::Tolerance;
use crate::twin::{Twin, TwinError};
use online::Options;
use supervise::Supervisor;

pub use adopt::Adopted;
use alerts::Alerts;
use checkpoint::{read_checkpoint, start_state};
pub use observe::{LearningSummary, LiveState, Observer, Point, Status, Summary};
use options::check_options;
pub use options::{
    StreamSource, WatchOptions, CHECKPOINT_EVERY, FILE_IDLE, GAP_FACTOR, NOISE_REFERENCE, WINDOW,
};
use run::{end, read_stream};
use stream::{opening, stream_header, LineReader, Opening, Stream};
use watcher::{background_of, modes_to_track, open_stepper, Watcher};

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
