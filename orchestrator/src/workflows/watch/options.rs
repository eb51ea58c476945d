//! `twin watch`'s options: where the stream comes from, the window, the checkpoint and the
//! background diagnosis, checked before any work.

use super::background::DiagnosisOptions;
use super::mqtt::MqttUrl;
use super::supervise::LearnOptions;
use super::{background, modes, WatchError};
use crate::record::ColumnMap;
use std::path::PathBuf;
use std::time::Duration;

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

/// A time step above this × the nominal one is a gap.
pub const GAP_FACTOR: f64 = 1.5;
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

/// The options `watch_observed` checks itself: the window, the checkpoint interval, the rate.
pub(super) fn check_options(options: &WatchOptions) -> Result<(), WatchError> {
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
