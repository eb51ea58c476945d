//! One sample's stage: the twin's FMUs stepped once, the prediction compared with each measured
//! channel once the noise band is known, the modes tracked and the learner supervised; and the
//! watch's end, its summary.

use super::alerts::{floats, window_values, Alerts};
use super::background::Background;
use super::checkpoint::{State, Welford};
use super::observe::{status, LearningSummary, Observer, Status, Summary};
use super::online::{names_and_floors, Detector};
use super::options::{WatchOptions, GAP_FACTOR, NOISE_REFERENCE};
use super::stepper::Stepper;
use super::stream::{LineReader, Run};
use super::supervise::{Decision, LearnOptions};
use super::{modes, WatchError};
use crate::record::nominal_step;
use crate::twin::run::{Tolerance, PRIOR_NOISE_FRACTION};
use crate::twin::Twin;
use ::structure::channel::Channel;
use serde_json::{json, Value};
use std::time::{Duration, Instant};

pub(super) struct Watcher<'a> {
    /// Told of every alert written (its JSON object); an error stops the watch.
    pub(super) on_alert: &'a mut dyn FnMut(&Value) -> Result<(), String>,
    pub(super) state: State,
    pub(super) stepper: Stepper,
    /// The twin live now: the one watched, or the last adopted.
    pub(super) live: Twin,
    pub(super) alerts: Alerts,
    pub(super) reader: LineReader,
    /// A line read before the watch began (an MQTT stream's first), given out first.
    pub(super) pushed_back: Option<String>,
    pub(super) background: Option<Background>,
    /// The twin's noise variance per measured channel, where it holds one.
    pub(super) twin_noise: Vec<Option<f64>>,
    pub(super) options: &'a WatchOptions,
    /// The sample's measured values and the twin's predictions (per channel; reused).
    pub(super) measured: Vec<f64>,
    pub(super) predicted: Vec<f64>,
    /// The twin's modes while the tracker waits for the sampling interval, then the tracker.
    pub(super) twin_modes: Option<crate::workflows::modal::TwinModes>,
    pub(super) tracker: Option<modes::Tracker>,
    /// The live view (`--serve`), dropped if it panics.
    pub(super) observer: Option<&'a mut dyn Observer>,
    /// When the checkpoint was last saved.
    pub(super) saved_at: Option<Instant>,
    /// Windows open when their segment ended (a gap, the stream's end), for the gap's or the
    /// end's alert.
    pub(super) cut_windows: Vec<crate::evaluation::compare::FailingWindow>,
}

/// The stepper of `twin` (wired to give out every one of `channels`), its corrector's learning
/// parameters set; with the training-set budget when the corrector's FMU takes one.
pub(super) fn open_stepper(
    twin: &Twin,
    excitation: Channel,
    channels: &[Channel],
    learning: &LearnOptions,
) -> Result<(Stepper, Option<u32>), WatchError> {
    let wired = twin.wired_for(channels);
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

/// The twin's modes for `--track-modes` (its options checked first).
pub(super) fn modes_to_track(
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

/// The excitation column of `structure`: `force` or `ground_acc`.
pub(super) fn structure_excitation(structure: &::structure::Structure) -> Channel {
    Channel::Excitation(::structure::channel::ExcitationKind::of(
        &structure.excitation,
    ))
}

/// The stream's end: the checkpoint saved, the open segment finished, the diagnoses still
/// running awaited, and the `end` alert with the run's summary.
pub(super) fn end(
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

impl Watcher<'_> {
    /// NaN for every measured channel.
    pub(super) fn nan(&self) -> Vec<f64> {
        vec![f64::NAN; self.state.channels.len()]
    }

    /// The band's noise variances once known: the twin's for every channel it holds one for;
    /// for the others, [`PRIOR_NOISE_FRACTION`] of the measured variance over the
    /// [`NOISE_REFERENCE`] seconds after the segment's transient (summed as they come;
    /// `since`: the sample's time after the segment's start). Whether they are known (in
    /// `self.state.noise_variance`).
    pub(super) fn noise_known(&mut self, since: f64) -> bool {
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
    pub(super) fn noise_source(&self) -> String {
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
    pub(super) fn sample(&mut self, time: f64, excitation: f64) -> Result<(), WatchError> {
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
    pub(super) fn track(&mut self, time: f64) -> Result<(), WatchError> {
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
    pub(super) fn supervise(&mut self, time: f64) -> Result<(), WatchError> {
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
}
