//! Measurement records in and out, in one place: the CSV file, the same columns from arrays in
//! memory, one CSV line at a time for a live stream, and the CSV writer. A bad file is refused
//! with its name, the line and the problem.
//!
//! A record's columns: `time` (s); the excitation, `force` (N) or `ground_acc` (m/s²);
//! responses `acc<i>`, `vel<i>`, `disp<i>` for floor i, any subset, at least one; `control`
//! (N) kept by name. A header field may carry its unit, `acc2 (g)` (see
//! [`structure::channel::Unit`]); values are converted to SI on reading. A [`ColumnMap`] maps
//! other header names to these. Without a time column, comment lines before the header give
//! `# rate = <Hz>` and `# start = <s>`. Written times are put back on their nominal grid
//! ([`grid`]). A universal file (`.uff`, `.unv`, dataset 58, [`uff`]) is read into the same
//! record. A measured FRF ([`frf`]) is a CSV of `frequency` and `<ch>_re,<ch>_im` or `<ch>_db`
//! columns, or a universal file's FRFs.

pub mod excitation;
pub mod frf;
pub mod grid;
mod read;
pub mod stream;
pub mod uff;
pub(crate) mod write;

use std::collections::BTreeMap;
use std::path::Path;

use ::structure::channel::{split_unit, Channel};

pub use read::{AmbientRecord, DataError, Measurement, ReadOptions, Signal, EXTRA_COLUMNS};
pub use stream::{default_header, nominal_step, LineLayout};
pub use write::{columns_csv, csv_text, format_g9};

// Which reader a file goes to, here above the readers: a universal file (`.uff`, `.unv`) to
// `uff`, anything else to the CSV readers of `read` and `frf`.
impl Measurement {
    /// Read a record as its header says (see [`Measurement::read_with`]).
    pub fn read(path: &Path) -> Result<Self, DataError> {
        Self::read_with(path, &ReadOptions::default())
    }

    /// Read a record: a universal file by [`uff::read_record`], else a CSV file whose leading
    /// `#` lines may give `# rate = <Hz>` and `# start = <s>` for a file without a time column;
    /// the header names the columns, each `name` or `name (unit)` (mapped through
    /// `options.columns` first); every value is converted to SI and the times are put back on
    /// the nominal grid they were rounded from.
    pub fn read_with(path: &Path, options: &ReadOptions) -> Result<Self, DataError> {
        if uff::is_universal_file(path) {
            uff::read_record(path, &options.columns)
        } else {
            read::read_csv(path, options)
        }
    }
}

impl frf::MeasuredFrf {
    /// Read a measured FRF: a universal file by [`uff::read_frf`], anything else as CSV.
    pub fn read(path: &Path, columns: &ColumnMap) -> Result<Self, DataError> {
        if uff::is_universal_file(path) {
            uff::read_frf(path, columns)
        } else {
            frf::read_csv(path, columns)
        }
    }
}

/// Whether a record has an excitation column (`force` or `ground_acc`, after
/// `options.columns`): a record without one is ambient ([`AmbientRecord`]). A universal file is
/// taken to have one (its reader says otherwise).
pub fn has_excitation_column(path: &Path, options: &ReadOptions) -> Result<bool, DataError> {
    if uff::is_universal_file(path) {
        Ok(true)
    } else {
        read::csv_has_excitation(path, options)
    }
}

/// Header names a file uses for the twin's, as `--columns MAP.json` gives them:
/// `{"dotx1 (m/s)": "vel1", "fp (N)": "force"}`. A key matches a header field by its name and,
/// when the key has one, its unit; the field's unit goes with it unless the target names its
/// own (`{"fp": "force (kN)"}`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ColumnMap(BTreeMap<String, String>);

impl ColumnMap {
    /// A map whose every target is a column the twin knows; Err names the first that is not.
    pub fn new(map: BTreeMap<String, String>) -> Result<Self, String> {
        for (key, target) in &map {
            let (name, _) = split_unit(target);
            if Channel::parse(name).is_none()
                && !EXTRA_COLUMNS.contains(&name)
                && !frf::is_frf_column(name)
            {
                return Err(format!(
                    "'{key}' is mapped to '{target}', not a column the twin knows (time, force, \
                     ground_acc, acc<i>, vel<i>, disp<i>, control; in an FRF file frequency, \
                     <channel>_re, <channel>_im, <channel>_db)"
                ));
            }
        }
        Ok(ColumnMap(map))
    }

    /// A JSON object of strings.
    pub fn read(path: &Path) -> Result<Self, DataError> {
        let err = |message: String| DataError {
            path: path.to_owned(),
            line: None,
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let map: BTreeMap<String, String> = serde_json::from_str(&text).map_err(|e| {
            err(format!(
                "not a column map (a JSON object of header name → column name): {e}"
            ))
        })?;
        ColumnMap::new(map).map_err(err)
    }

    /// The header field as the twin reads it.
    pub fn apply(&self, field: &str) -> String {
        let (name, unit) = split_unit(field);
        for (key, target) in &self.0 {
            let (key_name, key_unit) = split_unit(key);
            if key_name != name || (key_unit.is_some() && key_unit != unit) {
                continue;
            }
            return match (split_unit(target), unit) {
                ((_, Some(_)), _) | (_, None) => target.trim().to_owned(),
                ((target_name, None), Some(unit)) => format!("{target_name} ({unit})"),
            };
        }
        field.trim().to_owned()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}
