//! A measured frequency response as data: a CSV of `frequency` (Hz) and, per measured channel,
//! either `<ch>_re,<ch>_im` (complex, per unit of the excitation: accelerance for `acc<i>`,
//! mobility for `vel<i>`, receptance for `disp<i>`, SI — per N for a force, per m/s² for ground
//! motion) or `<ch>_db` (magnitude in dB re 1 SI unit per unit excitation). A complex column may
//! name its unit as `response/excitation`, `acc1_re (g/N)`, `disp2_im (mm/kN)`; a dB column only
//! `(dB)`. Header names are mapped through the record reader's [`ColumnMap`] first. Universal
//! files (dataset 58) are read by [`super::uff`] into the same [`MeasuredFrf`].

use std::path::{Path, PathBuf};

use ::structure::channel::{split_unit, Channel, Quantity, Unit};
use rustfft::num_complex::Complex;

use super::read::parse_value;
use super::{ColumnMap, DataError};

/// One measured channel's frequency response.
#[derive(Debug, Clone, PartialEq)]
pub enum FrfValues {
    /// Complex, SI per unit excitation.
    Complex(Vec<Complex<f64>>),
    /// Magnitude only, dB re 1 SI unit per unit excitation (when the file's reference is
    /// known; see [`MeasuredFrf`]).
    Db(Vec<f64>),
}

impl FrfValues {
    /// 20 log10 |H| at every frequency.
    pub fn magnitude_db(&self) -> Vec<f64> {
        match self {
            FrfValues::Complex(h) => h.iter().map(|h| db(h.norm())).collect(),
            FrfValues::Db(v) => v.clone(),
        }
    }
    /// The phase (rad) where the file gives it.
    pub fn phase(&self) -> Option<Vec<f64>> {
        match self {
            FrfValues::Complex(h) => Some(h.iter().map(|h| h.arg()).collect()),
            FrfValues::Db(_) => None,
        }
    }
}

/// `20 log10 x`, with zero held at −600 dB rather than −∞.
pub fn db(magnitude: f64) -> f64 {
    20.0 * magnitude.max(1e-30).log10()
}

#[derive(Debug, Clone, PartialEq)]
pub struct FrfChannel {
    /// `acc<i>`, `vel<i>` or `disp<i>`.
    pub channel: Channel,
    pub values: FrfValues,
}

/// A measured FRF: every channel on one frequency grid.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredFrf {
    pub path: PathBuf,
    /// Hz, strictly increasing, non-negative.
    pub frequency: Vec<f64>,
    pub channels: Vec<FrfChannel>,
}

impl MeasuredFrf {
    pub fn channel_names(&self) -> Vec<String> {
        self.channels.iter().map(|c| c.channel.name()).collect()
    }
}

/// Which part of a channel's FRF a column holds.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Part {
    Re,
    Im,
    Db,
}

/// Whether `name` (no unit) is a column of an FRF file: `frequency` or `<channel>_re|_im|_db`.
pub(crate) fn is_frf_column(name: &str) -> bool {
    name == "frequency" || split_part(name).is_some()
}

fn split_part(name: &str) -> Option<(Channel, Part)> {
    let (base, part) = name.rsplit_once('_')?;
    let part = match part {
        "re" => Part::Re,
        "im" => Part::Im,
        "db" => Part::Db,
        _ => return None,
    };
    match Channel::parse(base)? {
        c @ Channel::Response { .. } => Some((c, part)),
        _ => None,
    }
}

/// The SI factor of a complex FRF column's unit `response/excitation` (`g/N`, `m/s2/kN`);
/// the response's quantity must be the channel's.
pub(crate) fn ratio_factor(channel: &Channel, unit: &str) -> Result<f64, String> {
    let (response, excitation) = unit.rsplit_once('/').ok_or_else(|| {
        format!(
            "unit '{unit}' of '{}': give response/excitation, e.g. m/s2/N",
            channel.name()
        )
    })?;
    let response_unit = Unit::parse(response.trim())
        .filter(|u| u.quantity() == channel.quantity())
        .ok_or_else(|| {
            format!(
                "unit '{unit}' of '{}': '{response}' is not a unit of {}",
                channel.name(),
                channel.quantity().si().symbol()
            )
        })?;
    let excitation_unit = Unit::parse(excitation.trim())
        .filter(|u| matches!(u.quantity(), Quantity::Force | Quantity::Acceleration))
        .ok_or_else(|| {
            format!(
                "unit '{unit}' of '{}': '{excitation}' is not a unit of force (N) or of ground \
                 acceleration (m/s2)",
                channel.name()
            )
        })?;
    Ok(response_unit.to_si() / excitation_unit.to_si())
}

/// Check the grid and the columns gathered per channel, for either reader.
pub(crate) fn check_frequency(frequency: &[f64]) -> Result<(), (usize, String)> {
    if frequency.len() < 2 {
        return Err((
            0,
            format!("{} frequencies; at least 2 are needed", frequency.len()),
        ));
    }
    for (k, f) in frequency.iter().enumerate() {
        if *f < 0.0 {
            return Err((k, format!("frequency {f} Hz is negative")));
        }
        if k > 0 && *f <= frequency[k - 1] {
            return Err((
                k,
                format!(
                    "frequency {f} Hz does not increase (after {} Hz)",
                    frequency[k - 1]
                ),
            ));
        }
    }
    Ok(())
}

/// Per header field: None for the frequency, else its channel, part and SI factor.
type FieldLayout = Vec<Option<(Channel, Part, f64)>>;

/// The header's fields read: which is the frequency and what each other one holds. Err: the
/// message about a field (named as written and as mapped).
fn header_layout(
    fields: &[String],
    columns: &ColumnMap,
) -> Result<(Option<usize>, FieldLayout), String> {
    let mut frequency_column = None;
    let mut layout: FieldLayout = Vec::with_capacity(fields.len());
    for (i, field) in fields.iter().enumerate() {
        let mapped = columns.apply(field);
        let (name, unit) = split_unit(&mapped);
        let at = |m: String| {
            let shown = if mapped == *field {
                format!("column '{field}'")
            } else {
                format!("column '{field}' (mapped to '{mapped}')")
            };
            format!("{shown}: {m}")
        };
        if name == "frequency" {
            if unit.is_some_and(|u| u != "Hz") {
                return Err(at("the frequency is read in Hz".into()));
            }
            if frequency_column.replace(i).is_some() {
                return Err(at("a second frequency column".into()));
            }
            layout.push(None);
            continue;
        }
        let (channel, part) =
            split_part(name).ok_or_else(|| {
                at("not an FRF column: frequency, or <channel>_re, <channel>_im, <channel>_db for \
                a channel acc<i>, vel<i>, disp<i>"
                .into())
            })?;
        let factor = match (part, unit) {
            (_, None) => 1.0,
            (Part::Db, Some("dB")) => 1.0,
            (Part::Db, Some(u)) => {
                return Err(at(format!(
                    "unit '{u}': a magnitude column is in dB re 1 SI unit per unit excitation"
                )))
            }
            (_, Some(u)) => ratio_factor(&channel, u).map_err(at)?,
        };
        if layout
            .iter()
            .flatten()
            .any(|(c, p, _)| *c == channel && *p == part)
        {
            return Err(at("appears twice".into()));
        }
        layout.push(Some((channel, part, factor)));
    }
    Ok((frequency_column, layout))
}

/// The channels in the order of their first column, each with its parts, each complete
/// (`_re` and `_im`, or `_db`).
fn channel_parts(layout: &FieldLayout) -> Result<Vec<(Channel, Vec<Part>)>, String> {
    let mut channels: Vec<(Channel, Vec<Part>)> = Vec::new();
    for (channel, part, _) in layout.iter().flatten() {
        match channels.iter_mut().find(|(c, _)| c == channel) {
            Some((_, parts)) => parts.push(*part),
            None => channels.push((*channel, vec![*part])),
        }
    }
    if channels.is_empty() {
        return Err("no response column: <channel>_re,<channel>_im or <channel>_db".into());
    }
    for (channel, parts) in &channels {
        let name = channel.name();
        let complex = parts.contains(&Part::Re) || parts.contains(&Part::Im);
        if complex && parts.contains(&Part::Db) {
            return Err(format!(
                "'{name}' has both complex and dB columns: give one or the other"
            ));
        }
        if complex && !(parts.contains(&Part::Re) && parts.contains(&Part::Im)) {
            return Err(format!("'{name}' needs both {name}_re and {name}_im"));
        }
    }
    Ok(channels)
}

/// The data rows' values per field (SI), and each row's line.
type Rows = (Vec<Vec<f64>>, Vec<u64>);

/// The data rows read. Err: (line, message).
fn read_rows<'a>(
    lines: impl Iterator<Item = (u64, &'a str)>,
    fields: &[String],
    layout: &FieldLayout,
) -> Result<Rows, (u64, String)> {
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); fields.len()];
    let mut lines_of_rows = Vec::new();
    for (line, row) in lines {
        let cells: Vec<&str> = row.split(',').map(str::trim).collect();
        if cells.len() != fields.len() {
            return Err((
                line,
                format!("{} fields, the header has {}", cells.len(), fields.len()),
            ));
        }
        for (i, cell) in cells.iter().enumerate() {
            let v = parse_value(&fields[i], cell).map_err(|m| (line, m))?;
            let factor = layout[i].map_or(1.0, |(_, _, f)| f);
            values[i].push(v * factor);
        }
        lines_of_rows.push(line);
    }
    Ok((values, lines_of_rows))
}

/// Each channel's FRF from its columns' values: its dB magnitude, or its complex ratio.
fn assemble(
    channels: Vec<(Channel, Vec<Part>)>,
    layout: &FieldLayout,
    values: &[Vec<f64>],
) -> Vec<FrfChannel> {
    let column = |channel: Channel, part: Part| {
        layout
            .iter()
            .position(|l| matches!(l, Some((c, p, _)) if *c == channel && *p == part))
    };
    channels
        .into_iter()
        .map(|(channel, parts)| {
            let values = if parts.contains(&Part::Db) {
                FrfValues::Db(
                    column(channel, Part::Db)
                        .map(|i| values[i].clone())
                        .unwrap_or_default(),
                )
            } else {
                let (re, im) = (column(channel, Part::Re), column(channel, Part::Im));
                let (re, im) = (re.map(|i| &values[i]), im.map(|i| &values[i]));
                FrfValues::Complex(match (re, im) {
                    (Some(re), Some(im)) => re
                        .iter()
                        .zip(im)
                        .map(|(a, b)| Complex::new(*a, *b))
                        .collect(),
                    _ => Vec::new(),
                })
            };
            FrfChannel { channel, values }
        })
        .collect()
}

/// A measured FRF's CSV: its header (the frequency and each channel's parts), its rows, the
/// frequencies checked, each channel assembled.
pub(super) fn read_csv(path: &Path, columns: &ColumnMap) -> Result<MeasuredFrf, DataError> {
    let err = |line: Option<u64>, message: String| DataError {
        path: path.to_owned(),
        line,
        message,
    };
    let text = std::fs::read_to_string(path).map_err(|e| err(None, format!("cannot read: {e}")))?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i as u64 + 1, l.trim()))
        .filter(|(_, l)| !(l.is_empty() || l.starts_with('#')));
    let (header_line, header) = lines.next().ok_or_else(|| {
        err(
            None,
            "empty: no header (frequency,<ch>_re,<ch>_im or <ch>_db)".into(),
        )
    })?;
    let at_header = |m: String| err(Some(header_line), m);
    let fields: Vec<String> = header.split(',').map(|f| f.trim().to_owned()).collect();
    let (frequency_column, layout) = header_layout(&fields, columns).map_err(at_header)?;
    let frequency_column = frequency_column
        .ok_or_else(|| err(Some(header_line), "missing column 'frequency' (Hz)".into()))?;
    let channels = channel_parts(&layout).map_err(at_header)?;
    let (mut values, lines_of_rows) =
        read_rows(lines, &fields, &layout).map_err(|(line, m)| err(Some(line), m))?;
    let frequency = std::mem::take(&mut values[frequency_column]);
    check_frequency(&frequency)
        .map_err(|(k, m)| err(lines_of_rows.get(k).copied().or(Some(header_line)), m))?;
    Ok(MeasuredFrf {
        path: path.to_owned(),
        frequency,
        channels: assemble(channels, &layout, &values),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new()
            .suffix(".csv")
            .tempfile()
            .expect("temp");
        f.write_all(text.as_bytes()).expect("write");
        f
    }

    #[test]
    fn reads_complex_and_db_columns_in_si() {
        let f = file("# an FRF\nfrequency (Hz),acc1_re (g/N),acc1_im (g/N),disp2_db\n1,1,2,-40\n2,0.5,0,-50\n");
        let m = MeasuredFrf::read(f.path(), &ColumnMap::default()).expect("reads");
        assert_eq!(m.frequency, vec![1.0, 2.0]);
        assert_eq!(m.channel_names(), ["acc1", "disp2"]);
        let FrfValues::Complex(h) = &m.channels[0].values else {
            panic!("complex")
        };
        assert_eq!(h[0], Complex::new(9.80665, 2.0 * 9.80665));
        assert_eq!(m.channels[1].values, FrfValues::Db(vec![-40.0, -50.0]));
    }

    #[test]
    fn the_bundled_measured_frf_reads() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/frf/swansea-3storey-frf.csv");
        let m = MeasuredFrf::read(&path, &ColumnMap::default()).expect("reads");
        assert_eq!(m.channel_names(), ["acc1", "acc2", "acc3"]);
        assert_eq!(m.frequency.len(), 801);
        assert_eq!(m.frequency[800], 100.0);
    }

    #[test]
    fn a_column_map_renames_frf_columns() {
        let f = file("f,H11 re,H11 im\n1,1,2\n2,3,4\n");
        let map = ColumnMap::new(
            [
                ("f", "frequency"),
                ("H11 re", "acc1_re"),
                ("H11 im", "acc1_im"),
            ]
            .into_iter()
            .map(|(a, b)| (a.to_owned(), b.to_owned()))
            .collect(),
        )
        .expect("map");
        let m = MeasuredFrf::read(f.path(), &map).expect("reads");
        assert_eq!(m.channel_names(), ["acc1"]);
    }

    #[test]
    fn refuses_bad_files_naming_file_line_and_problem() {
        let cases = [
            ("acc1_db\n1\n2\n", 1, "missing column 'frequency'"),
            (
                "frequency,acc1_re\n1,2\n2,3\n",
                1,
                "needs both acc1_re and acc1_im",
            ),
            (
                "frequency,acc1_re,acc1_im,acc1_db\n1,2,3,4\n2,3,4,5\n",
                1,
                "both complex and dB",
            ),
            ("frequency,speed_db\n1,2\n2,3\n", 1, "not an FRF column"),
            (
                "frequency,acc1_re (mm/N),acc1_im (mm/N)\n1,2,3\n2,3,4\n",
                1,
                "not a unit of",
            ),
            ("frequency,acc1_db (g)\n1,2\n2,3\n", 1, "dB re 1 SI unit"),
            ("frequency,acc1_db\n1,2\n2,x\n", 3, "not a number"),
            ("frequency,acc1_db\n1,2\n2,NaN\n", 3, "only finite"),
            (
                "# c\nfrequency,acc1_db\n1,2\n3,4\n2,4\n",
                5,
                "does not increase",
            ),
            ("frequency,acc1_db\n1,2\n2\n", 3, "fields"),
            ("frequency,acc1_db\n1,2\n", 2, "at least 2"),
        ];
        for (text, line, needle) in cases {
            let f = file(text);
            let e = MeasuredFrf::read(f.path(), &ColumnMap::default()).expect_err(needle);
            let shown = e.to_string();
            assert!(shown.contains(needle), "{needle}: {shown}");
            assert!(shown.contains(&f.path().display().to_string()), "{shown}");
            assert_eq!(e.line, Some(line), "{shown}");
        }
    }
}
