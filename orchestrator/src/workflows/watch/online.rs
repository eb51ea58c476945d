//! The comparison of `twin compare`, one sample at a time: the same out-of-band rule (±3σ and
//! the severity's centred moving RMS), the same grouping into windows and the same tolerance,
//! giving the same failing windows on a whole record. The severity looks half its window
//! ahead, so a sample is judged that many samples after it arrives; a segment's end (the
//! stream's end, or a gap) judges the rest with the window cut short, as the batch rule does at
//! a record's end.

use std::collections::VecDeque;

use ::structure::channel::Channel;
use serde::{Deserialize, Serialize};

use crate::evaluation::compare::{CompareOptions, FailingWindow};
use crate::evaluation::stats::nmse;

/// An out-of-band stretch being grown: what `compare` calls a group.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Group {
    start: f64,
    last: f64,
    outliers: usize,
    /// Per measured channel, whether it left the band.
    channels: Vec<bool>,
    /// Every sample from the first out-of-band one on, per channel.
    measured: Vec<Vec<f64>>,
    predicted: Vec<Vec<f64>>,
    /// How many of them run to the last out-of-band sample.
    through_last: usize,
    /// Whether a `failing` alert was raised for it.
    alerted: bool,
}

impl Group {
    fn nmse(&self, len: usize) -> Vec<f64> {
        (0..self.channels.len())
            .map(|c| nmse(&self.measured[c][..len], &self.predicted[c][..len]))
            .collect()
    }

    /// The positions of the channels that left the band.
    fn out(&self) -> Vec<usize> {
        (0..self.channels.len())
            .filter(|&c| self.channels[c])
            .collect()
    }
}

/// The names of the channels at `positions`, and their floors (each once, ascending), as
/// `compare`'s failing windows give them.
pub fn names_and_floors(channels: &[Channel], positions: &[usize]) -> (Vec<String>, Vec<usize>) {
    let names = positions.iter().map(|&c| channels[c].name()).collect();
    let mut floors: Vec<usize> = positions
        .iter()
        .map(|&c| match channels[c] {
            Channel::Response { floor, .. } => floor,
            _ => 0,
        })
        .collect();
    floors.sort_unstable();
    floors.dedup();
    (names, floors)
}

/// What the detector tells the stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A window has enough out-of-band samples and is above the tolerance so far.
    /// `channels`: the positions of those that left the band.
    Opened {
        start: f64,
        channels: Vec<usize>,
        nmse: Vec<f64>,
    },
    /// A window closed (no out-of-band sample within the merge gap after its last one).
    /// `failing`: whether it is a failing window by `compare`'s rule on its whole extent.
    Closed {
        window: FailingWindow,
        failing: bool,
        was_opened: bool,
    },
}

/// Running sums for an NMSE over everything after the transient (Welford's mean and variance),
/// per measured channel.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RunningNmse {
    n: Vec<u64>,
    mean: Vec<f64>,
    m2: Vec<f64>,
    sse: Vec<f64>,
}

impl RunningNmse {
    pub fn new(channels: usize) -> Self {
        RunningNmse {
            n: vec![0; channels],
            mean: vec![0.0; channels],
            m2: vec![0.0; channels],
            sse: vec![0.0; channels],
        }
    }

    fn add(&mut self, measured: &[f64], predicted: &[f64]) {
        for f in 0..self.n.len() {
            let y = measured[f];
            self.n[f] += 1;
            let d = y - self.mean[f];
            self.mean[f] += d / self.n[f] as f64;
            self.m2[f] += d * (y - self.mean[f]);
            self.sse[f] += (y - predicted[f]).powi(2);
        }
    }

    /// NMSE per channel (%); NaN before any sample.
    pub fn nmse(&self) -> Vec<f64> {
        (0..self.n.len())
            .map(|f| {
                if self.n[f] == 0 {
                    f64::NAN
                } else {
                    100.0 * self.sse[f] / self.m2[f]
                }
            })
            .collect()
    }
}

/// The state of one segment (from the stream's start or a gap to the next gap or the end).
///
/// The samples waiting for their severity window and the rolling window's samples are kept
/// flat, one record of fixed width per sample, so that a sample costs no allocation whatever
/// the number of channels.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Detector {
    options: Options,
    /// The measured channels, in the order of every per-channel vector here.
    channels: Vec<Channel>,
    noise_sd: Vec<f64>,
    /// Half the severity window, in samples.
    half: usize,
    start_time: Option<f64>,
    /// Samples in the segment so far, and the index of the first one not yet judged.
    count: usize,
    judged: usize,
    prefix: Vec<f64>,
    /// Per waiting sample: time, measured, predicted, and the severity's prefix sums of
    /// squared band-normalised residuals before and after it (1 + 4m values).
    pending: VecDeque<f64>,
    group: Option<Group>,
    /// The last `--window` seconds after the transient, for the rolling NMSE: time,
    /// measured, predicted (1 + 2m values a sample).
    rolling: VecDeque<f64>,
    /// NMSE over the stream after each segment's transient.
    pub overall: RunningNmse,
    /// Failing windows closed so far.
    pub failing_windows: u64,
    /// The sample being judged (scratch, not state).
    #[serde(skip)]
    scratch: Vec<f64>,
    #[serde(skip)]
    outside: Vec<bool>,
}

/// The comparison's rule (as `compare` takes it) and the rolling window's length.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Options {
    pub transient: f64,
    pub merge_gap: f64,
    pub min_outliers: usize,
    pub severity: f64,
    pub severity_window: f64,
    pub tolerance: f64,
    pub window: f64,
}

impl Options {
    pub fn new(compare: CompareOptions, window: f64) -> Self {
        Options {
            transient: compare.transient,
            merge_gap: compare.merge_gap,
            min_outliers: compare.min_outliers,
            severity: compare.severity,
            severity_window: compare.severity_window,
            tolerance: compare.tolerance,
            window,
        }
    }
}

impl Detector {
    /// `channels`: the measured channels; `noise_variance`: the band's, per channel; `dt`: the
    /// nominal sampling interval (s).
    pub fn new(options: Options, channels: Vec<Channel>, noise_variance: &[f64], dt: f64) -> Self {
        let m = channels.len();
        Detector {
            options,
            noise_sd: noise_variance.iter().map(|v| v.sqrt()).collect(),
            half: (options.severity_window / dt / 2.0).round() as usize,
            start_time: None,
            count: 0,
            judged: 0,
            prefix: vec![0.0; m],
            pending: VecDeque::new(),
            group: None,
            rolling: VecDeque::new(),
            overall: RunningNmse::new(m),
            failing_windows: 0,
            scratch: Vec::new(),
            outside: Vec::new(),
            channels,
        }
    }

    /// The measured channels, in the order of the NMSE vectors.
    pub fn channels(&self) -> &[Channel] {
        &self.channels
    }

    fn pending_width(&self) -> usize {
        1 + 4 * self.channels.len()
    }

    fn rolling_width(&self) -> usize {
        1 + 2 * self.channels.len()
    }

    /// Take one sample of the segment; events for the samples it lets the detector judge.
    pub fn push(&mut self, time: f64, measured: &[f64], predicted: &[f64]) -> Vec<Event> {
        let m = self.channels.len();
        let start = *self.start_time.get_or_insert(time);
        self.pending.push_back(time);
        self.pending.extend(&measured[..m]);
        self.pending.extend(&predicted[..m]);
        self.pending.extend(&self.prefix);
        for f in 0..m {
            let u = (measured[f] - predicted[f]) / self.noise_sd[f];
            self.prefix[f] += if u.is_finite() { u * u } else { f64::MAX / 4.0 };
        }
        self.pending.extend(&self.prefix);
        self.count += 1;
        if time - start >= self.options.transient {
            self.overall.add(measured, predicted);
            self.rolling.push_back(time);
            self.rolling.extend(&measured[..m]);
            self.rolling.extend(&predicted[..m]);
            let width = self.rolling_width();
            while let Some(&t) = self.rolling.front() {
                if time - t >= self.options.window {
                    self.rolling.drain(..width);
                } else {
                    break;
                }
            }
        }
        let mut events = Vec::new();
        while self.judged + self.half < self.count {
            self.judge(&mut events);
        }
        events
    }

    /// End the segment: judge what is left with the severity window cut short, close the open
    /// window. The next sample starts a new segment (with its own transient).
    pub fn finish_segment(&mut self) -> Vec<Event> {
        let mut events = Vec::new();
        while self.judged < self.count {
            self.judge(&mut events);
        }
        if let Some(group) = self.group.take() {
            events.push(self.close(group));
        }
        self.start_time = None;
        self.count = 0;
        self.judged = 0;
        self.prefix.iter_mut().for_each(|p| *p = 0.0);
        self.pending.clear();
        self.rolling.clear();
        events
    }

    /// Whether a failing window is open (announced, not yet closed).
    pub fn window_open(&self) -> bool {
        self.group.as_ref().is_some_and(|g| g.alerted)
    }

    /// NMSE per channel over the last `--window` seconds after the transient (NaN: no
    /// samples).
    pub fn rolling_nmse(&self) -> Vec<f64> {
        let m = self.channels.len();
        let width = self.rolling_width();
        let samples = self.rolling.len() / width;
        (0..m)
            .map(|f| {
                let y: Vec<f64> = (0..samples)
                    .map(|k| self.rolling[k * width + 1 + f])
                    .collect();
                let p: Vec<f64> = (0..samples)
                    .map(|k| self.rolling[k * width + 1 + m + f])
                    .collect();
                nmse(&y, &p)
            })
            .collect()
    }

    /// Judge sample `self.judged` (the oldest pending), as `compare` does.
    fn judge(&mut self, events: &mut Vec<Event>) {
        let m = self.channels.len();
        let width = self.pending_width();
        let k = self.judged;
        let first_pending = self.count - self.pending.len() / width;
        let at = |i: usize| (i - first_pending) * width;
        let a = k.saturating_sub(self.half);
        let b = (k + self.half + 1).min(self.count);
        let (entry, from, to) = (at(k), at(a), at(b - 1));
        let time = self.pending[entry];
        // The sample's measured and predicted values, and which channels left the band.
        self.scratch.clear();
        self.outside.clear();
        for f in 0..2 * m {
            self.scratch.push(self.pending[entry + 1 + f]);
        }
        for f in 0..m {
            let before = self.pending[from + 1 + 2 * m + f];
            let after = self.pending[to + 1 + 3 * m + f];
            let severe = ((after - before) / (b - a) as f64).sqrt() >= self.options.severity;
            let residual = (self.scratch[f] - self.scratch[m + f]).abs();
            self.outside
                .push(residual > 3.0 * self.noise_sd[f] && severe);
        }
        self.judged += 1;
        // Keep what later samples' severity windows still reach back to.
        let keep_from = self.judged.saturating_sub(self.half);
        let first_pending = self.count - self.pending.len() / width;
        if first_pending < keep_from {
            let done = (keep_from - first_pending).min(self.pending.len() / width);
            self.pending.drain(..done * width);
        }
        let start = self.start_time.unwrap_or(time);
        if time - start < self.options.transient {
            return;
        }
        let out = self.outside.iter().any(|&o| o);
        if let Some(group) = &self.group {
            if time - group.last > self.options.merge_gap {
                let group = self.group.take().expect("an open group");
                events.push(self.close(group));
            }
        }
        let (measured, predicted) = self.scratch.split_at(m);
        match (&mut self.group, out) {
            (Some(group), _) => {
                for f in 0..m {
                    group.measured[f].push(measured[f]);
                    group.predicted[f].push(predicted[f]);
                }
                if out {
                    group.last = time;
                    group.outliers += 1;
                    group.through_last = group.measured[0].len();
                    for f in 0..m {
                        group.channels[f] |= self.outside[f];
                    }
                }
            }
            (None, true) => {
                self.group = Some(Group {
                    start: time,
                    last: time,
                    outliers: 1,
                    channels: self.outside.clone(),
                    measured: measured.iter().map(|&v| vec![v]).collect(),
                    predicted: predicted.iter().map(|&v| vec![v]).collect(),
                    through_last: 1,
                    alerted: false,
                });
            }
            (None, false) => {}
        }
        if !out {
            return;
        }
        let options = self.options;
        if let Some(group) = &mut self.group {
            // Checked while it grows (not at every sample of a long one: the final word is
            // the close's, on the whole window).
            let n = group.outliers;
            if !group.alerted && n >= options.min_outliers && (n <= 64 || n % 32 == 0) {
                let nmse = group.nmse(group.through_last);
                if passes(group, &nmse, options.tolerance) {
                    group.alerted = true;
                    events.push(Event::Opened {
                        start: group.start,
                        channels: group.out(),
                        nmse,
                    });
                }
            }
        }
    }

    fn close(&mut self, group: Group) -> Event {
        let nmse = group.nmse(group.through_last);
        let failing = group.outliers >= self.options.min_outliers
            && passes(&group, &nmse, self.options.tolerance);
        if failing {
            self.failing_windows += 1;
        }
        let (channels, floors) = names_and_floors(&self.channels, &group.out());
        Event::Closed {
            window: FailingWindow {
                start: group.start,
                end: group.last,
                channels,
                floors,
                nmse,
            },
            failing,
            was_opened: group.alerted,
        }
    }
}

/// `compare`'s tolerance: some channel that left the band has an NMSE not below it.
fn passes(group: &Group, nmse: &[f64], tolerance: f64) -> bool {
    (0..group.channels.len()).any(|f| group.channels[f] && !(nmse[f] < tolerance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::compare::compare;

    /// The online detector gives `compare`'s windows on the unit tests' records.
    #[test]
    fn the_online_windows_are_compare_s() {
        let dt = 0.01;
        let time: Vec<f64> = (0..1000).map(|k| k as f64 * dt).collect();
        let base: Vec<f64> = time.iter().map(|t| (7.0 * t).sin()).collect();
        let predicted = [base.clone(), base.clone(), base.clone()];
        let mut measured = predicted.clone();
        for k in 500..=510 {
            measured[2][k] += 2.0;
        }
        for k in 530..=540 {
            measured[2][k] -= 2.0;
        }
        for k in 800..=805 {
            measured[0][k] += 2.0;
        }
        for k in 990..1000 {
            measured[1][k] += 0.3 * if k % 2 == 0 { 1.0 } else { -1.0 };
        }
        measured[1][300] += 2.0;
        for tolerance in [0.0, 50.0] {
            let options = CompareOptions {
                tolerance,
                ..CompareOptions::default()
            };
            let accs: Vec<::structure::channel::Channel> = (1..=3)
                .map(|f| ::structure::channel::Channel::parse(&format!("acc{f}")).expect("acc"))
                .collect();
            let batch = compare(
                &time, &accs, &measured, &predicted, &[0.01; 3], None, options,
            );
            let mut d = Detector::new(Options::new(options, 2.0), accs.clone(), &[0.01; 3], dt);
            let mut events = Vec::new();
            for k in 0..time.len() {
                events.extend(d.push(
                    time[k],
                    &[0, 1, 2].map(|f| measured[f][k]),
                    &[0, 1, 2].map(|f| predicted[f][k]),
                ));
            }
            events.extend(d.finish_segment());
            let online: Vec<FailingWindow> = events
                .into_iter()
                .filter_map(|e| match e {
                    Event::Closed {
                        window,
                        failing: true,
                        ..
                    } => Some(window),
                    _ => None,
                })
                .collect();
            assert_eq!(online, batch.failing_windows, "tolerance {tolerance}");
            assert!(!online.is_empty());
            let overall = d.overall.nmse();
            for f in 0..3 {
                assert!((overall[f] - batch.nmse[f]).abs() <= 1e-9 * batch.nmse[f].abs().max(1e-9));
            }
        }
    }

    /// Any channel set: a velocity and an acceleration of other floors (another quantity, its
    /// own band), in the record's order — the online windows, their channels and floors are
    /// `compare`'s.
    #[test]
    fn the_online_windows_are_compare_s_on_any_channels() {
        let dt = 0.005;
        let time: Vec<f64> = (0..2000).map(|k| k as f64 * dt).collect();
        let channels: Vec<Channel> = ["vel4", "acc2"]
            .iter()
            .map(|n| Channel::parse(n).expect("a channel"))
            .collect();
        let predicted: Vec<Vec<f64>> = vec![
            time.iter().map(|t| 0.01 * (3.0 * t).sin()).collect(),
            time.iter().map(|t| (5.0 * t).cos()).collect(),
        ];
        let mut measured = predicted.clone();
        // The velocity leaves its band (sd 1e-4) at 4.0–4.1 s, the acceleration (sd 0.01) at
        // 7.0–7.2 s, both at 8.5–8.6 s.
        for (c, from, to, offset) in [
            (0, 800, 820, 3e-3),
            (1, 1400, 1440, 0.5),
            (0, 1700, 1720, -3e-3),
            (1, 1700, 1720, 0.5),
        ] {
            for v in &mut measured[c][from..=to] {
                *v += offset;
            }
        }
        let noise = [1e-8, 1e-4];
        let options = CompareOptions::default();
        let batch = compare(
            &time, &channels, &measured, &predicted, &noise, None, options,
        );
        let mut d = Detector::new(Options::new(options, 2.0), channels.clone(), &noise, dt);
        let mut events = Vec::new();
        for k in 0..time.len() {
            events.extend(d.push(
                time[k],
                &[measured[0][k], measured[1][k]],
                &[predicted[0][k], predicted[1][k]],
            ));
        }
        events.extend(d.finish_segment());
        let online: Vec<FailingWindow> = events
            .into_iter()
            .filter_map(|e| match e {
                Event::Closed {
                    window,
                    failing: true,
                    ..
                } => Some(window),
                _ => None,
            })
            .collect();
        assert_eq!(online, batch.failing_windows);
        assert_eq!(online.len(), 3, "{online:?}");
        assert_eq!(online[0].channels, ["vel4"]);
        assert_eq!(online[1].channels, ["acc2"]);
        assert_eq!(online[2].channels, ["vel4", "acc2"]);
        assert_eq!(online[2].floors, [2, 4]);
    }
}
