//! The diagnosis of a failing window, run on a thread of its own while the stream goes on.
//!
//! The watcher keeps the last `record` seconds of the current segment (the excitation and the
//! measured channels, whatever the stream measures). When a failing window opens, a diagnosis is due: it starts when the window
//! closes, or `after` seconds after it opened, whichever comes first (more of the changed
//! behaviour is more evidence), on the samples kept then, with `twin diagnose`'s decision.
//! One runs at a time; a window that opens meanwhile waits for it. Its result is a
//! `diagnosis` alert (action, effects, NMSE before and after) and the whole report in a file
//! beside the alerts, ready for `twin add-physics --diagnosis`.
//!
//! A window whose opening located a change ([`super::online::locate_change`]) is diagnosed on
//! what came after it instead: the samples from the change's time to now, every fit starting
//! from the state the twin reached at the change on the `warmup` s before it
//! (`diagnose::change`), once `post` seconds of them exist, and again with each
//! further `post` seconds while the window stays open, up to [`MAX_POST`] s, until a verdict
//! (the action and where: the parameter recalibration moves most, the effects, the faulty
//! sensor) is firm: by its own evidence ([`super::firm`]: the candidates told apart, the
//! answer's posterior narrow), or because two looks in a row gave it. The first look's `post`
//! (10 s by default, about 20 periods of the paper's building's first mode) is the least that
//! the candidates' fits need; how much more it waits is the evidence's.
//!
//! What a checkpoint needs is here too: the kept samples, the due diagnosis, and the running
//! one's samples, so a restarted watcher runs again what its predecessor had not reported.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use ::structure::channel::Channel;

use serde_json::Value;

use super::firm::{weigh, Before, Weight};
use super::online::{ChangePoint, CHANGE_LOOKBACK};
use super::second;
use crate::twin::data::{Measurement, Signal};
use crate::twin::Twin;
use crate::workflows::diagnose::change::{before_the_change, chained_state, starting_from};
use crate::workflows::diagnose::{diagnose, Action, DiagnoseOptions, Diagnosis};

/// The most post-change seconds a diagnosis waits for.
pub const MAX_POST: f64 = 30.0;

/// When and on what the background diagnosis runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisOptions {
    /// Seconds of samples kept for it.
    pub record: f64,
    /// Seconds after a window opens that the diagnosis starts if the window is still open
    /// (a window without a located change).
    pub after: f64,
    /// Post-change seconds of the first diagnosis after a located change, and the step of
    /// the next ones.
    #[serde(default = "default_post")]
    pub post: f64,
    /// The comparison's transient (s).
    #[serde(default)]
    pub transient: f64,
    /// Seconds before a located change that its diagnosis starts with: the twin as it is runs
    /// on them from rest to the state it reached at the change, from which every fit starts
    /// (`diagnose::change`). The structure does not start at rest, and with a few % damping
    /// the difference takes seconds to die out (e^(−ζωt): 10 s leave about a twentieth of it
    /// on the paper's building's first mode, 30 s a ten-thousandth). With a shear FMU that
    /// has no start values, they are left out of the error measures instead.
    #[serde(default = "default_warmup")]
    pub warmup: f64,
    /// Wait for each diagnosis before the next sample (a recorded stream replayed at full
    /// speed, which would otherwise outrun its diagnoses; a live stream never waits).
    #[serde(default)]
    pub wait: bool,
}

fn default_warmup() -> f64 {
    30.0
}

fn default_post() -> f64 {
    10.0
}

impl Default for DiagnosisOptions {
    fn default() -> Self {
        DiagnosisOptions {
            record: 45.0,
            after: 5.0,
            post: default_post(),
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            warmup: default_warmup(),
            wait: false,
        }
    }
}

/// A located change being diagnosed while its window stays open.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Episode {
    pub window_start: f64,
    pub change: f64,
    /// The change time's interval's end: samples after it are surely the new structure's.
    pub change_high: f64,
    /// Diagnoses started for it so far.
    pub rounds: u32,
    /// The last diagnosis's verdict, and whether the one before agreed.
    pub verdict: Option<String>,
    pub firm: bool,
    /// Its answer was adopted: no further rounds.
    pub closed: bool,
    /// Windows that opened again while its looks went on: the change's too.
    #[serde(default)]
    pub windows: Vec<f64>,
    /// The end of its last window that closed (s of the stream).
    #[serde(default)]
    pub last_closed: Option<f64>,
    /// The last look's structural answer (its parameters) and the last sample it answered on:
    /// the next look checks its samples for a second change against it ([`second_change`]).
    #[serde(default)]
    pub answer: Option<(Vec<(String, Value)>, f64)>,
}

impl Episode {
    /// A change located at `c`, its first window opening at `window_start`, not looked at yet.
    fn new(window_start: f64, c: &ChangePoint) -> Self {
        Episode {
            window_start,
            change: c.time,
            change_high: c.high,
            rounds: 0,
            verdict: None,
            firm: false,
            closed: false,
            windows: Vec::new(),
            last_closed: None,
            answer: None,
        }
    }

    /// Whether a window opening at `window_start` is this change's: while its looks go on, and
    /// after them, while its answer is not adopted, unless the residual has been back in band
    /// for [`CHANGE_LOOKBACK`] s — as long as a new change's location looks back. A structure
    /// left changed (no `--adopt`) or a faulty sensor fails the band on and off: one change,
    /// looked at until firm, not a new change at each window.
    fn owns(&self, window_start: f64, looking: bool) -> bool {
        !self.closed
            && (looking
                || self
                    .last_closed
                    .is_none_or(|end| window_start - end < CHANGE_LOOKBACK))
    }
}

/// The stream's columns as kept: the excitation and the measured channels; each sample kept
/// flat as its time, the excitation and the channels' values (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Columns {
    pub excitation: Channel,
    pub channels: Vec<Channel>,
}

impl Columns {
    /// Values a sample takes.
    pub fn width(&self) -> usize {
        2 + self.channels.len()
    }
}

/// A diagnosis started and not yet reported.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Job {
    /// The failing window it is about (its start, s of the stream).
    pub window_start: f64,
    /// The stream's sampling interval.
    pub dt: f64,
    pub columns: Columns,
    /// The samples, flat ([`Columns`]).
    pub samples: Vec<f64>,
    /// The located change it diagnoses what came after (None: the window's samples), and
    /// which look at it this is (1 first).
    #[serde(default)]
    pub change: Option<f64>,
    #[serde(default)]
    pub round: u32,
    /// The seconds before the change it starts with, left out of its error measures (None:
    /// the comparison's transient).
    #[serde(default)]
    pub warmup: Option<f64>,
    /// The last look's answer on the same change ([`Episode::answer`]).
    #[serde(default)]
    pub answer: Option<(Vec<(String, Value)>, f64)>,
}

impl Job {
    /// The first and the last sample's times (NaN without samples).
    pub fn span(&self) -> (f64, f64) {
        let width = self.columns.width();
        let n = self.samples.len() / width;
        if n == 0 {
            return (f64::NAN, f64::NAN);
        }
        (self.samples[0], self.samples[(n - 1) * width])
    }
}

/// The part a checkpoint carries.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Saved {
    /// The kept samples, flat ([`Columns`]).
    pub kept: VecDeque<f64>,
    /// A window whose diagnosis is due: (its start, when it opened).
    pub due: Option<(f64, f64)>,
    pub running: Option<Job>,
    /// The last window whose diagnosis started (its start).
    #[serde(default)]
    pub launched: Option<f64>,
    /// Diagnoses reported so far (they number the report files).
    pub reported: u64,
    /// The located change being diagnosed.
    #[serde(default)]
    pub episode: Option<Episode>,
}

/// What a diagnosis's thread sends back: its result, a second change it cut at, and how its
/// effects fit the samples before its change.
type Outcome = (
    Result<Diagnosis, String>,
    Option<ChangePoint>,
    Option<Before>,
);

/// A finished diagnosis.
pub struct Finished {
    pub job: Job,
    pub result: Result<Diagnosis, String>,
    /// Wall-clock seconds from its start.
    pub seconds: f64,
    /// Its verdict is the one before's on the same change: firm.
    pub firm: bool,
    /// A second change found after the samples the last look answered on: this look answered
    /// on the samples before it.
    pub second: Option<ChangePoint>,
    /// What its evidence says of its verdict (a look at a change that answered).
    pub weight: Option<Weight>,
    /// Why it is firm: its own evidence, or the look before's same verdict.
    pub because: Option<String>,
    /// An `add_physics` answer after a change: whether its effects were there before.
    pub before: Option<Before>,
}

pub struct Background {
    pub saved: Saved,
    columns: Columns,
    options: DiagnosisOptions,
    /// The twins live so far, each from the change its answer was to (the first from the
    /// start): the last is diagnosed, the ones before give the state it starts from.
    history: Vec<(f64, Twin)>,
    diagnose: DiagnoseOptions,
    dt: f64,
    /// The running diagnosis's thread.
    worker: Option<(Receiver<Outcome>, Instant)>,
}

impl Background {
    pub fn new(
        twin: &Twin,
        options: DiagnosisOptions,
        diagnose: DiagnoseOptions,
        saved: Saved,
        columns: Columns,
    ) -> Self {
        let mut b = Background {
            saved,
            columns,
            options,
            history: vec![(f64::NEG_INFINITY, twin.duplicate())],
            diagnose,
            dt: f64::NAN,
            worker: None,
        };
        // A diagnosis the last run started and did not report runs again.
        if let Some(job) = b.saved.running.clone() {
            b.start(job);
        }
        b
    }

    /// Keep one sample of the segment: its time, excitation and measured values.
    pub fn push(&mut self, time: f64, excitation: f64, measured: &[f64]) {
        let width = self.columns.width();
        let kept = &mut self.saved.kept;
        kept.push_back(time);
        kept.push_back(excitation);
        kept.extend(&measured[..width - 2]);
        // Enough for the last look after a change and its warm-up, and for a window's record.
        let keep = self
            .options
            .record
            .max(MAX_POST + self.options.warmup + self.options.post);
        while kept.front().is_some_and(|&t| time - t > keep) {
            kept.drain(..width);
        }
    }

    /// Every sample kept (the current one last), as a record of the stream's channels.
    pub fn kept(&self) -> Result<Measurement, String> {
        record(&Job {
            window_start: f64::NAN,
            dt: self.dt,
            columns: self.columns.clone(),
            samples: self.saved.kept.iter().copied().collect(),
            change: None,
            round: 0,
            warmup: None,
            answer: None,
        })
    }

    /// A gap: the next segment's twin starts anew, and so does what is kept.
    pub fn gap(&mut self) {
        self.saved.kept.clear();
    }

    /// A failing window opened at `time`; `change`: the change located behind it. While the
    /// looks at a change go on (not firm, not adopted, not past [`MAX_POST`]), a window that
    /// opens again is that change's (a damping change, a contact, fails the band on and off):
    /// its looks keep their schedule from the first change.
    pub fn opened(&mut self, window_start: f64, time: f64, change: Option<ChangePoint>) {
        let live = self
            .saved
            .episode
            .as_ref()
            .is_some_and(|e| e.owns(window_start, self.next_post(e).is_some()));
        if let (true, Some(e)) = (live, &mut self.saved.episode) {
            e.windows.push(window_start);
            return;
        }
        if let Some(c) = change {
            // What came after the change is diagnosed, in rounds (`poll`).
            if self
                .saved
                .due
                .is_some_and(|(start, _)| start == window_start)
            {
                self.saved.due = None;
            }
            self.saved.episode = Some(Episode::new(window_start, &c));
            return;
        }
        if self.saved.due.is_none() && self.saved.launched != Some(window_start) {
            self.saved.due = Some((window_start, time));
        }
    }

    /// The post-change seconds the next round of `episode` waits for (None: no more).
    fn next_post(&self, e: &Episode) -> Option<f64> {
        if e.firm || e.closed {
            return None;
        }
        let post = self.options.post * (e.rounds + 1) as f64;
        (post <= MAX_POST + 1e-9 || e.rounds == 0).then_some(post.min(MAX_POST))
    }

    /// A window (from `window_start` to `end`) closed: its diagnosis starts now if it was
    /// failing, is dropped if not. A located change's looks go on (back in band for now is not
    /// the structure back as it was: a damping change or a contact fails the band on and off).
    pub fn closed(&mut self, window_start: f64, end: f64, failing: bool) {
        if let Some(e) = self
            .saved
            .episode
            .as_mut()
            .filter(|e| e.window_start == window_start || e.windows.contains(&window_start))
        {
            e.last_closed = Some(end);
            return;
        }
        match self.saved.due {
            Some((start, _)) if start == window_start && !failing => self.saved.due = None,
            Some((start, _)) if start == window_start => self.launch(),
            None if failing && self.saved.launched != Some(window_start) => {
                // Judged failing only as it closed: due now.
                self.saved.due = Some((window_start, f64::NEG_INFINITY));
                self.launch();
            }
            _ => {}
        }
    }

    /// At each sample: start what is due, collect what finished.
    pub fn poll(&mut self, time: f64) -> Option<Finished> {
        if let Some((_, opened)) = self.saved.due {
            if time - opened >= self.options.after {
                self.launch();
            }
        }
        if let Some(e) = &self.saved.episode {
            if let Some(post) = self.next_post(e) {
                if time - e.change_high >= post {
                    self.launch_episode(post);
                }
            }
        }
        self.collect(self.options.wait)
    }

    /// The watch adopted `twin`: later diagnoses are of it, and the change it answers is not
    /// looked at again. It is the structure from that change on; the twins before it, before.
    pub fn adopted(&mut self, twin: &Twin) {
        let since = self.answered_change();
        self.history.retain(|(t, _)| *t < since);
        self.history.push((since, twin.duplicate()));
        if let Some(e) = &mut self.saved.episode {
            e.closed = true;
        }
    }

    /// The change an answer adopted now is to: the episode's (none: the whole record's, a
    /// window's diagnosis fitted over all of it).
    fn answered_change(&self) -> f64 {
        self.saved
            .episode
            .as_ref()
            .filter(|e| !e.closed)
            .map_or(f64::NEG_INFINITY, |e| e.change)
    }

    /// The state `twin`, adopted now, reaches at the last of the samples `kept`: the twins
    /// live before the change it answers run up to it, `twin` from there (None: a shear FMU
    /// without start values).
    pub fn reached(
        &self,
        twin: &Twin,
        kept: &Measurement,
    ) -> crate::workflows::diagnose::Result<Option<Vec<(String, f64)>>> {
        let since = self.answered_change();
        let mut history: Vec<(f64, &Twin)> = self
            .history
            .iter()
            .filter(|(t, _)| *t < since)
            .map(|(t, twin)| (*t, twin))
            .collect();
        history.push((since, twin));
        chained_state(&history, kept)
    }

    /// At the stream's end: start what is due and wait for what runs; each finished one. A
    /// located change not yet looked at is diagnosed on what came after it, however little.
    pub fn finish(&mut self) -> Vec<Finished> {
        let mut done = Vec::new();
        loop {
            if self.worker.is_none() && self.saved.due.is_some() {
                self.launch();
            }
            if self.worker.is_none() {
                // The looks the stream's samples allow that a busy worker held back, each on
                // its own amount; a change not looked at yet, on what there is.
                let last = self.saved.kept.back().map(|_| {
                    let width = self.columns.width();
                    self.saved.kept[self.saved.kept.len() - width]
                });
                let look = match (&self.saved.episode, last) {
                    (Some(e), Some(last)) => match self.next_post(e) {
                        Some(post) if last - e.change_high >= post => Some(post),
                        _ if e.rounds == 0 => Some(f64::INFINITY),
                        _ => None,
                    },
                    _ => None,
                };
                if let Some(post) = look {
                    self.launch_episode(post);
                }
            }
            match self.collect(true) {
                Some(f) => done.push(f),
                None => return done,
            }
        }
    }

    /// Look at a second change ([`Finished::second`]) on its own, now that the answer to the
    /// first is adopted: an episode of its own from its time, its windows to come its.
    pub fn second(&mut self, c: &ChangePoint) {
        self.saved.episode = Some(Episode::new(c.time, c));
    }

    /// Whether a diagnosis is running.
    pub fn busy(&self) -> bool {
        self.worker.is_some()
    }

    /// The stream's sampling interval, once known.
    pub fn set_dt(&mut self, dt: f64) {
        self.dt = dt;
    }

    fn launch(&mut self) {
        if self.worker.is_some() {
            return;
        }
        let Some((window_start, _)) = self.saved.due.take() else {
            return;
        };
        let width = self.columns.width();
        let kept = &self.saved.kept;
        let last = kept.len().checked_sub(width).map_or(f64::NAN, |k| kept[k]);
        let first = (0..kept.len() / width)
            .find(|&k| last - kept[k * width] <= self.options.record + 1e-9)
            .unwrap_or(0);
        let job = Job {
            window_start,
            dt: self.dt,
            columns: self.columns.clone(),
            samples: kept.range(first * width..).copied().collect(),
            change: None,
            round: 1,
            warmup: None,
            answer: None,
        };
        self.saved.running = Some(job.clone());
        self.saved.launched = Some(window_start);
        self.start(job);
    }

    /// The next round of the episode: the samples from its change less the warm-up to `post`
    /// seconds after the change's interval.
    fn launch_episode(&mut self, post: f64) {
        if self.worker.is_some() {
            return;
        }
        let Some(e) = &mut self.saved.episode else {
            return;
        };
        e.rounds += 1;
        let (window_start, change, round) = (e.window_start, e.change, e.rounds);
        let answer = e.answer.clone();
        let until = e.change_high + post;
        let from = change - self.options.warmup;
        let width = self.columns.width();
        let kept = &self.saved.kept;
        let first = (0..kept.len() / width)
            .find(|&k| kept[k * width] >= from - 1e-9)
            .unwrap_or(kept.len() / width);
        let last = (first..kept.len() / width)
            .find(|&k| kept[k * width] > until + 1e-9)
            .unwrap_or(kept.len() / width);
        let start = kept.get(first * width).copied().unwrap_or(change);
        let job = Job {
            window_start,
            dt: self.dt,
            columns: self.columns.clone(),
            samples: kept.range(first * width..last * width).copied().collect(),
            change: Some(change),
            round,
            warmup: Some((change - start).max(self.options.transient)),
            answer,
        };
        self.saved.running = Some(job.clone());
        self.saved.launched = Some(window_start);
        self.start(job);
    }

    fn start(&mut self, job: Job) {
        let (send, receive) = std::sync::mpsc::channel();
        let history: Vec<(f64, Twin)> = self
            .history
            .iter()
            .map(|(t, twin)| (*t, twin.duplicate()))
            .collect();
        let mut options = self.diagnose.clone();
        if let Some(w) = job.warmup {
            options.transient = w;
        }
        options.changed_at = job.change;
        std::thread::spawn(move || {
            let (mut second, mut prior) = (None, None);
            let result = record(&job).and_then(|m| {
                let (twin, m) = continued(&history, m, job.change).map_err(|e| e.to_string())?;
                let m = match (job.change, &job.answer) {
                    (Some(change), Some((answer, until))) => {
                        let answer = second::from_json(answer);
                        second = second::second_change(&twin, &answer, &m, change, *until);
                        match &second {
                            Some(c) => before(&m, c.low),
                            None => m,
                        }
                    }
                    _ => m,
                };
                let d = diagnose(&twin, &m, &options).map_err(|e| e.to_string())?;
                prior = job.change.and_then(|at| effect_before(&twin, &d, &m, at));
                Ok(d)
            });
            // The watcher may have stopped waiting; nothing to do then.
            let _ = send.send((result, second, prior));
        });
        self.worker = Some((receive, Instant::now()));
    }

    fn collect(&mut self, wait: bool) -> Option<Finished> {
        let (receive, started) = self.worker.as_ref()?;
        let stopped = || (Err("the diagnosis thread stopped".into()), None, None);
        let (result, second, before) = if wait {
            receive.recv().unwrap_or_else(|_| stopped())
        } else {
            match receive.try_recv() {
                Ok(r) => r,
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => stopped(),
            }
        };
        let seconds = started.elapsed().as_secs_f64();
        self.worker = None;
        let mut job = self.saved.running.take()?;
        if let Some(c) = &second {
            // It answered on the samples before the second change.
            let width = job.columns.width();
            let keep = job
                .samples
                .chunks(width)
                .take_while(|s| s[0] < c.low)
                .count();
            job.samples.truncate(keep * width);
        }
        self.saved.reported += 1;
        let mut firm = false;
        let (mut weight, mut because) = (None, None);
        if let (Some(e), Some(_)) = (&mut self.saved.episode, job.change) {
            if e.window_start == job.window_start {
                let now = result.as_ref().ok().map(verdict);
                let w = result.as_ref().ok().map(weigh);
                because = match (&w, &now) {
                    (
                        Some(Weight {
                            decisive: Some(why),
                            ..
                        }),
                        _,
                    ) => Some(why.clone()),
                    (_, Some(v)) if now == e.verdict => {
                        Some(format!("the look before gave the same verdict, {v}"))
                    }
                    _ => None,
                };
                weight = w;
                e.firm = because.is_some();
                e.verdict = now;
                firm = e.firm;
                e.answer = result
                    .as_ref()
                    .ok()
                    .and_then(super::adopt::answer)
                    .map(|a| (second::to_json(&a), job.span().1));
            }
        }
        Some(Finished {
            job,
            result,
            seconds,
            firm,
            second,
            weight,
            because,
            before,
        })
    }
}

/// A diagnosis's verdict: its action and where (the parameter recalibration moved most, in
/// posterior sds; the effects; the faulty sensor).
pub fn verdict(d: &Diagnosis) -> String {
    let site = match d.action {
        Action::Recalibrate => d
            .recalibration
            .as_ref()
            .and_then(|r| r.parameters.first())
            .map(|p| p.name.clone())
            .unwrap_or_default(),
        Action::AddPhysics => d
            .effects
            .iter()
            .map(|e| e.name.label.clone())
            .collect::<Vec<_>>()
            .join("+"),
        Action::SensorFault => d
            .sensor
            .as_ref()
            .map(|s| s.channel.clone())
            .unwrap_or_default(),
        _ => String::new(),
    };
    format!("{}:{site}", d.action.name())
}

/// The live twin and the samples it is diagnosed on, for a look at what came after `change`
/// in `m`: when an earlier answer was adopted within `m` (the last twin is live from a change
/// after `m`'s start), the twins before run up to that change, and the live twin starts from
/// the state they reached there, on the samples from there on — rather than run from rest at
/// `m`'s start over samples of a structure it was not yet. Otherwise the live twin on `m`.
fn continued(
    history: &[(f64, Twin)],
    m: Measurement,
    change: Option<f64>,
) -> crate::workflows::diagnose::Result<(Twin, Measurement)> {
    let Some((since, live)) = history.last().map(|(t, twin)| (*t, twin)) else {
        return Err(crate::workflows::diagnose::DiagnoseError::Setup(
            "no live twin to diagnose".into(),
        ));
    };
    let at = |t: f64| m.time.iter().position(|&s| s >= t - 1e-9 * m.dt);
    let (Some(change), Some(k)) = (change, at(since)) else {
        return Ok((live.duplicate(), m));
    };
    // The live twin's start and the change each need a sample of their own before them.
    if k == 0 || at(change).is_none_or(|k0| k + 1 >= k0) {
        return Ok((live.duplicate(), m));
    }
    let before: Vec<(f64, &Twin)> = history[..history.len() - 1]
        .iter()
        .map(|(t, twin)| (*t, twin))
        .collect();
    match chained_state(&before, &m.head(k + 1))? {
        Some(state) => Ok((starting_from(live, &state)?, m.samples(k..m.len()))),
        None => Ok((live.duplicate(), m)),
    }
}

/// Seconds of the samples before a change that [`effect_before`] leaves out: both twins run
/// from rest there.
const BEFORE_SKIP: f64 = 10.0;

/// For an `add_physics` answer `d` after the change at `at`: how its effects fit the samples
/// of `m` before the change ([`super::firm::before`]); None for any other answer.
fn effect_before(twin: &Twin, d: &Diagnosis, m: &Measurement, at: f64) -> Option<Before> {
    if d.action != Action::AddPhysics {
        return None;
    }
    let answer = super::adopt::answer(d)?;
    let (old, new) = before_the_change(twin, &answer, m, at, BEFORE_SKIP).ok()??;
    let label = d
        .effects
        .iter()
        .map(|e| e.name.label.clone())
        .collect::<Vec<_>>()
        .join("+");
    Some(super::firm::before(&old, &new, &label, at))
}

/// `m`'s samples before `time`.
fn before(m: &Measurement, time: f64) -> Measurement {
    let n = m.time.iter().take_while(|&&t| t < time).count();
    m.head(n)
}

/// A job's samples as a record of the stream's channels (SI) for `diagnose`.
pub fn record(job: &Job) -> Result<Measurement, String> {
    let width = job.columns.width();
    let n = job.samples.len() / width;
    if n < 2 {
        return Err(format!("{n} samples kept; a diagnosis needs more"));
    }
    let column = |i: usize| -> Vec<f64> { (0..n).map(|k| job.samples[k * width + i]).collect() };
    let signal = |channel: Channel, i: usize| Signal {
        channel,
        unit: channel.quantity().si(),
        values: column(i),
    };
    let (from, to) = job.span();
    Ok(Measurement {
        path: PathBuf::from(format!("the stream from {from:.3} s to {to:.3} s")),
        time: column(0),
        dt: job.dt,
        excitation: signal(job.columns.excitation, 1),
        responses: job
            .columns
            .channels
            .iter()
            .enumerate()
            .map(|(c, &channel)| signal(channel, 2 + c))
            .collect(),
        extra: Default::default(),
        header_line: None,
    })
}

/// Where the `k`-th diagnosis's report goes: beside the alerts, `ALERTS.diagnosis-k.json`.
pub fn report_path(alerts: &Path, k: u64) -> PathBuf {
    let stem = alerts
        .file_stem()
        .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
    alerts.with_file_name(format!("{stem}.diagnosis-{k}.json"))
}
