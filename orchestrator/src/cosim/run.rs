//! `twin run`: any FMI 2.0 co-simulation FMU, or an SSP system of them, run by the master.
//!
//! The configuration (experiment, start values, the input file's columns) is checked against
//! the modelDescriptions before any FMU's code is loaded. The run then follows fmpy's
//! `simulate_fmu` conventions, so the same FMU with the same inputs gives the same rows:
//! - the communication points are `start + k·h` up to the stop time; an FMU that handles
//!   variable communication steps also stops at the input file's events (repeated time rows,
//!   changes of a discrete input), and gets a last short step to the stop time;
//! - continuous Real inputs are interpolated linearly between the file's rows at each point,
//!   the others (Integer, Boolean, Enumeration, discrete Reals) are held from the last row; an
//!   FMU that declares `canInterpolateInputs` also gets the slope up to the next point (unless
//!   `hold_inputs`: fmpy's default never sends one);
//! - a system's connections are resolved by Gauss–Seidel at each point (default), or by Jacobi
//!   (`algorithm`): every component then reads the others' outputs as the last step left them,
//!   as fmpy's `simulate_ssp` does (which also delivers the system inputs a step late);
//! - the outputs at a point are recorded as the step left them, before that point's inputs are
//!   applied (point 0: after the start values and the first inputs, in initialisation mode);
//! - an FMU that ends the simulation itself (`fmi2Discard` + `fmi2Terminated`) ends the run at
//!   its last successful time, recorded as the last row.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::cosim::import::{
    self, Causality, Fmu, ImportError, Instance, ModelDescription, ScalarType, ScalarVariable,
    UnpackLimits, Unpacked, UnpackedFmu,
};
use crate::cosim::master::{
    Algorithm, MasterError, NodeId, Observer, Port, PortType, Recording, RunEnd, System, TypedPort,
};
use crate::cosim::ssp::{self, Connection, SsvValue};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error("{path}: {message}")]
    Model { path: PathBuf, message: String },
    #[error("{0}")]
    Config(String),
    #[error("{path}: line {line}: {message}")]
    Input {
        path: PathBuf,
        line: usize,
        message: String,
    },
}

/// What to run and how; None takes the model's `DefaultExperiment` (then fmpy's defaults).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub start: Option<f64>,
    pub stop: Option<f64>,
    pub step: Option<f64>,
    /// CSV: `time` first, then columns named like inputs (or tunable parameters).
    pub input: Option<PathBuf>,
    /// `NAME=VALUE` start values (`component.variable` in a system).
    pub sets: Vec<String>,
    /// Record the local variables too, not only the outputs.
    pub output_all: bool,
    /// Hold every input over each step, even for FMUs that can interpolate inputs (fmpy's
    /// `simulate_fmu` default).
    pub hold_inputs: bool,
    /// How a system's connections are resolved at a communication point: Gauss–Seidel (each
    /// component, in the SSD's order, sees what the ones before it produced at this point,
    /// repeated until nothing changes) or Jacobi (every component sees the outputs as the last
    /// step left them: fmpy's `simulate_ssp` for connections between components).
    pub algorithm: Algorithm,
}

/// A recorded column.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    pub name: String,
    pub scalar_type: ScalarType,
}

/// The recorded rows: `values[c][k]` (NaN for a String column, whose values are in `texts`).
#[derive(Debug, Clone)]
pub struct RunResult {
    pub columns: Vec<Column>,
    pub time: Vec<f64>,
    pub values: Vec<Vec<f64>>,
    pub texts: BTreeMap<usize, Vec<String>>,
    pub start: f64,
    pub stop: f64,
    pub step: f64,
    /// Set when an FMU ended the run itself: (its component, the time).
    pub terminated: Option<(String, f64)>,
}

impl RunResult {
    /// `time,<columns…>`; Reals in shortest round-trip form, Booleans as 0/1.
    pub fn write_csv(&self, writer: impl std::io::Write) -> Result<(), csv::Error> {
        let mut w = csv::Writer::from_writer(writer);
        let mut header = vec!["time".to_owned()];
        header.extend(self.columns.iter().map(|c| c.name.clone()));
        w.write_record(&header)?;
        let mut row = Vec::with_capacity(header.len());
        for (k, t) in self.time.iter().enumerate() {
            row.clear();
            row.push(real_text(*t));
            for (c, column) in self.columns.iter().enumerate() {
                row.push(match column.scalar_type {
                    ScalarType::String => self.texts[&c][k].clone(),
                    ScalarType::Real => real_text(self.values[c][k]),
                    _ => format!("{}", self.values[c][k] as i64),
                });
            }
            w.write_record(&row)?;
        }
        w.flush()?;
        Ok(())
    }

    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .position(|c| c.name == name)
            .map(|i| self.values[i].as_slice())
    }
}

/// The shortest text that reads back to the same `f64`: plain for magnitudes from 1e-4 to
/// 1e15, scientific beyond (Rust's `{:e}` is shortest round-trip too).
fn real_text(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-4..1e15).contains(&a) || !a.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

// ---------------------------------------------------------------------------------------------
// The model: one FMU, or the components of an SSP system

struct Component {
    /// Instance name (the SSP component's name, or the FMU's model identifier).
    name: String,
    /// Prefix of its variables' names in the run: "" for a lone FMU, "name." in a system.
    prefix: String,
    md: ModelDescription,
    /// Taken when the FMU is loaded.
    fmu: Option<UnpackedFmu>,
    /// Start values from the system's parameter bindings, by variable name.
    bound: Vec<(String, SsvValue)>,
}

struct Model {
    path: PathBuf,
    components: Vec<Component>,
    connections: Vec<Connection>,
    /// The system's input connectors (a system only).
    system_inputs: Vec<String>,
    default_start: Option<f64>,
    default_stop: Option<f64>,
    default_step: Option<f64>,
    _archive: Option<Unpacked>,
}

fn is_ssp(path: &Path) -> Result<bool, RunError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("ssp") => Ok(true),
        Some(e) if e.eq_ignore_ascii_case("fmu") => Ok(false),
        _ => Err(RunError::Model {
            path: path.to_owned(),
            message: "neither an .fmu nor an .ssp file".into(),
        }),
    }
}

impl Model {
    fn open(path: &Path) -> Result<Self, RunError> {
        if !path.is_file() {
            return Err(RunError::Model {
                path: path.to_owned(),
                message: "no such file".into(),
            });
        }
        if !is_ssp(path)? {
            let fmu = UnpackedFmu::open(path)?;
            let md = fmu.model_description.clone();
            let (start, stop, step) = (
                md.default_start_time,
                md.default_stop_time,
                md.default_step_size,
            );
            return Ok(Model {
                path: path.to_owned(),
                components: vec![Component {
                    name: md.model_identifier.clone(),
                    prefix: String::new(),
                    md,
                    fmu: Some(fmu),
                    bound: Vec::new(),
                }],
                connections: Vec::new(),
                system_inputs: Vec::new(),
                default_start: start,
                default_stop: stop,
                default_step: step,
                _archive: None,
            });
        }
        let bad = |message: String| RunError::Model {
            path: path.to_owned(),
            message,
        };
        let archive = import::unpack(path, UnpackLimits::default())?;
        let read = |inner: &str| {
            std::fs::read_to_string(archive.path().join(inner))
                .map_err(|e| bad(format!("{inner}: {e}")))
        };
        let ssd = ssp::parse_ssd(&read("SystemStructure.ssd")?)
            .map_err(|m| bad(format!("SystemStructure.ssd: {m}")))?;
        let mut components = Vec::new();
        for (i, c) in ssd.components.iter().enumerate() {
            if ssd.components[..i].iter().any(|d| d.name == c.name) {
                return Err(bad(format!("two components are named '{}'", c.name)));
            }
            // A source is a path inside the archive: nothing absolute, no '..', no other scheme.
            let inside = !c.source.starts_with('/')
                && !c.source.contains(':')
                && !c.source.split('/').any(|part| part == "..");
            let fmu_path = archive.path().join(&c.source);
            if !inside || !fmu_path.is_file() {
                return Err(bad(format!(
                    "component '{}': its source '{}' is not in the archive",
                    c.name, c.source
                )));
            }
            let fmu = UnpackedFmu::open(&fmu_path).map_err(|e| {
                bad(format!(
                    "component '{}' ({}): {}",
                    c.name,
                    c.source,
                    e.to_string()
                        .replace(&fmu_path.display().to_string(), "the FMU")
                ))
            })?;
            let mut bound = Vec::new();
            for binding in &c.bindings {
                bound.extend(
                    ssp::parse_ssv(&read(binding)?).map_err(|m| bad(format!("{binding}: {m}")))?,
                );
            }
            components.push(Component {
                name: c.name.clone(),
                prefix: format!("{}.", c.name),
                md: fmu.model_description.clone(),
                fmu: Some(fmu),
                bound,
            });
        }
        if components.is_empty() {
            return Err(bad("the system has no components".into()));
        }
        // The smallest of the components' default steps, so no component is stepped coarser
        // than its author meant.
        let default_step = components
            .iter()
            .filter_map(|c| c.md.default_step_size)
            .reduce(f64::min);
        let system_inputs = ssd
            .connectors
            .iter()
            .filter(|c| c.kind == "input")
            .map(|c| c.name.clone())
            .collect();
        Ok(Model {
            path: path.to_owned(),
            components,
            connections: ssd.connections,
            system_inputs,
            default_start: ssd.start_time,
            default_stop: ssd.stop_time,
            default_step,
            _archive: Some(archive),
        })
    }

    fn component_index(&self, name: &str) -> Option<usize> {
        self.components.iter().position(|c| c.name == name)
    }

    /// Every variable by its name in the run.
    fn variables(&self) -> impl Iterator<Item = (usize, String, &ScalarVariable)> {
        self.components.iter().enumerate().flat_map(|(i, c)| {
            c.md.variables
                .iter()
                .map(move |v| (i, format!("{}{}", c.prefix, v.name), v))
        })
    }

    /// The component inputs a system input connector feeds.
    fn fed_by_system_input(&self, connector: &str) -> Vec<(usize, ScalarVariable)> {
        if !self.system_inputs.iter().any(|c| c == connector) {
            return Vec::new();
        }
        self.connections
            .iter()
            .filter(|k| k.start_element.is_none() && k.start_connector == connector)
            .filter_map(|k| {
                let i = self.component_index(k.end_element.as_deref()?)?;
                let v = self.components[i].md.variable(&k.end_connector)?;
                Some((i, v.clone()))
            })
            .collect()
    }

    fn find(&self, name: &str) -> Option<(usize, &ScalarVariable)> {
        for (i, c) in self.components.iter().enumerate() {
            if let Some(local) = name.strip_prefix(&c.prefix) {
                if let Some(v) = c.md.variable(local) {
                    return Some((i, v));
                }
            }
        }
        None
    }

    fn unknown(&self, what: &str, name: &str, candidates: Vec<String>) -> RunError {
        let close = closest(name, &candidates);
        RunError::Config(format!(
            "{what} '{name}': {} has no such variable{}",
            self.path.display(),
            if close.is_empty() {
                String::new()
            } else {
                format!(" (closest: {})", close.join(", "))
            }
        ))
    }

    fn all_variable_names(&self) -> Vec<String> {
        self.variables().map(|(_, n, _)| n).collect()
    }

    fn can_vary_step(&self) -> bool {
        self.components
            .iter()
            .all(|c| c.md.can_handle_variable_step)
    }
}

/// Up to three names closest to `name` (by edit distance), for "did you mean".
fn closest(name: &str, candidates: &[String]) -> Vec<String> {
    let mut scored: Vec<(usize, &String)> = candidates
        .iter()
        .map(|c| (strsim::levenshtein(name, c), c))
        .filter(|(d, c)| *d <= (name.len().max(c.len()) / 2).max(2))
        .collect();
    scored.sort();
    scored.into_iter().take(3).map(|(_, c)| c.clone()).collect()
}

// ---------------------------------------------------------------------------------------------
// Values

/// A start value or input sample, checked against its variable's type.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Number(f64),
    Text(String),
}

fn parse_value(variable: &ScalarVariable, text: &str) -> Result<Value, String> {
    let t = text.trim();
    let number = match variable.scalar_type {
        ScalarType::Real => t
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or("a finite Real")?,
        ScalarType::Integer | ScalarType::Enumeration => {
            f64::from(t.parse::<i32>().map_err(|_| "an Integer")?)
        }
        ScalarType::Boolean => match t {
            "1" | "true" | "True" => 1.0,
            "0" | "false" | "False" => 0.0,
            _ => return Err("a Boolean (0, 1, true, false)".into()),
        },
        ScalarType::String => return Ok(Value::Text(text.to_owned())),
    };
    Ok(Value::Number(number))
}

fn ssv_value(variable: &ScalarVariable, value: &SsvValue) -> Result<Value, String> {
    match (variable.scalar_type, value) {
        (ScalarType::Real, SsvValue::Real(x)) => Ok(Value::Number(*x)),
        (ScalarType::Real, SsvValue::Integer(i)) => Ok(Value::Number(f64::from(*i))),
        (ScalarType::Integer | ScalarType::Enumeration, SsvValue::Integer(i)) => {
            Ok(Value::Number(f64::from(*i)))
        }
        (ScalarType::Boolean, SsvValue::Boolean(b)) => Ok(Value::Number(f64::from(u8::from(*b)))),
        (ScalarType::String, SsvValue::String(s)) => Ok(Value::Text(s.clone())),
        (ty, v) => Err(format!("is {ty:?}, the parameter set gives {v:?}")),
    }
}

fn settable(v: &ScalarVariable) -> bool {
    v.variability != "constant"
        && (matches!(v.causality, Causality::Parameter | Causality::Input)
            || matches!(v.initial.as_deref(), Some("exact" | "approx")))
}

fn port_type(t: ScalarType) -> PortType {
    match t {
        ScalarType::Real => PortType::Real,
        ScalarType::Integer | ScalarType::Enumeration => PortType::Integer,
        ScalarType::Boolean => PortType::Boolean,
        ScalarType::String => PortType::String,
    }
}

fn set_value(
    instance: &mut Instance,
    v: &ScalarVariable,
    value: &Value,
) -> Result<(), ImportError> {
    let vr = [v.value_reference];
    match (v.scalar_type, value) {
        (ScalarType::String, Value::Text(s)) => instance.set_string(&vr, &[s.as_str()]),
        (ScalarType::Real, Value::Number(x)) => instance.set_real(&vr, &[*x]),
        (ScalarType::Integer | ScalarType::Enumeration, Value::Number(x)) => {
            instance.set_integer(&vr, &[*x as i32])
        }
        (ScalarType::Boolean, Value::Number(x)) => instance.set_boolean(&vr, &[*x != 0.0]),
        // Checked when the configuration was validated.
        _ => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// The input file, resampled as fmpy does

/// One input column bound to a variable.
struct InputColumn {
    /// The header's name.
    name: String,
    /// The variables it drives: (component, variable); several for a system input.
    targets: Vec<(usize, ScalarVariable)>,
    /// The first target: its type decides how the column is read.
    variable: ScalarVariable,
    /// Interpolated linearly (continuous Real); else held.
    continuous: bool,
    samples: Vec<f64>,
    /// String samples (String variables: refused when the run is planned).
    texts: Vec<String>,
}

struct InputTable {
    time: Vec<f64>,
    columns: Vec<InputColumn>,
}

fn isclose(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

impl InputTable {
    fn read(path: &Path, model: &Model) -> Result<Self, RunError> {
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
                return Err(at(
                    1,
                    format!(
                        "column '{name}' is no input of {}{}",
                        model.path.display(),
                        if close.is_empty() {
                            format!(" (its inputs: {})", inputs.join(", "))
                        } else {
                            format!(" (closest: {})", close.join(", "))
                        }
                    ),
                ));
            };
            if columns.iter().any(|c: &InputColumn| c.name == name) {
                return Err(at(1, format!("column '{name}' appears twice")));
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
        Ok(InputTable { time, columns })
    }

    /// Input events after `time`: repeated time rows and changes of a held input (fmpy's
    /// `Input.findEvents`).
    fn events(&self) -> Vec<f64> {
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
    fn value_at(&self, column: &InputColumn, time: f64, after_event: bool) -> (f64, usize) {
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

/// fmpy's `auto_interval`: a round step giving 500 to 1000 points.
fn auto_interval(span: f64) -> f64 {
    let mut h = 10f64.powf(span.log10().round() - 3.0);
    let n = span / h;
    if n >= 2500.0 {
        h *= 5.0;
    } else if n >= 2000.0 {
        h *= 4.0;
    } else if n >= 1000.0 {
        h *= 2.0;
    } else if n <= 200.0 {
        h /= 5.0;
    } else if n <= 250.0 {
        h /= 4.0;
    } else if n <= 500.0 {
        h /= 2.0;
    }
    h
}

/// The communication points, as fmpy's co-simulation loop takes them.
fn schedule(start: f64, stop: f64, step: f64, events: &[f64], variable_step: bool) -> Vec<f64> {
    let mut times = vec![start];
    let mut time = start;
    let mut n: u64 = 0;
    let mut pending = 0;
    loop {
        if time > stop || isclose(time, stop) {
            break;
        }
        let regular = start + (n + 1) as f64 * step;
        let mut next = regular;
        // The next event after `time`: time only grows, so the search resumes where it
        // stopped (one pass over the events for the whole schedule, not one per point).
        while pending < events.len() && (events[pending] <= time || isclose(events[pending], time))
        {
            pending += 1;
        }
        let event = events.get(pending).copied().unwrap_or(f64::INFINITY);
        if variable_step && next > event && !isclose(next, event) {
            next = event;
        }
        if next > stop && !isclose(next, stop) {
            if variable_step {
                next = stop;
            } else {
                break;
            }
        }
        times.push(next);
        time = next;
        if isclose(time, regular) {
            n += 1;
        }
    }
    times
}

// ---------------------------------------------------------------------------------------------
// The recorder

struct Columns {
    ports: Vec<Port>,
    text_ports: Vec<Port>,
    time: Vec<f64>,
    values: Vec<Vec<f64>>,
    texts: Vec<Vec<String>>,
}

impl Observer for Columns {
    fn record(&mut self, time: f64, values: &[f64]) {
        self.time.push(time);
        for (column, &v) in self.values.iter_mut().zip(values) {
            column.push(v);
        }
    }
    fn ports(&self) -> &[Port] {
        &self.ports
    }
    fn text_ports(&self) -> &[Port] {
        &self.text_ports
    }
    fn record_text(&mut self, values: &[&str]) {
        for (column, v) in self.texts.iter_mut().zip(values) {
            column.push((*v).to_owned());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The run

/// Checked configuration: everything decided before an FMU is loaded.
struct Plan {
    start: f64,
    stop: f64,
    step: f64,
    /// Per component: start values.
    starts: Vec<Vec<(ScalarVariable, Value)>>,
    input: Option<InputTable>,
    /// Recorded variables: (component, variable, name in the run).
    recorded: Vec<(usize, ScalarVariable, String)>,
    times: Vec<f64>,
}

fn plan(model: &Model, options: &RunOptions) -> Result<Plan, RunError> {
    let start = options.start.or(model.default_start).unwrap_or(0.0);
    let stop = options.stop.or(model.default_stop).unwrap_or(start + 1.0);
    if !start.is_finite() || !stop.is_finite() {
        return Err(RunError::Config(format!(
            "start {start} and stop {stop} must be finite"
        )));
    }
    if stop <= start {
        return Err(RunError::Config(format!(
            "the stop time {stop} is not after the start time {start}"
        )));
    }
    let step = options
        .step
        .or(model.default_step)
        .unwrap_or_else(|| auto_interval(stop - start));
    if !(step > 0.0 && step.is_finite()) {
        return Err(RunError::Config(format!(
            "the step must be a positive number of seconds, was {step}"
        )));
    }
    if (stop - start) / step > 1e8 {
        return Err(RunError::Config(format!(
            "{} steps of {step} s from {start} to {stop} s: more than 10⁸",
            ((stop - start) / step).ceil()
        )));
    }

    let mut starts: Vec<Vec<(ScalarVariable, Value)>> = vec![Vec::new(); model.components.len()];
    for (i, c) in model.components.iter().enumerate() {
        for (name, value) in &c.bound {
            let variable = c.md.variable(name).ok_or_else(|| {
                RunError::Config(format!(
                    "{}: component '{}': its parameter set names '{name}', which {} does not have",
                    model.path.display(),
                    c.name,
                    c.md.model_name
                ))
            })?;
            let value = ssv_value(variable, value).map_err(|m| {
                RunError::Config(format!(
                    "{}: component '{}': parameter '{name}' {m}",
                    model.path.display(),
                    c.name
                ))
            })?;
            starts[i].push((variable.clone(), value));
        }
    }
    for set in &options.sets {
        let (name, text) = set
            .split_once('=')
            .ok_or_else(|| RunError::Config(format!("--set '{set}': expected NAME=VALUE")))?;
        let name = name.trim();
        let (i, variable) = model
            .find(name)
            .ok_or_else(|| model.unknown("--set", name, model.all_variable_names()))?;
        if !settable(variable) {
            return Err(RunError::Config(format!(
                "--set '{name}': a {:?} variable of variability '{}' cannot be given a start value",
                variable.causality, variable.variability
            )));
        }
        let value = parse_value(variable, text).map_err(|expected| {
            RunError::Config(format!(
                "--set '{name}': '{text}' is not {expected} ('{name}' is {:?})",
                variable.scalar_type
            ))
        })?;
        starts[i].retain(|(v, _)| v.name != variable.name);
        starts[i].push((variable.clone(), value));
    }

    let input = options
        .input
        .as_deref()
        .map(|path| InputTable::read(path, model))
        .transpose()?;
    if let Some(table) = &input {
        for column in &table.columns {
            for (i, v) in &column.targets {
                let c = &model.components[*i];
                let fed = model.connections.iter().any(|k| {
                    k.start_element.is_some()
                        && k.end_element.as_deref() == Some(c.name.as_str())
                        && k.end_connector == v.name
                });
                if fed {
                    return Err(RunError::Config(format!(
                        "{}: column '{}' drives {}{}, which a connection already feeds",
                        options.input.as_deref().unwrap_or(Path::new("")).display(),
                        column.name,
                        c.prefix,
                        v.name
                    )));
                }
                if column.variable.scalar_type == ScalarType::String {
                    return Err(RunError::Config(format!(
                        "column '{}': String inputs from a file are not supported; set them \
                         with --set",
                        column.name
                    )));
                }
            }
        }
    }

    let mut recorded = Vec::new();
    for (i, c) in model.components.iter().enumerate() {
        for v in &c.md.variables {
            let keep = v.causality == Causality::Output
                || (options.output_all && v.causality == Causality::Local);
            if keep {
                recorded.push((i, v.clone(), format!("{}{}", c.prefix, v.name)));
            }
        }
    }

    let events = input.as_ref().map(InputTable::events).unwrap_or_default();
    let times = schedule(start, stop, step, &events, model.can_vary_step());
    Ok(Plan {
        start,
        stop,
        step,
        starts,
        input,
        recorded,
        times,
    })
}

/// Run `path` (an `.fmu` or `.ssp`). `progress(done, total)` is called after each step.
pub fn run(
    path: &Path,
    options: &RunOptions,
    progress: impl FnMut(u64, u64),
) -> Result<RunResult, RunError> {
    let model = Model::open(path)?;
    let plan = plan(&model, options)?;
    execute(
        model,
        plan,
        options.hold_inputs,
        options.algorithm,
        progress,
    )
}

/// Each component's ports (inputs driven by the file or by connections, outputs recorded or
/// feeding connections) and the connections between them.
struct Ports {
    inputs: Vec<Vec<ScalarVariable>>,
    outputs: Vec<Vec<ScalarVariable>>,
    /// (from component, output name) → (to component, input name).
    links: Vec<((usize, String), (usize, String))>,
}

impl Ports {
    fn of(model: &Model, plan: &Plan) -> Result<Ports, RunError> {
        let n = model.components.len();
        let mut ports = Ports {
            inputs: vec![Vec::new(); n],
            outputs: vec![Vec::new(); n],
            links: Vec::new(),
        };
        let add = |list: &mut Vec<ScalarVariable>, v: &ScalarVariable| {
            if !list.iter().any(|x| x.name == v.name) {
                list.push(v.clone());
            }
        };
        if let Some(table) = &plan.input {
            for column in &table.columns {
                for (i, v) in &column.targets {
                    add(&mut ports.inputs[*i], v);
                }
            }
        }
        for k in &model.connections {
            if let (Some(from), Some(to)) = (&k.start_element, &k.end_element) {
                let (fi, fv) = connector(model, from, &k.start_connector)?;
                let (ti, tv) = connector(model, to, &k.end_connector)?;
                add(&mut ports.outputs[fi], &fv);
                add(&mut ports.inputs[ti], &tv);
                ports.links.push(((fi, fv.name), (ti, tv.name)));
            }
        }
        for (i, v, _) in &plan.recorded {
            add(&mut ports.outputs[*i], v);
        }
        Ok(ports)
    }

    /// Component `i`'s input `name`'s port index.
    fn input(&self, i: usize, name: &str) -> Option<usize> {
        self.inputs[i].iter().position(|v| v.name == name)
    }

    /// Component `i`'s output `name`'s port index.
    fn output(&self, i: usize, name: &str) -> Option<usize> {
        self.outputs[i].iter().position(|v| v.name == name)
    }
}

/// The component `element` and its variable `connector`, as a connection names them.
fn connector(
    model: &Model,
    element: &str,
    connector: &str,
) -> Result<(usize, ScalarVariable), RunError> {
    let bad = |message: String| RunError::Model {
        path: model.path.clone(),
        message,
    };
    let i = model.component_index(element).ok_or_else(|| {
        bad(format!(
            "a connection names the component '{element}', which the system does not have"
        ))
    })?;
    let v = model.components[i].md.variable(connector).ok_or_else(|| {
        bad(format!(
            "a connection names '{element}.{connector}', which its FMU does not have"
        ))
    })?;
    Ok((i, v.clone()))
}

/// Every component's FMU loaded, instantiated and initialised (start values, then the input
/// file's values at the start); the libraries must outlive the instances.
fn instantiate(model: &mut Model, plan: &Plan) -> Result<(Vec<Fmu>, Vec<Instance>), RunError> {
    let mut loaded: Vec<Fmu> = Vec::new();
    let mut instances: Vec<Instance> = Vec::new();
    for (i, c) in model.components.iter_mut().enumerate() {
        let Some(unpacked) = c.fmu.take() else {
            continue;
        };
        let fmu = unpacked.load()?;
        let mut instance = fmu.instantiate(&c.name)?;
        instance.setup_experiment(plan.start, Some(plan.stop))?;
        instance.enter_initialization_mode()?;
        for (v, value) in &plan.starts[i] {
            set_value(&mut instance, v, value)?;
        }
        if let Some(table) = &plan.input {
            for column in &table.columns {
                let (x, _) = table.value_at(column, plan.start, false);
                for (_, v) in column.targets.iter().filter(|(j, _)| *j == i) {
                    set_value(&mut instance, v, &Value::Number(x))?;
                }
            }
        }
        instance.exit_initialization_mode()?;
        loaded.push(fmu);
        instances.push(instance);
    }
    Ok((loaded, instances))
}

/// The master's system: a slave per instance with its ports, the input file's columns
/// resampled at every communication point, and the connections.
fn wire(
    model: &Model,
    plan: &Plan,
    ports: &Ports,
    instances: Vec<Instance>,
    hold_inputs: bool,
    algorithm: Algorithm,
) -> Result<(System, Vec<NodeId>), RunError> {
    let mut system = System::new();
    system.recording = Recording::BeforeInputs;
    system.interpolate_inputs = !hold_inputs;
    system.algorithm = algorithm;
    let typed = |vars: &[ScalarVariable]| {
        vars.iter()
            .map(|v| TypedPort {
                vr: v.value_reference,
                ty: port_type(v.scalar_type),
            })
            .collect()
    };
    let mut ids: Vec<NodeId> = Vec::new();
    for (i, instance) in instances.into_iter().enumerate() {
        ids.push(system.add_typed_slave(
            &model.components[i].name,
            Box::new(instance),
            typed(&ports.inputs[i]),
            typed(&ports.outputs[i]),
        ));
    }
    if let Some(table) = &plan.input {
        for column in &table.columns {
            let samples: Vec<f64> = plan
                .times
                .iter()
                .map(|&t| table.value_at(column, t, true).0)
                .collect();
            let signal = system.add_signal(&column.name, samples);
            for (i, v) in &column.targets {
                if let Some(p) = ports.input(*i, &v.name) {
                    system.connect(signal, ids[*i], p)?;
                }
            }
        }
    }
    for ((fi, fname), (ti, tname)) in &ports.links {
        let from = ports.output(*fi, fname).unwrap_or(0);
        let to = ports.input(*ti, tname).unwrap_or(0);
        system.connect(Port::Output(ids[*fi], from), ids[*ti], to)?;
    }
    Ok((system, ids))
}

/// What a run records: the columns' names and types, the observer that keeps their values, and
/// which of them are text (recorded apart, their numbers NaN).
struct Recorded {
    columns: Vec<Column>,
    recorder: Columns,
    text_columns: Vec<usize>,
}

impl Recorded {
    fn of(plan: &Plan, ports: &Ports, ids: &[NodeId]) -> Recorded {
        let mut columns = Vec::new();
        let mut output_ports = Vec::new();
        let mut text_ports = Vec::new();
        let mut text_columns = Vec::new();
        for (c, (i, v, name)) in plan.recorded.iter().enumerate() {
            let port = Port::Output(ids[*i], ports.output(*i, &v.name).unwrap_or(0));
            output_ports.push(port);
            if v.scalar_type == ScalarType::String {
                text_ports.push(port);
                text_columns.push(c);
            }
            columns.push(Column {
                name: name.clone(),
                scalar_type: v.scalar_type,
            });
        }
        Recorded {
            columns,
            recorder: Columns {
                values: vec![Vec::new(); output_ports.len()],
                texts: vec![Vec::new(); text_ports.len()],
                ports: output_ports,
                text_ports,
                time: Vec::new(),
            },
            text_columns,
        }
    }

    /// The run's result once the system has run to `end`.
    fn result(self, plan: &Plan, end: RunEnd) -> RunResult {
        let mut values = self.recorder.values;
        for &c in &self.text_columns {
            values[c].iter_mut().for_each(|x| *x = f64::NAN);
        }
        RunResult {
            columns: self.columns,
            time: self.recorder.time,
            values,
            texts: self
                .text_columns
                .into_iter()
                .zip(self.recorder.texts)
                .collect(),
            start: plan.start,
            stop: plan.stop,
            step: plan.step,
            terminated: match end {
                RunEnd::Completed => None,
                RunEnd::Terminated { at, node } => Some((node, at)),
            },
        }
    }
}

/// Run the planned model: its ports, its FMUs initialised, the system wired, run and recorded.
fn execute(
    mut model: Model,
    plan: Plan,
    hold_inputs: bool,
    algorithm: Algorithm,
    progress: impl FnMut(u64, u64),
) -> Result<RunResult, RunError> {
    let ports = Ports::of(&model, &plan)?;
    let (loaded, instances) = instantiate(&mut model, &plan)?;
    let (mut system, ids) = wire(&model, &plan, &ports, instances, hold_inputs, algorithm)?;
    let mut recorded = Recorded::of(&plan, &ports, &ids);
    let end = system.run_at(&plan.times, &mut [&mut recorded.recorder], progress)?;
    // The instances go before the libraries they came from.
    drop(system);
    drop(loaded);
    Ok(recorded.result(&plan, end))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schedule_is_fmpys() {
        // Fixed step: stops at the last point not past the stop time.
        assert_eq!(schedule(0.0, 1.05, 0.5, &[], false), vec![0.0, 0.5, 1.0]);
        // Variable step: a last short step to the stop time, and input events in between.
        assert_eq!(
            schedule(0.0, 1.05, 0.5, &[0.7], true),
            vec![0.0, 0.5, 0.7, 1.0, 1.05]
        );
        // Points are start + k·h, never a running sum.
        let times = schedule(0.0, 1.0, 0.1, &[], false);
        assert_eq!(times.len(), 11);
        assert_eq!(times[3], 3.0 * 0.1);
        assert_eq!(times[10], 1.0);
    }

    #[test]
    fn reals_are_written_to_read_back_exactly() {
        for x in [
            0.0,
            -0.0,
            1.0 / 3.0,
            6.766057429708043e-10,
            -2.5e300,
            123456.789,
            1e15,
            1e-4,
        ] {
            let text = real_text(x);
            assert_eq!(
                text.parse::<f64>().expect("a number").to_bits(),
                x.to_bits(),
                "{text}"
            );
        }
        assert_eq!(real_text(6.766057429708043e-10), "6.766057429708043e-10");
        assert_eq!(real_text(0.25), "0.25");
    }

    #[test]
    fn auto_interval_gives_fmpys_round_steps() {
        assert_eq!(auto_interval(1.0), 0.002);
        assert_eq!(auto_interval(10.0), 0.02);
    }

    #[test]
    fn closest_names_are_suggested() {
        let names: Vec<String> = ["force", "control_force", "k1", "k2"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        assert_eq!(closest("forse", &names)[0], "force");
        assert!(closest("zzzzzzzz", &names).is_empty());
    }
}
