//! Reading a record (a CSV file, or columns in memory) into a [`Measurement`]: its channels in
//! SI, on the nominal sampling grid the times were rounded from.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use ::structure::channel::{
    parse_header_field, split_unit, Channel, ExcitationKind, Quantity, Unit,
};
use ::structure::paper;

use super::grid::{nominal_grid, resolution, GridError};
use super::ColumnMap;

#[derive(Debug, thiserror::Error)]
#[error("{path}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct DataError {
    pub path: PathBuf,
    pub line: Option<u64>,
    pub message: String,
}

/// Columns kept by name beside the channels: the control force a controlled record carries
/// (N), which `twin` replays into a twin that takes one.
pub const EXTRA_COLUMNS: [&str; 1] = ["control"];

/// One measured column: what it measures, the unit it was written in, its values in SI.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    pub channel: Channel,
    pub unit: Unit,
    pub values: Vec<f64>,
}

/// A record: the excitation and the measured responses, in SI, sampled on the grid
/// `time[k] = time[0] + k·dt`.
#[derive(Debug, Clone)]
pub struct Measurement {
    pub path: PathBuf,
    /// The times as written (reports give them back so); without a time column, the grid
    /// from the start time and the rate. The twin steps on the nominal grid
    /// `time[0] + k·dt`, never on these differences.
    pub time: Vec<f64>,
    /// The sampling interval of the nominal grid (recovered from rounded times).
    pub dt: f64,
    /// `force` (N) or `ground_acc` (m/s²).
    pub excitation: Signal,
    /// `acc<i>` (m/s²), `vel<i>` (m/s), `disp<i>` (m), in the order of the file's columns; at
    /// least one.
    pub responses: Vec<Signal>,
    /// Other columns kept by name ([`EXTRA_COLUMNS`]).
    pub extra: HashMap<String, Vec<f64>>,
    /// The file's header line, for messages about its columns (None: not from a file).
    pub header_line: Option<u64>,
}

/// How to read a record beyond its own header.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Header names the file uses for the twin's (`--columns MAP.json`).
    pub columns: ColumnMap,
}

fn acc_channel(floor: usize) -> Channel {
    Channel::Response {
        quantity: Quantity::Acceleration,
        floor,
    }
}

impl Measurement {
    pub fn len(&self) -> usize {
        self.time.len()
    }
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }
    pub fn duration(&self) -> f64 {
        self.dt * (self.len().saturating_sub(1)) as f64
    }

    /// The record's first `n` samples (all of it when shorter), every column cut alike.
    pub fn head(&self, n: usize) -> Measurement {
        self.samples(0..n)
    }

    /// The record's samples `range` (clipped to the record), every column cut alike.
    pub fn samples(&self, range: std::ops::Range<usize>) -> Measurement {
        let end = range.end.min(self.len());
        let start = range.start.min(end);
        let cut = |s: &Signal| Signal {
            channel: s.channel,
            unit: s.unit,
            values: s.values[start..end].to_vec(),
        };
        Measurement {
            path: self.path.clone(),
            time: self.time[start..end].to_vec(),
            dt: self.dt,
            excitation: cut(&self.excitation),
            responses: self.responses.iter().map(cut).collect(),
            extra: self
                .extra
                .iter()
                .map(|(name, values)| {
                    let end = end.min(values.len());
                    (name.clone(), values[start.min(end)..end].to_vec())
                })
                .collect(),
            header_line: self.header_line,
        }
    }

    /// Every channel: the excitation, then the responses.
    pub fn channels(&self) -> impl Iterator<Item = &Signal> {
        std::iter::once(&self.excitation).chain(&self.responses)
    }

    /// A measured channel's values (SI), if the record has it.
    pub fn channel(&self, channel: Channel) -> Option<&[f64]> {
        self.channels()
            .find(|s| s.channel == channel)
            .map(|s| s.values.as_slice())
    }

    /// The record's channels as the paper's rig sees them (`is_paper_rig` of it: a force and an
    /// accelerometer on each of the rig's floors).
    pub fn rig_channels(&self) -> paper::Measured {
        paper::Measured {
            excitation: self.excitation.channel,
            responses: self.responses.iter().map(|s| s.channel).collect(),
        }
    }

    /// Whether the record has what the workflows written for the paper's rig need: a force and
    /// an accelerometer on floors 1 to 3 ([`Measurement::rig_channels`]). Err names the first
    /// missing column.
    pub fn require_paper_rig(&self) -> Result<(), DataError> {
        let err = |message: String| DataError {
            path: self.path.clone(),
            line: self.header_line,
            message,
        };
        match self.rig_channels().missing() {
            None => Ok(()),
            Some(paper::Missing::Force) => Err(err(format!(
                "missing column 'force': this command needs the force; the record is excited \
                 by '{}'",
                self.excitation.channel.name()
            ))),
            Some(paper::Missing::Response(channel)) => Err(err(format!(
                "missing column '{}': this command needs an accelerometer on each of floors 1 \
                 to {}; the record has {}",
                channel.name(),
                paper::STOREYS,
                self.channel_names().join(", ")
            ))),
        }
    }

    /// The channels' names, excitation first.
    pub fn channel_names(&self) -> Vec<String> {
        self.channels().map(|s| s.channel.name()).collect()
    }

    /// The force (N). Panics unless the record is excited by a force, as every record the
    /// paper-rig workflows are given is ([`Measurement::require_paper_rig`]: the commands and the
    /// Python package check it when they read one).
    pub fn force(&self) -> &[f64] {
        self.force_checked();
        &self.excitation.values
    }

    /// Floor `f`'s acceleration (m/s², `f` from 0). Panics when the record has no
    /// `acc{f + 1}` (it has floors 1 to 3's when [`Measurement::require_paper_rig`] holds).
    pub fn acc(&self, f: usize) -> &[f64] {
        self.channel(acc_channel(f + 1))
            .unwrap_or_else(|| panic!("{}: no column acc{}", self.path.display(), f + 1))
    }

    /// The values of `channels`, in their order, when the record measured each of them (the
    /// paper's rig: `structure::paper::channels()`).
    pub fn values_of(&self, channels: &[Channel]) -> Option<Vec<&[f64]>> {
        channels.iter().map(|&c| self.channel(c)).collect()
    }

    /// Floor `f`'s acceleration to change in place (a sensor fault planted by a test).
    pub fn acc_mut(&mut self, f: usize) -> &mut Vec<f64> {
        let path = self.path.display().to_string();
        self.responses
            .iter_mut()
            .find(|s| s.channel == acc_channel(f + 1))
            .map(|s| &mut s.values)
            .unwrap_or_else(|| panic!("{path}: no column acc{}", f + 1))
    }

    /// The force to change in place.
    pub fn force_mut(&mut self) -> &mut Vec<f64> {
        self.force_checked();
        &mut self.excitation.values
    }

    fn force_checked(&self) {
        assert!(
            self.excitation.channel == Channel::Excitation(ExcitationKind::Force),
            "{}: the excitation is '{}', not 'force'",
            self.path.display(),
            self.excitation.channel.name()
        );
    }

    /// A record from named columns in memory (the Python package's arrays), checked as a file
    /// is: names (`name` or `name (unit)`, mapped through `columns`), equal lengths, finite
    /// numbers, at least 2 samples, the times on a uniform grid (taken as written to 1 µs).
    /// `origin` names it in messages (no line numbers: sample indices from 0).
    pub fn from_named_columns(
        origin: &Path,
        named: Vec<(String, Vec<f64>)>,
        columns: &ColumnMap,
    ) -> Result<Self, DataError> {
        let err = |message: String| DataError {
            path: origin.to_owned(),
            line: None,
            message,
        };
        let header: Vec<String> = named.iter().map(|(name, _)| name.clone()).collect();
        let layout = Layout::parse(&header, columns).map_err(err)?;
        let time_index = layout
            .time
            .ok_or_else(|| err("no 'time' column".to_owned()))?;
        let n = named[time_index].1.len();
        for (name, column) in &named {
            if column.len() != n {
                return Err(err(format!(
                    "'{name}' has {} samples, 'time' has {n}",
                    column.len()
                )));
            }
            if let Some(k) = column.iter().position(|v| !v.is_finite()) {
                return Err(err(format!(
                    "'{name}' is {} at sample {k}; only finite numbers are accepted",
                    column[k]
                )));
            }
        }
        if n < 2 {
            return Err(err(format!("{n} samples; at least 2 are needed")));
        }
        let mut columns: Vec<Vec<f64>> = named.into_iter().map(|(_, c)| c).collect();
        // Arrays carry no printed resolution: their times are taken as written to 1 µs.
        let (_, dt) = nominal_grid(&columns[time_index], &vec![1e-6; n])
            .map_err(|e| grid_error(e, |k| err(format!("sample {k}"))))?;
        let (excitation, responses, extra) = layout.take_signals(&mut columns);
        let excitation = excitation.ok_or_else(|| err("no excitation column".to_owned()))?;
        Ok(Measurement {
            path: origin.to_owned(),
            time: std::mem::take(&mut columns[time_index]),
            dt,
            excitation,
            responses,
            extra,
            header_line: None,
        })
    }

    /// A record of a force and floor accelerations from arrays (SI; `acc[f]` floor `f + 1`'s,
    /// the paper's rig: `acc1..acc3`), checked as a file is; `extra` more named columns (e.g.
    /// `control`).
    pub fn from_columns(
        origin: &Path,
        time: Vec<f64>,
        force: Vec<f64>,
        acc: Vec<Vec<f64>>,
        extra: HashMap<String, Vec<f64>>,
    ) -> Result<Self, DataError> {
        let mut named = vec![("time".to_owned(), time), ("force".to_owned(), force)];
        for (f, a) in acc.into_iter().enumerate() {
            named.push((format!("acc{}", f + 1), a));
        }
        let mut extra: Vec<(String, Vec<f64>)> = extra.into_iter().collect();
        extra.sort_by(|a, b| a.0.cmp(&b.0));
        named.extend(extra);
        Self::from_named_columns(origin, named, &ColumnMap::default())
    }
}

/// Read a CSV record (see [`Measurement::read_with`], which dispatches a universal file to
/// [`super::uff`]).
pub(super) fn read_csv(path: &Path, options: &ReadOptions) -> Result<Measurement, DataError> {
    let read = read_file(path, options, true)?;
    let excitation = read.excitation.ok_or_else(|| DataError {
        path: path.to_owned(),
        line: Some(read.header_line),
        message: "missing column 'force' or 'ground_acc'".into(),
    })?;
    Ok(Measurement {
        path: path.to_owned(),
        time: read.time,
        dt: read.dt,
        excitation,
        responses: read.responses,
        extra: read.extra,
        header_line: Some(read.header_line),
    })
}

/// A record of the responses alone, without the excitation: ambient vibration (wind,
/// traffic, microtremor), what a building's permanent monitoring usually measures. Kept apart
/// from [`Measurement`] so that no time-domain comparison can take it: only output-only modal
/// identification does (`workflows::modal::identify_ambient`).
#[derive(Debug, Clone)]
pub struct AmbientRecord {
    pub path: PathBuf,
    pub time: Vec<f64>,
    pub dt: f64,
    pub responses: Vec<Signal>,
    pub header_line: Option<u64>,
}

impl AmbientRecord {
    /// Read a CSV record as [`Measurement::read_with`] does, an excitation column not required
    /// (one the file has is left out).
    pub fn read(path: &Path, options: &ReadOptions) -> Result<Self, DataError> {
        let read = read_file(path, options, false)?;
        Ok(AmbientRecord {
            path: path.to_owned(),
            time: read.time,
            dt: read.dt,
            responses: read.responses,
            header_line: Some(read.header_line),
        })
    }

    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }
}

/// Whether a CSV record's header names an excitation column (`force` or `ground_acc`, after
/// `options.columns`).
pub(super) fn csv_has_excitation(path: &Path, options: &ReadOptions) -> Result<bool, DataError> {
    let err = |line: Option<u64>, message: String| DataError {
        path: path.to_owned(),
        line,
        message,
    };
    // The header is within the file's first MiB (the comments before it are read to 64 KiB).
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 1 << 20), &mut bytes))
        .map_err(|e| err(None, format!("cannot read: {e}")))?;
    let (_, header_line, _, header) = csv_header(path, &bytes)?;
    let layout = Layout::parse_with(&header, &options.columns, false)
        .map_err(|m| err(Some(header_line), m))?;
    Ok(layout.excitation.is_some())
}

/// A CSV record's leading comments, its header's line, the reader after the header, and the
/// header's fields; Err for a file without a header.
fn csv_header<'a>(
    path: &Path,
    bytes: &'a [u8],
) -> Result<(Comments, u64, csv::Reader<&'a [u8]>, Vec<String>), DataError> {
    let err = |line: Option<u64>, message: String| DataError {
        path: path.to_owned(),
        line,
        message,
    };
    let (comments, comment_lines) =
        leading_comments(bytes).map_err(|(line, m)| err(Some(line), m))?;
    let header_line = comment_lines + 1;
    // Fields are trimmed where they are read (the reader's own trimming rebuilt every row: a
    // tenth of reading a record).
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(bytes);
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| err(Some(header_line), format!("bad header: {e}")))?
        .iter()
        .map(|h| h.trim().to_owned())
        .collect();
    if header.iter().all(|h| h.is_empty()) {
        return Err(err(
            Some(header_line),
            format!(
                "missing columns: no header (the paper's header is {})",
                ::structure::paper::header()
            ),
        ));
    }
    Ok((comments, header_line, reader, header))
}

/// A CSV record's columns as read: the excitation None when `require_excitation` is false and
/// the file has none (an ambient record).
struct FileColumns {
    time: Vec<f64>,
    dt: f64,
    excitation: Option<Signal>,
    responses: Vec<Signal>,
    extra: HashMap<String, Vec<f64>>,
    header_line: u64,
}

/// Read a CSV record (see [`Measurement::read_with`]).
fn read_file(
    path: &Path,
    options: &ReadOptions,
    require_excitation: bool,
) -> Result<FileColumns, DataError> {
    let err = |line: Option<u64>, message: String| DataError {
        path: path.to_owned(),
        line,
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| err(None, format!("cannot read: {e}")))?;
    // Line numbers from byte offsets: the csv crate's own line count is off by one on CRLF files.
    let line_at = |p: Option<&csv::Position>| {
        p.map(|p| {
            let mut at = (p.byte() as usize).min(bytes.len());
            // A record's recorded start can sit on the line break before it.
            while at < bytes.len() && (bytes[at] == b'\r' || bytes[at] == b'\n') {
                at += 1;
            }
            1 + bytes[..at].iter().filter(|&&b| b == b'\n').count() as u64
        })
    };
    let (comments, header_line, mut reader, header) = csv_header(path, &bytes)?;
    let layout = Layout::parse_with(&header, &options.columns, require_excitation)
        .map_err(|m| err(Some(header_line), m))?;
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    let mut time_resolution = Vec::new();
    // One record reused for every row (a fresh one per row was a tenth of the read's time).
    let mut record = csv::StringRecord::new();
    while reader
        .read_record(&mut record)
        .map_err(|e| err(line_at(e.position()), format!("malformed row: {e}")))?
    {
        // Worked out only for an error: counting lines is linear in the file.
        let line = || line_at(record.position());
        if record.len() != header.len() {
            return Err(err(
                line(),
                format!("{} fields, the header has {}", record.len(), header.len()),
            ));
        }
        for (i, field) in record.iter().enumerate() {
            let value = parse_value(&header[i], field.trim()).map_err(|m| err(line(), m))?;
            columns[i].push(value);
        }
        if let Some(t) = layout.time {
            time_resolution.push(resolution(&record[t]));
        }
    }
    let n = columns.first().map_or(0, Vec::len);
    if n < 2 {
        return Err(err(None, format!("{n} data rows; at least 2 are needed")));
    }
    let first_data_line = header_line + 1;
    let (t0, dt) = match layout.time {
        Some(t) => {
            if let Some(rate) = comments.rate {
                return Err(err(
                    Some(1),
                    format!("'# rate = {rate}' and a time column: give one or the other"),
                ));
            }
            let time = &columns[t];
            nominal_grid(time, &time_resolution).map_err(|e| {
                grid_error(e, |k| err(Some(first_data_line + k as u64), String::new()))
            })?
        }
        None => {
            let rate = comments.rate.ok_or_else(|| {
                err(
                    Some(header_line),
                    "no 'time' column: give the sample rate in a comment line before the \
                     header, '# rate = <Hz>' (and '# start = <s>' unless it is 0)"
                        .to_owned(),
                )
            })?;
            (comments.start.unwrap_or(0.0), 1.0 / rate)
        }
    };
    let (excitation, responses, extra) = layout.take_signals(&mut columns);
    Ok(FileColumns {
        time: match layout.time {
            Some(t) => std::mem::take(&mut columns[t]),
            None => (0..n).map(|k| t0 + k as f64 * dt).collect(),
        },
        dt,
        excitation,
        responses,
        extra,
        header_line,
    })
}

/// The message of a sampling problem at sample `k`, placed by `at(k)` (a line or a sample).
fn grid_error(e: GridError, at: impl Fn(usize) -> DataError) -> DataError {
    let mut error = at(e.sample);
    error.message = if error.message.is_empty() {
        e.message
    } else {
        format!("{}: {}", error.message, e.message)
    };
    error
}

/// Where each column goes (a file's header, or a stream's: [`super::stream::LineLayout`]).
pub(super) struct Layout {
    pub(super) time: Option<usize>,
    /// None only for an ambient record ([`Layout::parse_with`] not requiring it).
    pub(super) excitation: Option<(usize, Channel, Unit)>,
    pub(super) responses: Vec<(usize, Channel, Unit)>,
    pub(super) extra: Vec<(usize, String)>,
}

impl Layout {
    /// The excitation, the responses (in SI) and the extra columns, taken out of `columns`.
    fn take_signals(
        &self,
        columns: &mut [Vec<f64>],
    ) -> (Option<Signal>, Vec<Signal>, HashMap<String, Vec<f64>>) {
        let mut take = |i: usize, unit: Unit| -> Vec<f64> {
            let mut values = std::mem::take(&mut columns[i]);
            let factor = unit.to_si();
            if factor != 1.0 {
                values.iter_mut().for_each(|v| *v *= factor);
            }
            values
        };
        let excitation = self.excitation.map(|(index, channel, unit)| Signal {
            channel,
            unit,
            values: take(index, unit),
        });
        let responses = self
            .responses
            .iter()
            .map(|&(i, channel, unit)| Signal {
                channel,
                unit,
                values: take(i, unit),
            })
            .collect();
        let extra = self
            .extra
            .iter()
            .map(|(i, name)| (name.clone(), std::mem::take(&mut columns[*i])))
            .collect();
        (excitation, responses, extra)
    }

    pub(super) fn parse(header: &[String], map: &ColumnMap) -> Result<Layout, String> {
        Self::parse_with(header, map, true)
    }

    /// As [`Layout::parse`]; without `require_excitation` a header with no excitation column
    /// is taken (an ambient record).
    pub(super) fn parse_with(
        header: &[String],
        map: &ColumnMap,
        require_excitation: bool,
    ) -> Result<Layout, String> {
        let mut time = None;
        let mut excitation: Option<(usize, Channel, Unit)> = None;
        let mut responses: Vec<(usize, Channel, Unit)> = Vec::new();
        let mut extra = Vec::new();
        let mut seen: BTreeMap<String, &str> = BTreeMap::new();
        for (i, field) in header.iter().enumerate() {
            let named = map.apply(field);
            let (name, _) = split_unit(&named);
            if EXTRA_COLUMNS.contains(&name) {
                if seen.insert(name.to_owned(), field).is_some() {
                    return Err(format!("column '{name}' appears twice"));
                }
                extra.push((i, name.to_owned()));
                continue;
            }
            let (channel, unit) = parse_header_field(&named).map_err(|e| {
                if named == *field {
                    e.to_string()
                } else {
                    format!("{e} (mapped from '{field}')")
                }
            })?;
            if let Some(first) = seen.insert(channel.name(), field) {
                return Err(if first == field {
                    format!("column '{field}' appears twice")
                } else {
                    format!(
                        "columns '{first}' and '{field}' are both '{}'",
                        channel.name()
                    )
                });
            }
            match channel {
                Channel::Time => time = Some(i),
                Channel::Excitation(_) => {
                    if let Some((_, other, _)) = excitation {
                        return Err(format!(
                            "columns '{}' and '{field}': a record has one excitation, \
                             'force' or 'ground_acc'",
                            other.name()
                        ));
                    }
                    excitation = Some((i, channel, unit));
                }
                Channel::Response { .. } => responses.push((i, channel, unit)),
            }
        }
        if excitation.is_none() && require_excitation {
            return Err(format!(
                "missing column 'force' or 'ground_acc' (the excitation; the paper's header is {})",
                ::structure::paper::header()
            ));
        }
        if responses.is_empty() {
            return Err(format!(
                "no response column: at least one of acc<i>, vel<i>, disp<i> (the paper's header is {})",
                ::structure::paper::header()
            ));
        }
        Ok(Layout {
            time,
            excitation,
            responses,
            extra,
        })
    }
}

/// What the comment lines before the header say.
#[derive(Debug, Default)]
struct Comments {
    rate: Option<f64>,
    start: Option<f64>,
}

/// The `#` lines (and blank lines) before the header: `# rate = 1000` (Hz), `# start = 12.5`
/// (s); other comments are free text. Returns them and how many lines they take.
fn leading_comments(bytes: &[u8]) -> Result<(Comments, u64), (u64, String)> {
    // Line by line up to the first that is neither blank nor a comment: only those lines are
    // made text (the whole first 64 kB made text was a tenth of reading a 1,024-sample record).
    let mut comments = Comments::default();
    let mut lines = 0;
    for line in bytes[..bytes.len().min(64 * 1024)].split_inclusive(|b| *b == b'\n') {
        let line = String::from_utf8_lossy(line);
        let trimmed = line.trim();
        if !(trimmed.is_empty() || trimmed.starts_with('#')) {
            break;
        }
        lines += 1;
        let Some(body) = trimmed.strip_prefix('#') else {
            continue;
        };
        let Some((key, value)) = body.split_once(['=', ':']) else {
            continue;
        };
        let key = key.trim().to_ascii_lowercase();
        let value = value.trim();
        let number = |unit: &str| -> Result<f64, (u64, String)> {
            let text = value.strip_suffix(unit).unwrap_or(value).trim();
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| (lines, format!("'# {key} = {value}' is not a number")))
        };
        match key.as_str() {
            "rate" => {
                let rate = number("Hz")?;
                if rate <= 0.0 {
                    return Err((
                        lines,
                        format!("'# rate = {value}': the rate must be positive"),
                    ));
                }
                comments.rate = Some(rate);
            }
            "start" => comments.start = Some(number("s")?),
            _ => {}
        }
    }
    Ok((comments, lines))
}

/// One field of column `name` as a finite number, or why it is not one.
pub(super) fn parse_value(name: &str, field: &str) -> Result<f64, String> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(format!("'{name}' is {v}; only finite numbers are accepted")),
        Err(_) => Err(format!("'{name}' is not a number: '{field}'")),
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use ::structure::channel::Channel;
    use std::io::Write;

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().expect("temp");
        f.write_all(text.as_bytes()).expect("write");
        f
    }

    #[test]
    fn reads_the_bundled_example_exactly_on_its_grid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/dataset1.csv");
        let m = Measurement::read(&path).expect("example reads");
        assert_eq!(m.len(), 1024);
        assert_eq!(m.dt, 1.0 / 51.2);
        assert!((m.duration() - 1023.0 / 51.2).abs() < 1e-12);
    }

    #[test]
    fn keeps_extra_columns() {
        let f = file("time,force,acc1,acc2,acc3,control\n0,1,2,3,4,5\n0.5,1,2,3,4,6\n");
        let m = Measurement::read(f.path()).expect("reads");
        assert_eq!(m.extra["control"], vec![5.0, 6.0]);
        assert_eq!(m.dt, 0.5);
    }

    #[test]
    fn refuses_bad_files_naming_file_line_and_problem() {
        let cases = [
            (
                "time,acc1,acc2\n0,1,2\n1,1,2\n",
                Some(1),
                "missing column 'force' or 'ground_acc'",
            ),
            ("time,force\n0,1\n1,1\n", Some(1), "no response column"),
            (
                "time,force,acc1,speed\n0,1,2,3\n1,1,2,3\n",
                Some(1),
                "column 'speed'",
            ),
            (
                "time,force,acc1 (furlong/s2)\n0,1,2\n1,1,2\n",
                Some(1),
                "unknown unit 'furlong/s2'",
            ),
            (
                "time,force,acc1 (mm/s)\n0,1,2\n1,1,2\n",
                Some(1),
                "not one of a",
            ),
            (
                "time,force,acc1,acc1\n0,1,2,2\n1,1,2,2\n",
                Some(1),
                "appears twice",
            ),
            ("force,acc1\n0,1\n1,1\n", Some(1), "# rate"),
            (
                "time,force,acc1,acc2,acc3\n0,1,2,3,4\n1,1,NaN,3,4\n",
                Some(3),
                "only finite",
            ),
            (
                "time,force,acc1,acc2,acc3\n0,1,2,3,4\n1,1,x,3,4\n",
                Some(3),
                "not a number",
            ),
            (
                "time,force,acc1,acc2,acc3\n0,1,2,3,4\n1,1,2,3,4\n0.5,1,2,3,4\n",
                Some(4),
                "does not increase",
            ),
            (
                "time,force,acc1,acc2,acc3\n0,1,2,3,4\n1,1,2,3,4\n3,1,2,3,4\n",
                Some(3),
                "non-uniform",
            ),
            ("time,force,acc1,acc2,acc3\n", None, "0 data rows"),
            ("", None, "missing column"),
            ("time,force,acc1,acc2,acc3\n0,1,2,3\n", Some(2), "fields"),
            (
                "time,force,acc1,acc2,acc3\r\n0,1,0,0,0\r\n0.5,NaN,2,3,4\r\n1,1,2,3,4\r\n",
                Some(3),
                "only finite",
            ),
        ];
        for (text, line, needle) in cases {
            let f = file(text);
            let e = Measurement::read(f.path()).expect_err(needle);
            let shown = e.to_string();
            assert!(shown.contains(needle), "{needle}: {shown}");
            assert!(
                shown.contains(&f.path().display().to_string()),
                "names the file: {shown}"
            );
            if let Some(l) = line {
                assert_eq!(e.line, Some(l), "{shown}");
            }
        }
    }

    #[test]
    fn units_are_converted_to_si() {
        let f = file("time,force (kN),acc1 (g),vel2 (mm/s),disp3 (mm)\n0,1,1,1,1\n0.5,2,2,2,2\n");
        let m = Measurement::read(f.path()).expect("reads");
        assert_eq!(m.excitation.values, vec![1e3, 2e3]);
        assert_eq!(m.excitation.unit, Unit::KiloNewton);
        let value = |name: &str| m.channel(Channel::parse(name).expect("name")).expect(name)[1];
        assert_eq!(value("acc1"), 2.0 * 9.80665);
        assert_eq!(value("vel2"), 2e-3);
        assert_eq!(value("disp3"), 2e-3);
    }

    #[test]
    fn a_column_map_renames_and_keeps_or_sets_units() {
        let f = file("t,fp (N),dotx1 (mm/s),ag\n0,1,1,1\n0.5,2,2,2\n");
        let map: BTreeMap<String, String> = [
            ("t", "time"),
            ("fp (N)", "force"),
            ("dotx1", "vel1"),
            ("ag", "acc2 (g)"),
        ]
        .into_iter()
        .map(|(a, b)| (a.to_owned(), b.to_owned()))
        .collect();
        let columns = ColumnMap::new(map).expect("map");
        let m = Measurement::read_with(f.path(), &ReadOptions { columns }).expect("reads");
        assert_eq!(m.channel_names(), ["force", "vel1", "acc2"]);
        assert_eq!(m.responses[0].values, vec![1e-3, 2e-3]);
        assert_eq!(m.responses[1].values, vec![9.80665, 2.0 * 9.80665]);
        let bad = ColumnMap::new([("x".to_owned(), "speed".to_owned())].into()).expect_err("bad");
        assert!(bad.contains("'speed'"), "{bad}");
    }

    #[test]
    fn a_subset_with_ground_motion_reads_and_is_refused_where_the_rig_is_needed() {
        let f = file("time,ground_acc (g),acc3\n0,0.1,1\n0.01,0.2,2\n0.02,0.1,1\n");
        let m = Measurement::read(f.path()).expect("reads");
        assert_eq!(m.channel_names(), ["ground_acc", "acc3"]);
        let e = m.require_paper_rig().expect_err("no force");
        assert!(e.to_string().contains("'force'"), "{e}");
        let f = file("time,force,acc1,acc3\n0,0.1,1,1\n0.01,0.2,2,2\n");
        let e = Measurement::read(f.path())
            .expect("reads")
            .require_paper_rig()
            .expect_err("no acc2");
        assert!(e.to_string().contains("'acc2'"), "{e}");
    }

    #[test]
    fn a_start_and_a_rate_stand_for_the_time_column() {
        let f = file("# logger 7\n# rate = 1000 Hz\n# start = 12.5\nforce,acc1\n1,2\n3,4\n5,6\n");
        let m = Measurement::read(f.path()).expect("reads");
        assert_eq!(m.dt, 1e-3);
        assert_eq!(m.time, vec![12.5, 12.5 + 1e-3, 12.5 + 2e-3]);
        // Lines are counted from the file's first, comments included.
        let f = file("# rate = 10\nforce,acc1\n1,2\n3,x\n");
        let e = Measurement::read(f.path()).expect_err("bad value");
        assert_eq!(e.line, Some(4), "{e}");
    }

    #[test]
    fn times_rounded_to_a_millisecond_step_on_the_exact_grid() {
        let mut text = String::from("time,force,acc1\n");
        for k in 0..5000 {
            text.push_str(&format!("{:.3},1,2\n", 12.0 + k as f64 / 51.2));
        }
        let m = Measurement::read(file(&text).path()).expect("reads");
        assert_eq!(m.dt, 1.0 / 51.2);
        // The times stay as written; the grid the twin steps on is time[0] + k·dt.
        assert_eq!(m.time[4999], 109.637);
        assert_eq!(m.time[0] + 4999.0 * m.dt, 12.0 + 4999.0 * (1.0 / 51.2));
    }

    #[test]
    fn irregular_sampling_is_refused_naming_the_line() {
        let mut text = String::from("# a comment\ntime,force,acc1\n");
        for k in 0..100 {
            let t = k as f64 * 0.01 + if k == 60 { 0.003 } else { 0.0 };
            text.push_str(&format!("{t:.6},1,2\n"));
        }
        let f = file(&text);
        let e = Measurement::read(f.path()).expect_err("irregular");
        assert_eq!(e.line, Some(63), "{e}");
        assert!(e.to_string().contains("non-uniform"), "{e}");
    }
}
