//! The input file: its columns matched to the model's inputs, its rows interpolated (continuous
//! Reals) or held (the rest) at each communication point, its events.

use std::path::Path;

use crate::cosim::import::{Causality, ScalarType, ScalarVariable};

use super::model::{closest, parse_value, Model, Value};
use super::RunError;

/// One input column bound to a variable.
pub(super) struct InputColumn {
    /// The header's name.
    pub(super) name: String,
    /// The variables it drives: (component, variable); several for a system input.
    pub(super) targets: Vec<(usize, ScalarVariable)>,
    /// The first target: its type decides how the column is read.
    pub(super) variable: ScalarVariable,
    /// Interpolated linearly (continuous Real); else held.
    pub(super) continuous: bool,
    pub(super) samples: Vec<f64>,
    /// String samples (String variables: refused when the run is planned).
    pub(super) texts: Vec<String>,
}

pub(super) struct InputTable {
    pub(super) time: Vec<f64>,
    pub(super) columns: Vec<InputColumn>,
}

pub(super) fn isclose(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

impl InputTable {
    /// The input file at `path` read against `model`: a `time` column first, then one column
    /// per input of the model (or system input), every row parsed as its input's type, the
    /// times not decreasing. Errors name the file and the line.
    pub(super) fn read(path: &Path, model: &Model) -> Result<Self, RunError> {
        let at = |line: usize, message: String| RunError::Input {
            path: path.to_owned(),
            line,
            message,
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(path)
            .map_err(|e| at(1, format!("cannot read: {e}")))?;
        let header = reader
            .headers()
            .map_err(|e| at(1, format!("no header: {e}")))?
            .clone();
        if header.get(0) != Some("time") {
            return Err(at(
                1,
                format!(
                    "the first column must be 'time', not '{}'",
                    header.get(0).unwrap_or("")
                ),
            ));
        }
        let mut columns = Self::columns(&header, model).map_err(|m| at(1, m))?;
        let time = Self::rows(&mut reader, &header, &mut columns, &at)?;
        Ok(InputTable { time, columns })
    }

    /// The header's columns after `time`, each matched to the input (or the system input's
    /// targets) of `model` it drives; Err: a column that drives none (with the closest inputs'
    /// names), or one named twice.
    fn columns(header: &csv::StringRecord, model: &Model) -> Result<Vec<InputColumn>, String> {
        let drivable =
            |v: &ScalarVariable| v.causality == Causality::Input || v.variability == "tunable";
        let mut columns = Vec::new();
        for name in header.iter().skip(1) {
            let targets = match model.find(name).filter(|(_, v)| drivable(v)) {
                Some((i, v)) => vec![(i, v.clone())],
                None => model.fed_by_system_input(name),
            };
            let Some((_, variable)) = targets.first().cloned() else {
                let inputs: Vec<String> = model
                    .variables()
                    .filter(|(_, _, v)| drivable(v))
                    .map(|(_, n, _)| n)
                    .chain(model.system_inputs.iter().cloned())
                    .collect();
                let close = closest(name, &inputs);
                return Err(format!(
                    "column '{name}' is no input of {}{}",
                    model.path.display(),
                    if close.is_empty() {
                        format!(" (its inputs: {})", inputs.join(", "))
                    } else {
                        format!(" (closest: {})", close.join(", "))
                    }
                ));
            };
            if columns.iter().any(|c: &InputColumn| c.name == name) {
                return Err(format!("column '{name}' appears twice"));
            }
            columns.push(InputColumn {
                name: name.to_owned(),
                targets,
                continuous: variable.scalar_type == ScalarType::Real
                    && !matches!(variable.variability.as_str(), "discrete" | "tunable"),
                variable,
                samples: Vec::new(),
                texts: Vec::new(),
            });
        }
        Ok(columns)
    }

    /// The file's rows into `columns` (each parsed as its input's type); the times, not
    /// decreasing, at least one row. `at` makes the error of a line.
    fn rows(
        reader: &mut csv::Reader<std::fs::File>,
        header: &csv::StringRecord,
        columns: &mut [InputColumn],
        at: &dyn Fn(usize, String) -> RunError,
    ) -> Result<Vec<f64>, RunError> {
        let mut time: Vec<f64> = Vec::new();
        for (row, record) in reader.records().enumerate() {
            let line = row + 2;
            let record = record.map_err(|e| at(line, e.to_string()))?;
            if record.len() != header.len() {
                return Err(at(
                    line,
                    format!("{} fields, the header has {}", record.len(), header.len()),
                ));
            }
            let t: f64 = record[0]
                .parse()
                .ok()
                .filter(|t: &f64| t.is_finite())
                .ok_or_else(|| at(line, format!("time '{}' is not a number", &record[0])))?;
            if let Some(&last) = time.last() {
                if t < last {
                    return Err(at(
                        line,
                        format!("time {t} is before the previous row's {last}"),
                    ));
                }
            }
            time.push(t);
            for (c, column) in columns.iter_mut().enumerate() {
                let text = &record[c + 1];
                match parse_value(&column.variable, text).map_err(|expected| {
                    at(
                        line,
                        format!("column '{}': '{text}' is not {expected}", &header[c + 1]),
                    )
                })? {
                    Value::Number(x) => column.samples.push(x),
                    Value::Text(s) => {
                        column.samples.push(f64::NAN);
                        column.texts.push(s);
                    }
                }
            }
        }
        if time.is_empty() {
            return Err(at(2, "no rows".into()));
        }
        Ok(time)
    }

    /// Input events after `time`: repeated time rows and changes of a held input (fmpy's
    /// `Input.findEvents`).
    pub(super) fn events(&self) -> Vec<f64> {
        let t = &self.time;
        let mut events: Vec<f64> = Vec::new();
        for i in 0..t.len().saturating_sub(1) {
            if t[i + 1] == t[i] {
                events.push(t[i]);
            }
        }
        for column in self.columns.iter().filter(|c| !c.continuous) {
            for i in 0..t.len().saturating_sub(1) {
                let changed = if column.variable.scalar_type == ScalarType::String {
                    column.texts[i] != column.texts[i + 1]
                } else {
                    column.samples[i].to_bits() != column.samples[i + 1].to_bits()
                };
                if changed {
                    events.push(t[i + 1]);
                }
            }
        }
        events.sort_by(f64::total_cmp);
        events.dedup();
        events
    }

    /// The row whose value a held input has at `time` (fmpy's `Input.interpolate`, discrete),
    /// or the interpolated value of a continuous one.
    pub(super) fn value_at(
        &self,
        column: &InputColumn,
        time: f64,
        after_event: bool,
    ) -> (f64, usize) {
        let t = &self.time;
        let n = t.len();
        if n < 2 {
            return (column.samples[0], 0);
        }
        let i0 = t.partition_point(|&x| x < time);
        if i0 == 0 {
            return (column.samples[0], 0);
        }
        if i0 == n {
            return (column.samples[n - 1], n - 1);
        }
        if !column.continuous {
            let mut i = i0 - 1;
            if after_event {
                while i + 1 < n && (t[i + 1] < time || isclose(time, t[i + 1])) {
                    i += 1;
                }
            }
            return (column.samples[i], i);
        }
        if isclose(time, t[i0]) && i0 < n - 1 && isclose(t[i0], t[i0 + 1]) {
            let mut i = i0;
            if after_event {
                while i < n - 1 && isclose(t[i], t[i + 1]) {
                    i += 1;
                }
            }
            return (column.samples[i], i);
        }
        let (i, j) = (i0 - 1, i0);
        let w0 = (t[j] - time) / (t[j] - t[i]);
        let w1 = 1.0 - w0;
        (w0 * column.samples[i] + w1 * column.samples[j], j)
    }
}
