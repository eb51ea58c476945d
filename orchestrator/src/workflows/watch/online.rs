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
    /// `change`: where the residual's variance changed, located in the samples before
    /// ([`locate_change`]).
    Opened {
        start: f64,
        channels: Vec<usize>,
        nmse: Vec<f64>,
        change: Option<ChangePoint>,
    },
    /// A window closed: the residual stayed in its band for the merge gap after its last
    /// out-of-band sample, or (`cut`) the segment ended (the stream's end, a gap) while it was
    /// open — that is no return to the band.
    /// `failing`: whether it is a failing window by `compare`'s rule on its whole extent.
    Closed {
        window: FailingWindow,
        failing: bool,
        was_opened: bool,
        cut: bool,
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
    /// The last [`CHANGE_LOOKBACK`] seconds after the transient for the change's location:
    /// time and each channel's squared band-normalised residual (1 + m values a sample).
    #[serde(default)]
    recent: VecDeque<f64>,
    /// The last closed window's end: a change is looked for after it.
    #[serde(default)]
    search_from: Option<f64>,
}

/// Seconds of residuals kept to locate a change in when a window opens.
pub const CHANGE_LOOKBACK: f64 = 30.0;
/// Samples each side of a candidate change time at least.
const CHANGE_MIN_SIDE: usize = 8;
/// The least log-likelihood ratio (per unit of the correlation's inflation) of a located
/// change: white residuals without a step give a few units (the largest of many correlated
/// splits' χ²₁/2), a storey's 10 % stiffness loss hundreds.
const CHANGE_MIN_LLR: f64 = 10.0;
/// Half the 95 % quantile of χ² with one degree of freedom: the drop of the log-likelihood
/// ratio that bounds the change time's interval (before the correlation's inflation).
const HALF_CHI2_95: f64 = 1.92;

/// Where the residual's variance changed: the generalised likelihood ratio of a variance
/// step in the band-normalised residuals, maximised over the step's time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChangePoint {
    /// The first sample after the step (s of the stream).
    pub time: f64,
    /// The times whose log-likelihood ratio is within the interval's drop of the largest
    /// (an approximate 95 % interval, widened by the residuals' correlation).
    pub low: f64,
    pub high: f64,
    /// The largest log-likelihood ratio (summed over the channels).
    pub log_likelihood_ratio: f64,
    /// The residual's variance after the step over that before, per channel.
    pub variance_ratio: Vec<f64>,
    /// The drop's inflation for the correlated residuals (1: independent samples).
    pub inflation: f64,
}

/// Locate a variance step in `u2` (per sample, `m` channels' squared band-normalised
/// residuals, flat) at the times `time`: for each candidate split `j` (at least
/// [`CHANGE_MIN_SIDE`] samples each side) the log-likelihood ratio of Gaussian residuals with
/// one variance before and another after against one throughout, summed over the channels,
/// `½ Σ_c [n ln(S/n) − j ln(S₀/j) − (n−j) ln(S₁/(n−j))]`. Its interval: the splits within
/// `1.92 κ` of the largest, κ = 1 + 2 Σ ρ_k, the lag correlations of the after-step squared
/// residuals (summed over channels) up to the first that is not positive — correlated
/// samples carry less evidence than their number. None with too few samples, or when the
/// largest ratio is below [`CHANGE_MIN_LLR`] κ.
pub fn locate_change(time: &[f64], u2: &[f64], m: usize) -> Option<ChangePoint> {
    let n = time.len();
    if m == 0 || n < 2 * CHANGE_MIN_SIDE || u2.len() != n * m {
        return None;
    }
    let floor = 1e-300;
    let mut prefix = vec![0.0; (n + 1) * m];
    for k in 0..n {
        for c in 0..m {
            prefix[(k + 1) * m + c] = prefix[k * m + c] + u2[k * m + c];
        }
    }
    let xlnx = |count: usize, sum: f64| {
        let count = count as f64;
        count * (sum.max(floor) / count).ln()
    };
    let llr = |j: usize| -> f64 {
        (0..m)
            .map(|c| {
                let total = prefix[n * m + c];
                let before = prefix[j * m + c];
                0.5 * (xlnx(n, total) - xlnx(j, before) - xlnx(n - j, total - before))
            })
            .sum()
    };
    let splits = CHANGE_MIN_SIDE..=n - CHANGE_MIN_SIDE;
    let values: Vec<(usize, f64)> = splits.map(|j| (j, llr(j))).collect();
    let &(best, largest) = values
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|v| v.1.is_finite())?;
    // The after-step residuals' correlation.
    let after: Vec<f64> = (best..n)
        .map(|k| (0..m).map(|c| u2[k * m + c]).sum())
        .collect();
    let mean = after.iter().sum::<f64>() / after.len() as f64;
    let centred: Vec<f64> = after.iter().map(|x| x - mean).collect();
    let var: f64 = centred.iter().map(|x| x * x).sum();
    let mut inflation = 1.0;
    if var > 0.0 {
        for lag in 1..centred.len() / 2 {
            let rho: f64 = centred[lag..]
                .iter()
                .zip(&centred)
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / var;
            if rho <= 0.0 {
                break;
            }
            inflation += 2.0 * rho;
        }
    }
    if largest < CHANGE_MIN_LLR * inflation {
        // No step stands out of chance's.
        return None;
    }
    let drop = HALF_CHI2_95 * inflation;
    let within: Vec<usize> = values
        .iter()
        .filter(|v| v.1 >= largest - drop)
        .map(|v| v.0)
        .collect();
    let (lo, hi) = (within[0], within[within.len() - 1]);
    let variance_ratio = (0..m)
        .map(|c| {
            let before = prefix[best * m + c] / best as f64;
            let after = (prefix[n * m + c] - prefix[best * m + c]) / (n - best) as f64;
            after / before.max(floor)
        })
        .collect();
    Some(ChangePoint {
        time: time[best],
        low: time[lo],
        high: time[hi],
        log_likelihood_ratio: largest,
        variance_ratio,
        inflation,
    })
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
            recent: VecDeque::new(),
            search_from: None,
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
        let after_transient = time - start >= self.options.transient;
        if after_transient {
            self.recent.push_back(time);
        }
        for f in 0..m {
            let u = (measured[f] - predicted[f]) / self.noise_sd[f];
            self.prefix[f] += if u.is_finite() { u * u } else { f64::MAX / 4.0 };
            if after_transient {
                self.recent.push_back(if u.is_finite() {
                    (u * u).min(1e12)
                } else {
                    1e12
                });
            }
        }
        while self
            .recent
            .front()
            .is_some_and(|&t| time - t > CHANGE_LOOKBACK)
        {
            self.recent.drain(..1 + m);
        }
        self.pending.extend(&self.prefix);
        self.count += 1;
        if after_transient {
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
            events.push(self.close(group, true));
        }
        self.recent.clear();
        self.search_from = None;
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
                events.push(self.close(group, false));
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
        let mut opened = None;
        if let Some(group) = &mut self.group {
            // Checked while it grows (not at every sample of a long one: the final word is
            // the close's, on the whole window).
            let n = group.outliers;
            if !group.alerted && n >= options.min_outliers && (n <= 64 || n % 32 == 0) {
                let nmse = group.nmse(group.through_last);
                if passes(group, &nmse, options.tolerance) {
                    group.alerted = true;
                    opened = Some((group.start, group.out(), nmse));
                }
            }
        }
        if let Some((start, channels, nmse)) = opened {
            let change = self.locate();
            events.push(Event::Opened {
                start,
                channels,
                nmse,
                change,
            });
        }
    }

    /// The change behind the window opening now: located in the residuals kept since the
    /// last closed window (at most [`CHANGE_LOOKBACK`] s), up to the newest sample.
    pub fn locate(&self) -> Option<ChangePoint> {
        let m = self.channels.len();
        let width = 1 + m;
        let samples = self.recent.len() / width;
        let from = self.search_from.unwrap_or(f64::NEG_INFINITY);
        let first = (0..samples)
            .find(|&k| self.recent[k * width] > from)
            .unwrap_or(samples);
        let mut time = Vec::with_capacity(samples - first);
        let mut u2 = Vec::with_capacity((samples - first) * m);
        for k in first..samples {
            time.push(self.recent[k * width]);
            u2.extend(self.recent.range(k * width + 1..(k + 1) * width));
        }
        locate_change(&time, &u2, m)
    }

    fn close(&mut self, group: Group, cut: bool) -> Event {
        self.search_from = Some(group.last);
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
            cut,
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

    /// A variance step in white residuals is located within a few samples, inside its interval;
    /// without a step the largest ratio stays small and the interval is wide.
    #[test]
    fn a_variance_step_is_located_with_its_interval() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (n, m, step) = (1000, 2, 613);
        let time: Vec<f64> = (0..n).map(|k| k as f64 * 0.02).collect();
        let mut stepped = Vec::new();
        let mut flat = Vec::new();
        for k in 0..n {
            for c in 0..m {
                let z: f64 = StandardNormal.sample(&mut rng);
                // Channel 0's sd ×2 after the step, channel 1 unchanged.
                let sd = if k >= step && c == 0 { 2.0 } else { 1.0 };
                stepped.push((sd * z).powi(2));
                flat.push(z * z);
            }
        }
        let found = locate_change(&time, &stepped, m).expect("a change");
        assert!((found.time - time[step]).abs() <= 10.0 * 0.02, "{found:?}");
        assert!(
            found.low <= time[step] && time[step] <= found.high,
            "{found:?}"
        );
        assert!(found.high - found.low < 2.0, "{found:?}");
        assert!((found.variance_ratio[0] - 4.0).abs() < 1.0, "{found:?}");
        assert!((found.variance_ratio[1] - 1.0).abs() < 0.3, "{found:?}");
        // No step: none stands out of chance's (the ratio a few units), the step's is far above.
        assert_eq!(locate_change(&time, &flat, m), None);
        assert!(found.log_likelihood_ratio > 100.0, "{found:?}");
        assert!(locate_change(&time[..10], &stepped[..20], m).is_none());
    }
}
