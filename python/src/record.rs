//! `Record`: a measurement (`time`, the excitation `force` or `ground_acc`, responses `acc<i>`,
//! `vel<i>`, `disp<i>`, units in the names), from a CSV file or numpy arrays;
//! `synth`: a synthetic record with hidden effects and its truth.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use numpy::{PyArray1, PyReadonlyArray1};
use orchestrator::record::{csv_text, ColumnMap, Measurement, ReadOptions};
use orchestrator::synth::{synth_controlled, InLoopController, Scenario};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::{detached, to_object, to_py, Kind};

/// A measurement record: time (s), the excitation (`force`, N, or `ground_acc`, m/s²) and
/// the measured responses (`acc<i>`, `vel<i>`, `disp<i>`), in SI on the nominal sampling grid;
/// a `control` column kept by name.
#[pyclass(module = "shear_twin._native", frozen)]
pub struct Record {
    pub(crate) measurement: Measurement,
}

fn column(values: &[f64], py: Python<'_>) -> Py<PyAny> {
    PyArray1::from_slice(py, values).into_any().unbind()
}

impl Record {
    /// The record checked against `twin` by the library's one guard (`twin::guard`) before any
    /// work; `DataError` names the column.
    pub(crate) fn for_twin(&self, twin: &orchestrator::twin::Twin) -> PyResult<&Measurement> {
        orchestrator::twin::guard::check_record(twin, &self.measurement)
            .map_err(|e| to_py(Kind::Data, e))?;
        Ok(&self.measurement)
    }
}

/// A column map from a dict (`{"dotx1 (m/s)": "vel1"}`) or the path of a MAP.json.
pub(crate) fn column_map(columns: Option<&Bound<'_, PyAny>>) -> PyResult<ColumnMap> {
    let Some(columns) = columns else {
        return Ok(ColumnMap::default());
    };
    if let Ok(map) = columns.extract::<std::collections::BTreeMap<String, String>>() {
        return ColumnMap::new(map).map_err(|e| to_py(Kind::Data, anyhow::anyhow!(e)));
    }
    let path: PathBuf = columns.extract()?;
    ColumnMap::read(&path).map_err(|e| to_py(Kind::Data, e))
}

#[pymethods]
impl Record {
    /// A record from arrays: `time`, `force` and one acceleration per floor, `acc1..accN` in
    /// floor order (1-D float arrays of one length; the paper's rig: `acc1, acc2, acc3`),
    /// checked as a CSV file is; `extra` more named columns (e.g. `control`). Other channels
    /// and units: [`Record::from_arrays`].
    #[new]
    #[pyo3(signature = (time, force, *acc, extra = None, name = "<arrays>"))]
    fn new(
        time: PyReadonlyArray1<'_, f64>,
        force: PyReadonlyArray1<'_, f64>,
        acc: &Bound<'_, PyTuple>,
        extra: Option<HashMap<String, PyReadonlyArray1<'_, f64>>>,
        name: &str,
    ) -> PyResult<Self> {
        let extra = extra
            .unwrap_or_default()
            .into_iter()
            .map(|(k, v)| (k, v.as_array().to_vec()))
            .collect();
        let vec = |a: &PyReadonlyArray1<'_, f64>| a.as_array().to_vec();
        let acc = acc
            .iter()
            .map(|a| Ok(vec(&a.extract::<PyReadonlyArray1<'_, f64>>()?)))
            .collect::<PyResult<Vec<_>>>()?;
        let measurement =
            Measurement::from_columns(Path::new(name), vec(&time), vec(&force), acc, extra)
                .map_err(|e| to_py(Kind::Data, e))?;
        Ok(Record { measurement })
    }

    /// Read a measurement CSV (`columns`: a column map, a dict or a MAP.json path, as `twin
    /// --columns`); a bad file raises `DataError` naming the file, line and problem.
    #[staticmethod]
    #[pyo3(signature = (path, *, columns = None))]
    fn read(py: Python<'_>, path: PathBuf, columns: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let columns = column_map(columns)?;
        let measurement = detached(py, || {
            Measurement::read_with(&path, &ReadOptions { columns })
                .map_err(|e| to_py(Kind::Data, e))
        })?;
        Ok(Record { measurement })
    }

    /// A record from named arrays: `{"time": ..., "ground_acc (g)": ..., "acc2": ...}` (names
    /// as a CSV header has them, mapped through `columns`), checked as a CSV file is.
    #[staticmethod]
    #[pyo3(signature = (arrays, *, columns = None, name = "<arrays>"))]
    fn from_arrays(
        arrays: &Bound<'_, PyDict>,
        columns: Option<&Bound<'_, PyAny>>,
        name: &str,
    ) -> PyResult<Self> {
        let columns = column_map(columns)?;
        let mut named = Vec::with_capacity(arrays.len());
        for (key, value) in arrays.iter() {
            let values: PyReadonlyArray1<'_, f64> = value.extract()?;
            named.push((key.extract::<String>()?, values.as_array().to_vec()));
        }
        let measurement = Measurement::from_named_columns(Path::new(name), named, &columns)
            .map_err(|e| to_py(Kind::Data, e))?;
        Ok(Record { measurement })
    }

    /// The measured channels' names, the excitation first (`["force", "acc1", ...]`).
    #[getter]
    fn channels(&self) -> Vec<String> {
        self.measurement.channel_names()
    }

    /// Write the record as the measurement CSV `twin` reads.
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let text = csv_text(&self.measurement);
        detached(py, || {
            orchestrator::fsutil::write_text_atomically(&path, &text)
                .map_err(|e| to_py(Kind::Data, e))
        })
    }

    /// Where the record came from (a file, or the name given to arrays).
    #[getter]
    fn path(&self) -> String {
        self.measurement.path.display().to_string()
    }

    /// The sampling interval, s.
    #[getter]
    fn dt(&self) -> f64 {
        self.measurement.dt
    }

    /// The record's length, s.
    #[getter]
    fn duration(&self) -> f64 {
        self.measurement.duration()
    }

    fn __len__(&self) -> usize {
        self.measurement.len()
    }

    /// The columns as numpy arrays (SI), by name (`pandas.DataFrame(record.to_dict())`).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = &self.measurement;
        let d = PyDict::new(py);
        d.set_item("time", column(&m.time, py))?;
        for signal in m.channels() {
            d.set_item(signal.channel.name(), column(&signal.values, py))?;
        }
        let mut names: Vec<&String> = m.extra.keys().collect();
        names.sort();
        for name in names {
            d.set_item(name, column(&m.extra[name], py))?;
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "Record('{}', {} samples at {} Hz)",
            self.path(),
            self.measurement.len(),
            1.0 / self.measurement.dt
        )
    }
}

/// A synthetic record of `twin synth`'s structure: `scenario` is the scenario JSON as a dict
/// (see `twin synth --help`; every field optional). Returns the record and the truth (a dict:
/// what the data file does not say). With `out`, the record is also written there; with
/// `controller` (a `twin control` report, its path or the dict), its design `controller_q`
/// (default: the first stable one) runs in the structure's loop and the record gets a
/// `control` column.
#[pyfunction]
#[pyo3(signature = (scenario, out = None, *, controller = None, controller_q = None))]
pub fn synth<'py>(
    py: Python<'py>,
    scenario: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
    controller: Option<&Bound<'py, PyAny>>,
    controller_q: Option<f64>,
) -> PyResult<(Record, Bound<'py, PyAny>)> {
    let value: serde_json::Value =
        pythonize::depythonize(scenario).map_err(|e| to_py(Kind::Synth, anyhow::anyhow!(e)))?;
    let spec = controller
        .map(|c| crate::twin::controller_spec(Kind::Synth, c))
        .transpose()?;
    let (mut measurement, truth) = detached(py, || {
        let scenario =
            Scenario::from_json(&value, "scenario").map_err(|e| to_py(Kind::Synth, e))?;
        let control = spec
            .map(|spec| InLoopController::from_report(spec, controller_q, scenario.seed))
            .transpose()
            .map_err(|e| to_py(Kind::Synth, e))?;
        let (record, truth) =
            synth_controlled(&scenario, control).map_err(|e| to_py(Kind::Synth, e))?;
        let truth = serde_json::to_value(&truth).map_err(|e| to_py(Kind::Synth, e))?;
        Ok((record.measurement, truth))
    })?;
    if let Some(path) = &out {
        let text = csv_text(&measurement);
        detached(py, || {
            orchestrator::fsutil::write_text_atomically(path, &text)
                .map_err(|e| to_py(Kind::Synth, e))
        })?;
        measurement.path = path.clone();
    }
    Ok((Record { measurement }, to_object(py, &truth)?))
}

/// `twin modal --data RUN1 --data RUN2 …`: the modes of one record or of several runs of one
/// test, identified as the CLI does (LSCF through a measured force, SSI-COV, FDD/EFDD, the
/// methods' verdicts side by side). Runs that share their response channels average together;
/// runs that each measured other floors with the same measured force (a roving accelerometer)
/// merge into one set of modes with shapes at every floor any run measured. Returns the CLI
/// report's `record` object; `DataError` when the runs cannot be one test.
#[pyfunction]
pub fn identify_modes<'py>(
    py: Python<'py>,
    records: Vec<PyRef<'py, Record>>,
) -> PyResult<Bound<'py, PyAny>> {
    if records.is_empty() {
        return Err(to_py(
            Kind::Data,
            anyhow::anyhow!("identify_modes: no record given"),
        ));
    }
    let runs: Vec<Measurement> = records.iter().map(|r| r.measurement.clone()).collect();
    let options = orchestrator::workflows::modal::IdentifyOptions::default();
    let found = detached(py, || {
        orchestrator::workflows::modal::identify(&runs, &options).map_err(|e| to_py(Kind::Data, e))
    })?;
    to_object(py, &found)
}
