//! `run`: any FMI 2.0 co-simulation FMU or SSP system, its outputs as arrays (`twin run`);
//! `pack_fmu`: a built FMU library into a `.fmu` (`twin pack-fmu`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use orchestrator::cosim::master::Algorithm;
use orchestrator::cosim::run::RunOptions;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{choice, detached, to_py, Kind};

/// `twin run`: run `model` (a `.fmu` or `.ssp`) and record its outputs. `start`, `stop`,
/// `step`: as the CLI's (None: the model's DefaultExperiment, then fmpy's rules); `input`: a
/// CSV (`time`, then columns named like the inputs); `sets`: start values by name
/// (`component.variable` in a system). Returns `(columns, info)`: the recorded columns by
/// name (`time` first) as numpy arrays (a String column as a list), and `start`, `stop`,
/// `step`, `terminated` (the component that ended the run and when, or None).
#[pyfunction]
#[pyo3(signature = (model, *, start = None, stop = None, step = None, input = None,
                    sets = None, output_all = false, hold_inputs = false, algorithm = None,
                    plot = None))]
#[allow(clippy::too_many_arguments)]
pub fn run<'py>(
    py: Python<'py>,
    model: PathBuf,
    start: Option<f64>,
    stop: Option<f64>,
    step: Option<f64>,
    input: Option<PathBuf>,
    sets: Option<BTreeMap<String, Bound<'py, PyAny>>>,
    output_all: bool,
    hold_inputs: bool,
    algorithm: Option<&str>,
    plot: Option<PathBuf>,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
    let kind = Kind::Run;
    if let Some(plot) = &plot {
        if plot.extension().and_then(|e| e.to_str()) != Some("svg") {
            return Err(crate::invalid(
                kind,
                format!("--plot {}: only .svg is supported", plot.display()),
            ));
        }
    }
    let mut texts = Vec::new();
    for (name, value) in sets.unwrap_or_default() {
        // As `--set NAME=VALUE` is read: the value's text (Python's bools as the CLI's).
        let text = if let Ok(b) = value.extract::<bool>() {
            b.to_string()
        } else {
            value.str()?.to_string()
        };
        texts.push(format!("{name}={text}"));
    }
    let options = RunOptions {
        start,
        stop,
        step,
        input,
        sets: texts,
        output_all,
        hold_inputs,
        algorithm: match algorithm {
            Some(a) => choice::<Algorithm>(kind, "algorithm", a)?,
            None => RunOptions::default().algorithm,
        },
    };
    let result = detached(py, || {
        let result = orchestrator::cosim::run::run(&model, &options, |_, _| {})
            .map_err(|e| to_py(kind, e))?;
        if let Some(plot) = &plot {
            let title = model
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let svg = orchestrator::report::run_plot::plot_run(&result, &title).map_err(|m| {
                crate::invalid(kind, format!("cannot draw {}: {m}", plot.display()))
            })?;
            orchestrator::fsutil::write_text_atomically(plot, &svg).map_err(|e| to_py(kind, e))?;
        }
        Ok(result)
    })?;
    let columns = PyDict::new(py);
    columns.set_item("time", numpy::PyArray1::from_slice(py, &result.time))?;
    for (c, column) in result.columns.iter().enumerate() {
        match result.texts.get(&c) {
            Some(texts) => columns.set_item(&column.name, texts.clone())?,
            None => columns.set_item(
                &column.name,
                numpy::PyArray1::from_slice(py, &result.values[c]),
            )?,
        }
    }
    let info = PyDict::new(py);
    info.set_item("start", result.start)?;
    info.set_item("stop", result.stop)?;
    info.set_item("step", result.step)?;
    info.set_item("terminated", result.terminated.clone())?;
    Ok((columns, info))
}

/// `twin pack-fmu`: a built FMU library and its modelDescription.xml into a `.fmu` archive at
/// `out`. Returns the modelIdentifier.
#[pyfunction]
#[pyo3(signature = (model_description, library, out, *, documentation = None, resources = None))]
pub fn pack_fmu(
    py: Python<'_>,
    model_description: PathBuf,
    library: PathBuf,
    out: PathBuf,
    documentation: Option<PathBuf>,
    resources: Option<PathBuf>,
) -> PyResult<String> {
    let contents = orchestrator::cosim::pack::FmuContents {
        model_description,
        library,
        documentation,
        resources,
    };
    detached(py, || {
        orchestrator::cosim::pack::pack_fmu(&contents, &out).map_err(|e| to_py(Kind::Run, e))
    })
}

/// `twin export-fmus`: the FMUs built into this package (shear, GP corrector, LQR,
/// substructure) written as `out/<modelIdentifier>.fmu`, for other FMI tools. Returns their
/// paths.
#[pyfunction]
pub fn export_fmus(py: Python<'_>, out: PathBuf) -> PyResult<Vec<PathBuf>> {
    detached(py, || {
        orchestrator::twin::embedded::export(&out).map_err(|e| {
            to_py(
                Kind::Run,
                anyhow::Error::from(e).context(format!("writing the FMUs into {}", out.display())),
            )
        })
    })
}
