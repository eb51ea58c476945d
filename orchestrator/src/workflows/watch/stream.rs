//! Reading the stream: its lines (standard input, a growing file, an MQTT topic), the header
//! checked against the twin's structure, the opening of a resumed or broker stream, and the
//! loop over its samples ([`read_stream`]) with their gaps and duplicates.

use super::alerts::Latency;
use super::checkpoint::State;
use super::mqtt::{ConnectionEvent, MqttSource};
use super::observe::{status, Status};
use super::options::{StreamSource, WatchOptions};
use super::watcher::{structure_excitation, Watcher};
use super::{io, WatchError};
use crate::record::{default_header, ColumnMap, LineLayout};
use ::structure::channel::Channel;
use serde_json::json;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::time::{Duration, Instant};

pub(super) const POLL: Duration = Duration::from_millis(100);

/// Lines of the stream: from standard input or a file (a partial last line of a growing file
/// held until it is complete), or from an MQTT topic's messages.
pub(super) enum LineReader {
    Text {
        reader: Box<dyn BufRead>,
        follow: Option<Duration>,
        partial: String,
    },
    Mqtt(Box<MqttSource>),
}

impl LineReader {
    pub(super) fn open(source: &StreamSource) -> Result<Self, WatchError> {
        Ok(match source {
            StreamSource::Stdin => LineReader::Text {
                reader: Box::new(BufReader::new(std::io::stdin())),
                follow: None,
                partial: String::new(),
            },
            StreamSource::File { path, follow, idle } => LineReader::Text {
                reader: Box::new(BufReader::new(
                    File::open(path).map_err(io(format!("cannot open {}", path.display())))?,
                )),
                follow: follow.then_some(*idle),
                partial: String::new(),
            },
            StreamSource::Mqtt {
                url,
                client_id,
                idle,
            } => LineReader::Mqtt(Box::new(MqttSource::open(
                url.clone(),
                client_id.clone(),
                *idle,
            )?)),
        })
    }

    pub(super) fn mqtt(&mut self) -> Option<&mut MqttSource> {
        match self {
            LineReader::Mqtt(m) => Some(m),
            LineReader::Text { .. } => None,
        }
    }

    /// The next line without its line break; None at the end.
    pub(super) fn next(&mut self) -> Result<Option<String>, WatchError> {
        let (reader, follow, partial) = match self {
            LineReader::Mqtt(m) => return m.next_line(),
            LineReader::Text {
                reader,
                follow,
                partial,
            } => (reader, follow, partial),
        };
        let mut idle_since = Instant::now();
        loop {
            let n = reader
                .read_line(partial)
                .map_err(io("cannot read the stream"))?;
            if partial.ends_with('\n') {
                let line = std::mem::take(partial);
                return Ok(Some(line.trim_end_matches(['\n', '\r']).to_owned()));
            }
            if n > 0 {
                idle_since = Instant::now();
            }
            match follow {
                Some(idle) if idle_since.elapsed() < *idle => std::thread::sleep(POLL),
                _ => {
                    // The end: a last line without a line break still counts.
                    return Ok((!partial.is_empty())
                        .then(|| std::mem::take(partial).trim_end_matches('\r').to_owned()));
                }
            }
        }
    }
}

/// The stream's columns, as the record module reads a header line, checked against the twin:
/// its excitation the one the structure takes, every response a channel of a floor it has.
pub(super) struct Header(pub(super) LineLayout);

impl Header {
    pub(super) fn parse(
        line: &str,
        columns: &ColumnMap,
        structure: &::structure::Structure,
        twin: &str,
    ) -> Result<Self, String> {
        let layout = LineLayout::parse_with(line, columns)?;
        for channel in
            std::iter::once(layout.excitation()).chain(layout.responses().iter().copied())
        {
            channel.check(&channel.name(), structure).map_err(|e| {
                format!(
                    "{e} (the twin: {twin}, {} storey(s) under {})",
                    structure.storeys(),
                    structure.excitation.describe()
                )
            })?;
        }
        Ok(Header(layout))
    }

    /// The stream's columns: the same excitation, the channels in `channels`' order.
    pub(super) fn for_stream(
        self,
        excitation: Channel,
        channels: &[Channel],
    ) -> Result<Self, String> {
        if self.0.excitation() != excitation {
            return Err(format!(
                "the header's excitation '{}' is not the stream's '{}'",
                self.0.excitation().name(),
                excitation.name()
            ));
        }
        self.0.in_order(channels).map(Header)
    }
}

/// The stream's header and its channels: its first header's, or those of the run a checkpoint
/// saved (a header that does not fit them: the checkpoint was made on another stream).
pub(super) fn stream_header(
    header_line: &str,
    options: &WatchOptions,
    structure: &::structure::Structure,
    describe: &str,
    saved: Option<&State>,
) -> Result<(Header, Channel, Vec<Channel>), WatchError> {
    let header = Header::parse(header_line, &options.columns, structure, describe)
        .map_err(WatchError::Header)?;
    let (excitation, channels) = match saved {
        Some(state) => (state.excitation, state.channels.clone()),
        None => (header.0.excitation(), header.0.responses().to_vec()),
    };
    let header = header
        .for_stream(excitation, &channels)
        .map_err(|message| match &options.checkpoint {
            Some(path) => WatchError::BadCheckpoint {
                path: path.clone(),
                message: format!("made on another stream: {message}"),
            },
            None => WatchError::Header(message),
        })?;
    Ok((header, excitation, channels))
}

/// The stream's opening: its header line, the broker's connection events before it, and a
/// first line read past it (an MQTT stream's first sample).
pub(super) struct Opening {
    pub(super) header_line: String,
    pub(super) early_events: Vec<ConnectionEvent>,
    pub(super) pushed_back: Option<String>,
}

/// The header: a file or standard input starts with its own; an MQTT stream's is the one its
/// last run saw (`saved`), else its first line if that is a header, else time, the excitation
/// and an accelerometer on every floor (the paper rig's `time,force,acc1,acc2,acc3`).
pub(super) fn opening(
    reader: &mut LineReader,
    saved: Option<&State>,
    structure: &::structure::Structure,
) -> Result<Opening, WatchError> {
    let mut early_events = Vec::new();
    let mut pushed_back = None;
    let header_line = if matches!(reader, LineReader::Mqtt(_)) {
        match saved.and_then(|s| s.header.clone()) {
            Some(h) => h,
            None => loop {
                match reader.next()? {
                    None => {
                        break default_header(structure_excitation(structure), structure.storeys())
                    }
                    Some(line) if line.trim().is_empty() => {
                        if let Some(m) = reader.mqtt() {
                            early_events.extend(m.take_events());
                        }
                    }
                    Some(line) => {
                        let header = is_header(&line).then(|| line.clone());
                        pushed_back = Some(line);
                        break header.unwrap_or_else(|| {
                            default_header(structure_excitation(structure), structure.storeys())
                        });
                    }
                }
            },
        }
    } else {
        loop {
            match reader.next()? {
                None => return Err(WatchError::Header("the stream is empty".into())),
                Some(line) if line.trim().is_empty() => continue,
                Some(line) => break line,
            }
        }
    };
    Ok(Opening {
        header_line,
        early_events,
        pushed_back,
    })
}

/// What the stream is read against: the structure and twin its headers are checked with, its
/// channels, and where it comes from.
pub(super) struct Stream<'s> {
    pub(super) structure: &'s ::structure::Structure,
    pub(super) describe: &'s str,
    pub(super) excitation: Channel,
    pub(super) channels: &'s [Channel],
    pub(super) from_broker: bool,
    /// A followed file or a broker: the time spent waiting for it is left out of the speed.
    pub(super) live: bool,
}

/// What reading the stream measured: this run's samples and their latencies, when it began
/// and how long it waited for a live source.
pub(super) struct Run {
    pub(super) samples: u64,
    pub(super) latency: Latency,
    pub(super) started: Instant,
    pub(super) waited: Duration,
}

impl Run {
    /// Seconds spent on the samples, the waits for a live source left out.
    pub(super) fn seconds(&self) -> f64 {
        self.started
            .elapsed()
            .saturating_sub(self.waited)
            .as_secs_f64()
    }
}

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

/// Whether a line of an MQTT stream is a header (it starts with a letter, as a column name
/// does and a time does not).
pub(super) fn is_header(line: &str) -> bool {
    line.trim_start()
        .starts_with(|c: char| c.is_ascii_alphabetic())
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
