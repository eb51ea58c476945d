//! Frequency tracking in operation: the modes identified on a sliding window of the stream
//! (SSI-COV's, output-only: in operation the excitation is whatever the structure meets) and
//! set against the twin's modes and their band. A window is identified as `twin modal`
//! identifies a record ([`identify_window`]): the same selection and screens, with the
//! stream's excitation where it varies (a pole at the force's band edge or its own spectral
//! peak set aside, not tracked as a mode). Every `every` seconds of stream time the last
//! `window` seconds of every response channel are identified; each identified mode is paired
//! with the twin's, and a twin mode whose tracked frequency stays outside its band for
//! `persistence` identifications in a row is reported once as having left it (and again only
//! after it came back). The band of a mode: `sigmas` times the combined sd of the twin's
//! frequency (its posterior) and the identified one (the scatter over the stabilisation
//! diagram's orders), and never narrower than `tolerance` % of the twin's frequency: a window
//! of a minute identifies a frequency to a few tenths of a per cent, and a band that ignored
//! that would cry wolf.
//!
//! The buffer is not checkpointed: a resumed watch fills its first window anew.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::record::Signal;
use crate::workflows::modal::{
    identify_window, pair_modes, IdentifyOptions, ModeComparison, ObservedMode, TwinModes,
};
use ::structure::channel::{Channel, Quantity};
use numerics::modal::stabilisation::IdentifiedMode;

/// `twin watch --track-modes`: the sliding window and the band.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOptions {
    /// Seconds of stream identified each time.
    pub window: f64,
    /// Seconds of stream between identifications.
    pub every: f64,
    /// The band's half-width in combined sds …
    pub sigmas: f64,
    /// … and at least this, % of the twin's frequency.
    pub tolerance: f64,
    /// Identifications in a row outside the band before a `frequency` alert.
    pub persistence: usize,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            window: 60.0,
            every: 10.0,
            sigmas: 3.0,
            tolerance: 1.5,
            persistence: 2,
        }
    }
}

impl TrackOptions {
    pub fn validate(&self) -> Result<(), String> {
        let positive = |what: &str, v: f64| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(format!("{what} must be a positive number, was {v}"))
            }
        };
        positive("--modes-window", self.window)?;
        positive("--modes-every", self.every)?;
        positive("the band's sds", self.sigmas)?;
        positive("--modes-tolerance", self.tolerance)?;
        if self.persistence == 0 {
            return Err("the persistence must be at least 1 identification".into());
        }
        Ok(())
    }
}

/// One twin mode at one identification.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrackedMode {
    pub mode: usize,
    pub twin_frequency: f64,
    /// None: no identified mode paired with it in this window.
    pub frequency: Option<f64>,
    pub frequency_sd: Option<f64>,
    pub damping: Option<f64>,
    pub shift_percent: Option<f64>,
    pub shift_sd: Option<f64>,
    /// The band's half-width here, Hz.
    pub band: f64,
    pub outside: bool,
}

/// What an identification found (a `modes` alert's body).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Tracked {
    /// Stream time at the window's end.
    pub time: f64,
    pub window: f64,
    pub modes: Vec<TrackedMode>,
    /// Twin modes that left their band at this identification (persistently).
    pub left: Vec<usize>,
    /// Twin modes back inside.
    pub returned: Vec<usize>,
}

pub struct Tracker {
    options: TrackOptions,
    twin: TwinModes,
    channels: Vec<Channel>,
    buffers: Vec<VecDeque<f64>>,
    /// The stream's excitation (force or ground acceleration) over the window.
    excitation: (Channel, VecDeque<f64>),
    capacity: usize,
    every: usize,
    since: usize,
    dt: f64,
    outside_runs: Vec<usize>,
    reported: Vec<bool>,
    identify: IdentifyOptions,
}

impl Tracker {
    /// A tracker of `channels` and the `excitation` sampled every `dt` s against `twin`'s modes.
    pub fn new(
        options: TrackOptions,
        twin: TwinModes,
        channels: Vec<Channel>,
        excitation: Channel,
        dt: f64,
    ) -> Tracker {
        let capacity = (options.window / dt).round().max(1.0) as usize;
        let every = (options.every / dt).round().max(1.0) as usize;
        let n = twin.modes.len();
        Tracker {
            options,
            buffers: vec![VecDeque::with_capacity(capacity); channels.len()],
            excitation: (excitation, VecDeque::with_capacity(capacity)),
            channels,
            capacity,
            every,
            since: 0,
            dt,
            outside_runs: vec![0; n],
            reported: vec![false; n],
            // SSI-COV alone (no FRF fit), to four poles a twin mode.
            identify: IdentifyOptions {
                max_order: (4 * n).max(20),
                input_output: false,
                ..IdentifyOptions::default()
            },
            twin,
        }
    }

    /// A gap in the stream: the window starts anew.
    pub fn gap(&mut self) {
        for b in &mut self.buffers {
            b.clear();
        }
        self.excitation.1.clear();
        self.since = 0;
    }

    /// One sample of the excitation and every channel; an identification when one is due and
    /// the window is full.
    pub fn push(
        &mut self,
        time: f64,
        excitation: f64,
        values: &[f64],
    ) -> Option<Result<Tracked, String>> {
        if !excitation.is_finite() || values.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let buffers = self.buffers.iter_mut().chain([&mut self.excitation.1]);
        for (b, &v) in buffers.zip(values.iter().chain([&excitation])) {
            if b.len() == self.capacity {
                b.pop_front();
            }
            b.push_back(v);
        }
        self.since += 1;
        let full = self
            .buffers
            .first()
            .is_some_and(|b| b.len() == self.capacity);
        if !full || self.since < self.every {
            return None;
        }
        self.since = 0;
        Some(self.identify(time))
    }

    fn identify(&mut self, time: f64) -> Result<Tracked, String> {
        // Each channel scaled to unit variance (acceleration, velocity and displacement
        // channels side by side), the shapes scaled back afterwards.
        let mut scales = Vec::with_capacity(self.buffers.len());
        let responses: Vec<Signal> = self
            .buffers
            .iter()
            .zip(&self.channels)
            .map(|(b, channel)| {
                let n = b.len() as f64;
                let mean = b.iter().sum::<f64>() / n;
                let sd = (b.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
                let sd = if sd > 0.0 { sd } else { 1.0 };
                scales.push(sd);
                Signal {
                    channel: *channel,
                    unit: channel.quantity().si(),
                    values: b.iter().map(|v| (v - mean) / sd).collect(),
                }
            })
            .collect();
        let (channel, values) = &self.excitation;
        let excitation = Signal {
            channel: *channel,
            unit: channel.quantity().si(),
            values: values.iter().copied().collect(),
        };
        let found = identify_window(self.dt, Some(&excitation), &responses, &self.identify)
            .map_err(|e| e.to_string())?;
        let identified: Vec<IdentifiedMode> =
            found.modes.into_iter().map(|m| m.identified).collect();
        let comparison = self.compare(&identified, &scales);
        Ok(self.judge(time, &identified, &comparison))
    }

    /// The identified modes paired with the twin's, by shape at the floors the acceleration
    /// channels measure when there are two or more of them, else by frequency.
    fn compare(&self, identified: &[IdentifiedMode], scales: &[f64]) -> ModeComparison {
        let acc: Vec<usize> = (0..self.channels.len())
            .filter(|&c| self.channels[c].quantity() == Quantity::Acceleration)
            .collect();
        let floors: Vec<usize> = acc
            .iter()
            .filter_map(|&c| match self.channels[c] {
                Channel::Response { floor, .. } => Some(floor),
                _ => None,
            })
            .collect();
        let observed: Vec<ObservedMode> = identified
            .iter()
            .map(|m| ObservedMode {
                frequency: m.frequency,
                frequency_sd: Some(m.frequency_sd),
                damping: m.damping,
                damping_sd: Some(m.damping_sd),
                shape: acc.iter().map(|&c| m.shape[c] * scales[c]).collect(),
            })
            .collect();
        pair_modes(&self.twin, &observed, &floors)
    }

    fn judge(
        &mut self,
        time: f64,
        identified: &[IdentifiedMode],
        comparison: &ModeComparison,
    ) -> Tracked {
        let mut modes = Vec::with_capacity(self.twin.modes.len());
        let (mut left, mut returned) = (Vec::new(), Vec::new());
        for (i, t) in self.twin.modes.iter().enumerate() {
            let pair = comparison.pairs.iter().find(|p| p.twin_mode == i + 1);
            let id = pair.map(|p| &identified[p.observed_mode - 1]);
            let band = crate::workflows::modal::ModalBand {
                sigmas: self.options.sigmas,
                tolerance: self.options.tolerance,
            }
            .half_width(t.frequency, t.frequency_sd, id.map(|m| m.frequency_sd));
            let outside = id.is_some_and(|m| (m.frequency - t.frequency).abs() > band);
            if outside {
                self.outside_runs[i] += 1;
                if self.outside_runs[i] >= self.options.persistence && !self.reported[i] {
                    self.reported[i] = true;
                    left.push(i + 1);
                }
            } else if id.is_some() {
                self.outside_runs[i] = 0;
                if self.reported[i] {
                    self.reported[i] = false;
                    returned.push(i + 1);
                }
            }
            modes.push(TrackedMode {
                mode: i + 1,
                twin_frequency: t.frequency,
                frequency: id.map(|m| m.frequency),
                frequency_sd: id.map(|m| m.frequency_sd),
                damping: id.map(|m| m.damping),
                shift_percent: pair.map(|p| p.frequency_shift_percent),
                shift_sd: pair.and_then(|p| p.frequency_shift_sd),
                band,
                outside,
            });
        }
        Tracked {
            time,
            window: self.options.window,
            modes,
            left,
            returned,
        }
    }
}

/// The `modes` alerts of an alerts file (JSON lines), in order; other kinds are skipped, and a
/// line that is not JSON is an error naming the file and line.
pub fn read_tracked(path: &std::path::Path) -> Result<Vec<Tracked>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let value: serde_json::Value =
            serde_json::from_str(line).map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?;
        if value.get("kind").and_then(|k| k.as_str()) == Some("modes") {
            out.push(
                serde_json::from_value(value)
                    .map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?,
            );
        }
    }
    Ok(out)
}
