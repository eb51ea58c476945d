//! Reading a measurement file or columns in memory into a [`Measurement`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::REQUIRED_COLUMNS;

#[derive(Debug, thiserror::Error)]
#[error("{path}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct DataError {
    pub path: PathBuf,
    pub line: Option<u64>,
    pub message: String,
}

#[derive(Debug, Clone)]
pub struct Measurement {
    pub path: PathBuf,
    pub time: Vec<f64>,
    pub force: Vec<f64>,
    pub acc: [Vec<f64>; 3],
    /// The sampling interval, recovered exactly from the (rounded) time column.
    pub dt: f64,
    pub extra: HashMap<String, Vec<f64>>,
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

    pub fn read(path: &Path) -> Result<Self, DataError> {
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
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(bytes.as_slice());
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| err(Some(1), format!("bad header: {e}")))?
            .iter()
            .map(str::to_owned)
            .collect();
        let mut index = HashMap::new();
        for (i, name) in header.iter().enumerate() {
            if index.insert(name.clone(), i).is_some() {
                return Err(err(Some(1), format!("column '{name}' appears twice")));
            }
        }
        for required in REQUIRED_COLUMNS {
            if !index.contains_key(required) {
                return Err(err(
                    Some(1),
                    format!(
                        "missing column '{required}' (the header must have {})",
                        REQUIRED_COLUMNS.join(",")
                    ),
                ));
            }
        }
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
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
                let value = parse_value(&header[i], field).map_err(|m| err(line(), m))?;
                columns[i].push(value);
            }
        }
        let n = columns[0].len();
        if n < 2 {
            return Err(err(None, format!("{n} data rows; at least 2 are needed")));
        }
        let time = std::mem::take(&mut columns[index["time"]]);
        for k in 1..n {
            if time[k] <= time[k - 1] {
                return Err(err(
                    Some(k as u64 + 2),
                    format!(
                        "time {} does not increase (previous {})",
                        time[k],
                        time[k - 1]
                    ),
                ));
            }
        }
        let dt = uniform_step(&time).map_err(|(k, message)| err(Some(k as u64 + 2), message))?;
        let take =
            |columns: &mut Vec<Vec<f64>>, name: &str| std::mem::take(&mut columns[index[name]]);
        let force = take(&mut columns, "force");
        let acc = [
            take(&mut columns, "acc1"),
            take(&mut columns, "acc2"),
            take(&mut columns, "acc3"),
        ];
        let extra = header
            .iter()
            .enumerate()
            .filter(|(_, name)| !REQUIRED_COLUMNS.contains(&name.as_str()))
            .map(|(i, name)| (name.clone(), std::mem::take(&mut columns[i])))
            .collect();
        Ok(Measurement {
            path: path.to_owned(),
            time,
            force,
            acc,
            dt,
            extra,
        })
    }
}

impl Measurement {
    /// A record from columns in memory (the Python package's arrays), checked as a file is:
    /// equal lengths, finite numbers, at least 2 samples, time increasing on a uniform grid.
    /// `origin` names it in messages (no line numbers: sample indices from 0).
    pub fn from_columns(
        origin: &Path,
        time: Vec<f64>,
        force: Vec<f64>,
        acc: [Vec<f64>; 3],
        extra: HashMap<String, Vec<f64>>,
    ) -> Result<Self, DataError> {
        let err = |message: String| DataError {
            path: origin.to_owned(),
            line: None,
            message,
        };
        let n = time.len();
        let named = [("time", &time), ("force", &force)]
            .into_iter()
            .chain(["acc1", "acc2", "acc3"].into_iter().zip(acc.iter()))
            .chain(extra.iter().map(|(name, c)| (name.as_str(), c)));
        for (name, column) in named {
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
        if let Some(k) = (1..n).find(|&k| time[k] <= time[k - 1]) {
            return Err(err(format!(
                "time {} at sample {k} does not increase (previous {})",
                time[k],
                time[k - 1]
            )));
        }
        let dt =
            uniform_step(&time).map_err(|(k, message)| err(format!("sample {k}: {message}")))?;
        Ok(Measurement {
            path: origin.to_owned(),
            time,
            force,
            acc,
            dt,
            extra,
        })
    }
}

/// One field of column `name` as a finite number, or why it is not one.
pub(super) fn parse_value(name: &str, field: &str) -> Result<f64, String> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(format!("'{name}' is {v}; only finite numbers are accepted")),
        Err(_) => Err(format!("'{name}' is not a number: '{field}'")),
    }
}

/// The sampling interval of a uniformly sampled time column. Times in files are rounded (the
/// examples to 1 µs), so each sample may sit off the grid by a little; more than 1 % of a step
/// is non-uniform sampling. The rate is snapped to a round number of mHz when that moves the end
/// of the grid by at most 1 µs, so 51.2 Hz gives exactly 1/51.2 s.
fn uniform_step(time: &[f64]) -> Result<f64, (usize, String)> {
    let n = time.len();
    let mut dt = (time[n - 1] - time[0]) / (n - 1) as f64;
    let tolerance = 0.01 * dt;
    for (k, t) in time.iter().enumerate() {
        let grid = time[0] + k as f64 * dt;
        if (t - grid).abs() > tolerance {
            return Err((
                k,
                format!("non-uniform sampling: time {t} is off the {dt} s grid (expected {grid})"),
            ));
        }
    }
    let rate = 1.0 / dt;
    let snapped = (rate * 1000.0).round() / 1000.0;
    // Keep the snapped rate when the grid it gives ends within 1 µs (the examples' printed
    // precision) of the measured one.
    if snapped > 0.0 && ((1.0 / snapped) - dt).abs() * (n - 1) as f64 <= 1e-6 {
        dt = 1.0 / snapped;
    }
    Ok(dt)
}

#[cfg(test)]
mod tests {
    use super::*;
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
                "time,force,acc1,acc2\n0,1,2,3\n1,1,2,3\n",
                None,
                "missing column 'acc3'",
            ),
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
}
