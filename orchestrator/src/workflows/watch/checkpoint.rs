//! The checkpoint: everything a restarted watcher needs to go on exactly (stream position,
//! comparison state, counters, the FMUs' serialised states), read back at the start (the
//! watcher saves it now and then); the noise reference's running sums.

use super::adopt::Adopted;
use super::online::{Detector, Options};
use super::stepper::{NodeState, Stepper};
use super::supervise::Supervisor;
use super::{background, WatchError};
use ::structure::channel::Channel;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// A checkpoint's format version (2: any channels).
pub(super) const CHECKPOINT_VERSION: u32 = 2;
/// Everything a restarted watcher needs to go on exactly.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct State {
    pub(super) version: u32,
    pub(super) options: Options,
    /// Nominal sampling interval, s (None before the second sample).
    pub(super) dt: Option<f64>,
    /// Data lines read (after the header), good or bad.
    pub(super) lines: u64,
    pub(super) samples: u64,
    pub(super) last_time: Option<f64>,
    /// The current segment's first time and its samples so far (its FMU clock).
    pub(super) segment_start: Option<f64>,
    pub(super) segment_count: u64,
    /// The stream's excitation and measured channels (its first header's).
    pub(super) excitation: Channel,
    pub(super) channels: Vec<Channel>,
    /// The last header line of an MQTT stream (a resumed watcher reads the broker's lines with
    /// it).
    pub(super) header: Option<String>,
    /// The band's noise variance per channel, once known.
    pub(super) noise_variance: Option<Vec<f64>>,
    /// The sums over the reference stretch for the channels the twin holds no noise variance
    /// for.
    pub(super) reference: Welford,
    /// Samples (time, measured, predicted) held until the detector can judge them: the
    /// stream's first until the second gives the sampling interval, and those before the
    /// noise variances are known.
    pub(super) held: Vec<(f64, Vec<f64>, Vec<f64>)>,
    pub(super) detector: Option<Detector>,
    pub(super) bad_lines: u64,
    #[serde(default)]
    pub(super) duplicates: u64,
    pub(super) gaps: u64,
    pub(super) missing_samples: u64,
    /// Alerts raised so far (their sequence numbers run on from here), by kind.
    pub(super) seq: u64,
    pub(super) alerts: BTreeMap<String, u64>,
    pub(super) fmu: Vec<NodeState>,
    pub(super) fmu_last: Option<(f64, f64)>,
    #[serde(default)]
    pub(super) background: background::Saved,
    #[serde(default)]
    pub(super) supervisor: Option<Supervisor>,
    /// The twins the watch adopted, in order: the last is live.
    #[serde(default)]
    pub(super) adopted: Vec<Adopted>,
}

impl State {
    /// A new watch's state: nothing read yet.
    pub(super) fn fresh(options: Options, excitation: Channel, channels: Vec<Channel>) -> Self {
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

/// Running mean and variance per channel (Welford), for the band's prior.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub(super) struct Welford {
    pub(super) n: u64,
    pub(super) mean: Vec<f64>,
    pub(super) m2: Vec<f64>,
}

impl Welford {
    pub(super) fn add(&mut self, values: &[f64]) {
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
    pub(super) fn variance(&self, c: usize) -> f64 {
        self.m2[c] / self.n as f64
    }
}

/// A checkpoint's state, refused (naming the file) when it is of another format version or
/// was made with other comparison options.
pub(super) fn read_checkpoint(path: &Path, detector_options: Options) -> Result<State, WatchError> {
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

/// The watch's state: the checkpoint's, its segment's FMU state restored in `stepper`, or a
/// fresh one.
pub(super) fn start_state(
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
