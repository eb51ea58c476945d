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
//! What a checkpoint needs is here too: the kept samples, the due diagnosis, and the running
//! one's samples, so a restarted watcher runs again what its predecessor had not reported.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use ::structure::channel::Channel;

use crate::twin::data::{Measurement, Signal};
use crate::twin::Twin;
use crate::workflows::diagnose::{diagnose, DiagnoseOptions, Diagnosis};

/// When and on what the background diagnosis runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisOptions {
    /// Seconds of samples kept for it.
    pub record: f64,
    /// Seconds after a window opens that the diagnosis starts if the window is still open.
    pub after: f64,
}

impl Default for DiagnosisOptions {
    fn default() -> Self {
        DiagnosisOptions {
            record: 20.0,
            after: 5.0,
        }
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
}

/// A finished diagnosis.
pub struct Finished {
    pub job: Job,
    pub result: Result<Diagnosis, String>,
    /// Wall-clock seconds from its start.
    pub seconds: f64,
}

pub struct Background {
    pub saved: Saved,
    columns: Columns,
    options: DiagnosisOptions,
    twin: Twin,
    diagnose: DiagnoseOptions,
    dt: f64,
    /// The running diagnosis's thread.
    worker: Option<(Receiver<Result<Diagnosis, String>>, Instant)>,
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
            twin: twin.duplicate(),
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
        while kept
            .front()
            .is_some_and(|&t| time - t > self.options.record)
        {
            kept.drain(..width);
        }
    }

    /// A gap: the next segment's twin starts anew, and so does what is kept.
    pub fn gap(&mut self) {
        self.saved.kept.clear();
    }

    /// A failing window opened at `time`.
    pub fn opened(&mut self, window_start: f64, time: f64) {
        if self.saved.due.is_none() && self.saved.launched != Some(window_start) {
            self.saved.due = Some((window_start, time));
        }
    }

    /// A window closed: its diagnosis starts now if it was failing, is dropped if not.
    pub fn closed(&mut self, window_start: f64, failing: bool) {
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
        self.collect(false)
    }

    /// At the stream's end: start what is due and wait for what runs; each finished one.
    pub fn finish(&mut self) -> Vec<Finished> {
        let mut done = Vec::new();
        loop {
            if self.worker.is_none() && self.saved.due.is_some() {
                self.launch();
            }
            match self.collect(true) {
                Some(f) => done.push(f),
                None => return done,
            }
        }
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
        let job = Job {
            window_start,
            dt: self.dt,
            columns: self.columns.clone(),
            samples: self.saved.kept.iter().copied().collect(),
        };
        self.saved.running = Some(job.clone());
        self.saved.launched = Some(window_start);
        self.start(job);
    }

    fn start(&mut self, job: Job) {
        let (send, receive) = std::sync::mpsc::channel();
        let twin = self.twin.duplicate();
        let options = self.diagnose.clone();
        std::thread::spawn(move || {
            let result =
                record(&job).and_then(|m| diagnose(&twin, &m, &options).map_err(|e| e.to_string()));
            // The watcher may have stopped waiting; nothing to do then.
            let _ = send.send(result);
        });
        self.worker = Some((receive, Instant::now()));
    }

    fn collect(&mut self, wait: bool) -> Option<Finished> {
        let (receive, started) = self.worker.as_ref()?;
        let result = if wait {
            receive
                .recv()
                .unwrap_or_else(|_| Err("the diagnosis thread stopped".into()))
        } else {
            match receive.try_recv() {
                Ok(r) => r,
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => Err("the diagnosis thread stopped".into()),
            }
        };
        let seconds = started.elapsed().as_secs_f64();
        self.worker = None;
        let job = self.saved.running.take()?;
        self.saved.reported += 1;
        Some(Finished {
            job,
            result,
            seconds,
        })
    }
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
