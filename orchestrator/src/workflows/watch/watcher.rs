//! The watcher: the watch's state between samples (the checkpoint's [`State`], the twin's
//! stepper, the alerts file, the stream's reader, the background diagnosis, the live view) and
//! what it does with them. Per sample, the twin's FMUs stepped once, the prediction compared with
//! each measured channel once the noise band is known, the modes tracked and the learner
//! supervised; the alerts written; the live view told; the checkpoint saved; a background
//! diagnosis's answer reported and, on a firm verdict, its twin adopted. It stands on the data
//! and rules of the files below it (alerts, adopt, checkpoint, observe, options, stream); the
//! loop over the stream and the watch's end ([`super::run`]) stand on it.

use super::adopt::{adopted_path, answer, answer_fields, answered, Adopted};
use super::alerts::{floats, window_values, Alerts};
use super::background::{self, Background, Columns, Finished};
use super::checkpoint::{State, Welford};
use super::mqtt::ConnectionEvent;
use super::observe::{LiveState, Observer, Point, Status};
use super::online::{names_and_floors, Detector, Event};
use super::options::{WatchOptions, GAP_FACTOR, NOISE_REFERENCE};
use super::stepper::Stepper;
use super::stream::LineReader;
use super::supervise::{Decision, LearnOptions};
use super::{modes, WatchError};
use crate::fsutil::write_text_atomically;
use crate::record::nominal_step;
use crate::twin::run::PRIOR_NOISE_FRACTION;
use crate::twin::{ParameterValue, Twin, TwinError};
use ::structure::channel::Channel;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::{Instant, SystemTime};

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

/// The background diagnosis, when the watch runs one.
pub(super) fn background_of(
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
        self.track(time, excitation)?;
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
    pub(super) fn track(&mut self, time: f64, excitation: f64) -> Result<(), WatchError> {
        if self.tracker.is_none() {
            if let (Some(dt), Some(options)) = (self.state.dt, self.options.modes) {
                if let Some(twin) = self.twin_modes.take() {
                    self.tracker = Some(modes::Tracker::new(
                        options,
                        twin,
                        self.state.channels.clone(),
                        self.state.excitation,
                        dt,
                    ));
                }
            }
        }
        let Some(tracker) = &mut self.tracker else {
            return Ok(());
        };
        let Some(result) = tracker.push(time, excitation, &self.measured) else {
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

// The alerts: written, sent on, and made of the detector's events and the connection's.
impl Watcher<'_> {
    pub(super) fn alert(
        &mut self,
        time: Option<f64>,
        kind: &str,
        mut body: Value,
    ) -> Result<(), WatchError> {
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
    pub(super) fn send(&mut self, body: &Value) -> Result<(), WatchError> {
        if self.alerts.write(body)? {
            if let Some(m) = self.reader.mqtt() {
                m.publish_alert(body.to_string())?;
            }
            self.observe(|o| o.alert(body));
            (self.on_alert)(body).map_err(WatchError::Callback)?;
        }
        Ok(())
    }

    /// The broker connection's changes as `connection` alerts (without a sequence number: a
    /// resumed run's connections are its own).
    pub(super) fn connection_alerts(&mut self) -> Result<(), WatchError> {
        let Some(m) = self.reader.mqtt() else {
            return Ok(());
        };
        let events = m.take_events();
        self.report_connection(events)
    }

    /// Connection changes as `connection` alerts.
    pub(super) fn report_connection(
        &mut self,
        events: Vec<ConnectionEvent>,
    ) -> Result<(), WatchError> {
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

    pub(super) fn events(&mut self, time: f64, events: Vec<Event>) -> Result<(), WatchError> {
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
}

// What a caller sees while the watch runs: the status and the live view.

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
                crate::notice::notify(crate::notice::Topic::LivePage, || {
                    "the live page failed; the watch goes on without it".to_owned()
                });
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

// The checkpoint saved, and the next line read.
impl Watcher<'_> {
    pub(super) fn save(&mut self) -> Result<(), WatchError> {
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
}

impl Watcher<'_> {
    /// The next line of the stream, the connection's changes reported.
    pub(super) fn next_line(&mut self) -> Result<Option<String>, WatchError> {
        if let Some(line) = self.pushed_back.take() {
            return Ok(Some(line));
        }
        let line = self.reader.next();
        self.connection_alerts()?;
        line
    }
}

// A background diagnosis reported and, on a firm verdict, its twin adopted.
impl Watcher<'_> {
    /// A background diagnosis finished: its report beside the alerts, and a `diagnosis`
    /// alert (without a sequence number: when it comes depends on the machine).
    pub(super) fn diagnosed(&mut self, finished: Finished) -> Result<(), WatchError> {
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
    pub(super) fn diagnosis_body(&self, finished: &Finished) -> Value {
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
    pub(super) fn write_diagnosis(
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
    pub(super) fn adopt(
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
