//! Reading the stream: its lines (standard input, a growing file, an MQTT topic), the header
//! checked against the twin's structure, the opening of a resumed or broker stream, and what
//! reading it measured ([`Run`]). The loop over its samples is [`super::run`]'s.

use super::alerts::Latency;
use super::checkpoint::State;
use super::mqtt::{ConnectionEvent, MqttSource};
use super::options::{StreamSource, WatchOptions};
use super::{io, WatchError};
use crate::record::{default_header, ColumnMap, LineLayout};
use ::structure::channel::Channel;
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

/// Whether a line of an MQTT stream is a header (it starts with a letter, as a column name
/// does and a time does not).
pub(super) fn is_header(line: &str) -> bool {
    line.trim_start()
        .starts_with(|c: char| c.is_ascii_alphabetic())
}

/// The excitation column of `structure`: `force` or `ground_acc`.
pub(super) fn structure_excitation(structure: &::structure::Structure) -> Channel {
    Channel::Excitation(::structure::channel::ExcitationKind::of(
        &structure.excitation,
    ))
}
