//! The watch's run over its stream ([`read_stream`]): each line a header (a broker's), a bad
//! sample or a sample the [`Watcher`] watches, with their gaps and duplicates; and the stream's
//! end ([`end`]), its summary.

use super::alerts::{floats, window_values, Latency};
use super::background::Background;
use super::observe::{LearningSummary, Status, Summary};
use super::online::Detector;
use super::stream::{is_header, Header, Run, Stream};
use super::watcher::{status, Watcher};
use super::WatchError;
use crate::twin::run::Tolerance;
use ::structure::channel::Channel;
use serde_json::{json, Value};
use std::time::{Duration, Instant};
/// The stream read to its end: each line a header (a broker's), a bad sample or a sample
/// watched; the checkpoint saved every `checkpoint_every` samples, `progress` and the live view
/// told five times a second.
pub(super) fn read_stream(
    w: &mut Watcher,
    stream: &Stream,
    header: &mut Header,
    progress: &mut impl FnMut(&Status),
) -> Result<Run, WatchError> {
    let options = w.options;
    let mut position = Position {
        // Lines and samples the checkpoint has consumed are skipped (a broker does not
        // replay: there only the samples' times tell what was seen).
        skip_lines: if stream.from_broker { 0 } else { w.state.lines },
        skip_until: w.state.last_time,
        line_number: 0,
        this_run: 0,
    };
    let mut latency = Latency::new();
    let started = Instant::now();
    let mut since_save: u64 = 0;
    let mut last_status = Instant::now();
    // Time spent waiting for a live source (a followed file, a broker), left out of the speed.
    let mut waited = Duration::ZERO;
    loop {
        let asked = Instant::now();
        let Some(line) = w.next_line()? else {
            break;
        };
        if stream.live {
            waited += asked.elapsed();
        }
        if line.trim().is_empty() {
            // A file's blank line still counts for the line numbers; a broker's empty line is
            // only a connection change.
            if !stream.from_broker {
                position.line_number += 1;
            }
            continue;
        }
        position.line_number += 1;
        if stream.from_broker && is_header(&line) {
            broker_header(w, stream, header, line, position.line_number)?;
            continue;
        }
        let began = Instant::now();
        match seen(w, stream, header, &line, &mut position) {
            Seen::Skipped => {}
            Seen::Bad(reason) => {
                w.state.bad_lines += 1;
                let time = w.state.last_time;
                // A file's line numbers count the header as line 1; a broker's count the lines
                // of its messages from 1.
                let line = if stream.from_broker {
                    position.line_number
                } else {
                    position.line_number + 1
                };
                w.alert(time, "bad_sample", json!({"line": line, "reason": reason}))?;
            }
            Seen::Sample(time, excitation) => {
                w.sample(time, excitation)?;
                w.show(time, began);
                position.this_run += 1;
                latency.add(began.elapsed().as_secs_f64());
                since_save += 1;
                if since_save >= options.checkpoint_every {
                    since_save = 0;
                    w.save()?;
                }
                if last_status.elapsed() > Duration::from_millis(200) {
                    last_status = Instant::now();
                    progress(&status(w, position.this_run, started));
                    let elapsed = started.elapsed().saturating_sub(waited).as_secs_f64();
                    w.show_state(position.this_run, elapsed, false);
                }
            }
        }
    }
    Ok(Run {
        samples: position.this_run,
        latency,
        started,
        waited,
    })
}

/// Where the stream is: the line read last, the samples this run took, and what a checkpoint
/// consumed already (skipped).
pub(super) struct Position {
    pub(super) skip_lines: u64,
    pub(super) skip_until: Option<f64>,
    pub(super) line_number: u64,
    pub(super) this_run: u64,
}

/// What a data line is to the watch.
pub(super) enum Seen {
    /// Consumed by the run a checkpoint saved, or a broker's duplicate.
    Skipped,
    Bad(String),
    /// A sample's time and excitation (its responses in the watcher's `measured`).
    Sample(f64, f64),
}

/// A broker's header line mid-stream: the header from then on, or a bad sample when it does not
/// fit the stream.
pub(super) fn broker_header(
    w: &mut Watcher,
    stream: &Stream,
    header: &mut Header,
    line: String,
    line_number: u64,
) -> Result<(), WatchError> {
    match Header::parse(&line, &w.options.columns, stream.structure, stream.describe)
        .and_then(|h| h.for_stream(stream.excitation, stream.channels))
    {
        Ok(h) => {
            *header = h;
            w.state.header = Some(line);
        }
        Err(e) => {
            w.state.bad_lines += 1;
            let time = w.state.last_time;
            w.alert(
                time,
                "bad_sample",
                json!({"line": line_number, "reason": e.to_string()}),
            )?;
        }
    }
    Ok(())
}

/// A data line read into the watcher's `measured`: skipped when a checkpoint consumed it or a
/// broker sent it twice, bad when it does not parse or its time does not increase.
pub(super) fn seen(
    w: &mut Watcher,
    stream: &Stream,
    header: &Header,
    line: &str,
    position: &mut Position,
) -> Seen {
    let sample = header.0.sample_into(line, &mut w.measured);
    if position.line_number <= position.skip_lines {
        return Seen::Skipped;
    }
    if let (Ok((t, ..)), Some(until)) = (&sample, position.skip_until) {
        if position.this_run == 0 && *t <= until {
            w.state.lines = position.line_number;
            return Seen::Skipped;
        }
    }
    w.state.lines = position.line_number;
    if let (true, Ok((t, ..)), Some(last)) = (stream.from_broker, &sample, w.state.last_time) {
        if *t <= last {
            w.state.duplicates += 1;
            return Seen::Skipped;
        }
    }
    match (sample, w.state.last_time) {
        (Ok((t, _)), Some(last)) if t <= last => {
            Seen::Bad(format!("time {t} does not increase (previous {last})"))
        }
        (Ok((time, excitation)), _) => Seen::Sample(time, excitation),
        (Err(reason), _) => Seen::Bad(reason),
    }
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
