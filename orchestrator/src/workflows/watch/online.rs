//! The comparison of `twin compare`, one sample at a time: the same out-of-band rule (±3σ and
//! the severity's centred moving RMS), the same grouping into windows and the same tolerance,
//! giving the same failing windows on a whole record. The severity looks half its window
//! ahead, so a sample is judged that many samples after it arrives; a segment's end (the
//! stream's end, or a gap) judges the rest with the window cut short, as the batch rule does at
//! a record's end.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::evaluation::compare::{CompareOptions, FailingWindow};
use crate::evaluation::stats::nmse;

/// One sample waiting for its severity window to fill.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Entry {
    time: f64,
    measured: [f64; 3],
    predicted: [f64; 3],
    /// The severity's prefix sums of squared band-normalised residuals before this sample …
    before: [f64; 3],
    /// … and after it.
    after: [f64; 3],
}

/// An out-of-band stretch being grown: what `compare` calls a group.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Group {
    start: f64,
    last: f64,
    outliers: usize,
    floors: [bool; 3],
    /// Every sample from the first out-of-band one on, per floor.
    measured: [Vec<f64>; 3],
    predicted: [Vec<f64>; 3],
    /// How many of them run to the last out-of-band sample.
    through_last: usize,
    /// Whether a `failing` alert was raised for it.
    alerted: bool,
}

impl Group {
    fn nmse(&self, len: usize) -> [f64; 3] {
        [0, 1, 2].map(|f| nmse(&self.measured[f][..len], &self.predicted[f][..len]))
    }

    fn floors(&self) -> Vec<usize> {
        (0..3).filter(|&f| self.floors[f]).map(|f| f + 1).collect()
    }
}

/// What the detector tells the stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A window has enough out-of-band samples and is above the tolerance so far.
    Opened {
        start: f64,
        floors: Vec<usize>,
        nmse: [f64; 3],
    },
    /// A window closed (no out-of-band sample within the merge gap after its last one).
    /// `failing`: whether it is a failing window by `compare`'s rule on its whole extent.
    Closed {
        window: FailingWindow,
        failing: bool,
        was_opened: bool,
    },
}

/// Running sums for an NMSE over everything after the transient (Welford's mean and variance).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RunningNmse {
    n: [u64; 3],
    mean: [f64; 3],
    m2: [f64; 3],
    sse: [f64; 3],
}

impl RunningNmse {
    fn add(&mut self, measured: [f64; 3], predicted: [f64; 3]) {
        for f in 0..3 {
            let y = measured[f];
            self.n[f] += 1;
            let d = y - self.mean[f];
            self.mean[f] += d / self.n[f] as f64;
            self.m2[f] += d * (y - self.mean[f]);
            self.sse[f] += (y - predicted[f]).powi(2);
        }
    }

    /// NMSE per floor (%); NaN before any sample.
    pub fn nmse(&self) -> [f64; 3] {
        [0, 1, 2].map(|f| {
            if self.n[f] == 0 {
                f64::NAN
            } else {
                100.0 * self.sse[f] / self.m2[f]
            }
        })
    }
}

/// The state of one segment (from the stream's start or a gap to the next gap or the end).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Detector {
    options: Options,
    noise_sd: [f64; 3],
    /// Half the severity window, in samples.
    half: usize,
    start_time: Option<f64>,
    /// Samples in the segment so far, and the index of the first one not yet judged.
    count: usize,
    judged: usize,
    prefix: [f64; 3],
    pending: VecDeque<Entry>,
    group: Option<Group>,
    /// The last `--window` seconds after the transient, for the rolling NMSE.
    rolling: VecDeque<(f64, [f64; 3], [f64; 3])>,
    /// NMSE over the stream after each segment's transient.
    pub overall: RunningNmse,
    /// Failing windows closed so far.
    pub failing_windows: u64,
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
    /// `dt`: the nominal sampling interval (s); `noise_variance`: the band's, per floor.
    pub fn new(options: Options, noise_variance: [f64; 3], dt: f64) -> Self {
        Detector {
            options,
            noise_sd: noise_variance.map(f64::sqrt),
            half: (options.severity_window / dt / 2.0).round() as usize,
            start_time: None,
            count: 0,
            judged: 0,
            prefix: [0.0; 3],
            pending: VecDeque::new(),
            group: None,
            rolling: VecDeque::new(),
            overall: RunningNmse::default(),
            failing_windows: 0,
        }
    }

    /// Take one sample of the segment; events for the samples it lets the detector judge.
    pub fn push(&mut self, time: f64, measured: [f64; 3], predicted: [f64; 3]) -> Vec<Event> {
        let start = *self.start_time.get_or_insert(time);
        let before = self.prefix;
        for f in 0..3 {
            let u = (measured[f] - predicted[f]) / self.noise_sd[f];
            self.prefix[f] += if u.is_finite() { u * u } else { f64::MAX / 4.0 };
        }
        self.pending.push_back(Entry {
            time,
            measured,
            predicted,
            before,
            after: self.prefix,
        });
        self.count += 1;
        if time - start >= self.options.transient {
            self.overall.add(measured, predicted);
            self.rolling.push_back((time, measured, predicted));
            while let Some(&(t, ..)) = self.rolling.front() {
                if time - t >= self.options.window {
                    self.rolling.pop_front();
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
        self.prefix = [0.0; 3];
        self.pending.clear();
        self.rolling.clear();
        events
    }

    /// Whether a failing window is open (announced, not yet closed).
    pub fn window_open(&self) -> bool {
        self.group.as_ref().is_some_and(|g| g.alerted)
    }

    /// NMSE per floor over the last `--window` seconds after the transient (NaN: no samples).
    pub fn rolling_nmse(&self) -> [f64; 3] {
        [0, 1, 2].map(|f| {
            let y: Vec<f64> = self.rolling.iter().map(|(_, m, _)| m[f]).collect();
            let p: Vec<f64> = self.rolling.iter().map(|(_, _, p)| p[f]).collect();
            nmse(&y, &p)
        })
    }

    /// Judge sample `self.judged` (the oldest pending), as `compare` does.
    fn judge(&mut self, events: &mut Vec<Event>) {
        let k = self.judged;
        let first_pending = self.count - self.pending.len();
        let at = |i: usize| &self.pending[i - first_pending];
        let a = k.saturating_sub(self.half);
        let b = (k + self.half + 1).min(self.count);
        let entry = at(k).clone();
        let (from, to) = (at(a).before, at(b - 1).after);
        let outside = [0, 1, 2].map(|f| {
            let severe = ((to[f] - from[f]) / (b - a) as f64).sqrt() >= self.options.severity;
            (entry.measured[f] - entry.predicted[f]).abs() > 3.0 * self.noise_sd[f] && severe
        });
        self.judged += 1;
        // Keep what later samples' severity windows still reach back to.
        let keep_from = self.judged.saturating_sub(self.half);
        while first_pending_of(self) < keep_from {
            self.pending.pop_front();
        }
        let start = self.start_time.unwrap_or(entry.time);
        if entry.time - start < self.options.transient {
            return;
        }
        let out = outside.iter().any(|&o| o);
        if let Some(group) = &self.group {
            if entry.time - group.last > self.options.merge_gap {
                let group = self.group.take().expect("an open group");
                events.push(self.close(group));
            }
        }
        match (&mut self.group, out) {
            (Some(group), _) => {
                for f in 0..3 {
                    group.measured[f].push(entry.measured[f]);
                    group.predicted[f].push(entry.predicted[f]);
                }
                if out {
                    group.last = entry.time;
                    group.outliers += 1;
                    group.through_last = group.measured[0].len();
                    for f in 0..3 {
                        group.floors[f] |= outside[f];
                    }
                }
            }
            (None, true) => {
                self.group = Some(Group {
                    start: entry.time,
                    last: entry.time,
                    outliers: 1,
                    floors: outside,
                    measured: entry.measured.map(|v| vec![v]),
                    predicted: entry.predicted.map(|v| vec![v]),
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
                        floors: group.floors(),
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
        Event::Closed {
            window: FailingWindow {
                start: group.start,
                end: group.last,
                channels: group.floors().iter().map(|f| format!("acc{f}")).collect(),
                floors: group.floors(),
                nmse: nmse.to_vec(),
            },
            failing,
            was_opened: group.alerted,
        }
    }
}

fn first_pending_of(d: &Detector) -> usize {
    d.count - d.pending.len()
}

/// `compare`'s tolerance: some floor that left the band has an NMSE not below it.
fn passes(group: &Group, nmse: &[f64; 3], tolerance: f64) -> bool {
    (0..3).any(|f| group.floors[f] && !(nmse[f] < tolerance))
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
            let mut d = Detector::new(Options::new(options, 2.0), [0.01; 3], dt);
            let mut events = Vec::new();
            for k in 0..time.len() {
                events.extend(d.push(
                    time[k],
                    [0, 1, 2].map(|f| measured[f][k]),
                    [0, 1, 2].map(|f| predicted[f][k]),
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
}
