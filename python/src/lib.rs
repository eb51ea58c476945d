//! `shear_twin._native`: the orchestrator library as a Python extension module (PyO3).
//!
//! Thin, like the `twin` binary: Python arguments → the library's options → the work, with the
//! GIL released → numpy arrays and dicts back. Errors become Python exceptions carrying the
//! message the CLI prints (`{err:#}`, the error and its sources), and a panic anywhere below
//! becomes a `ShearTwinError` too, never a `PanicException` (which is no `Exception`).
//! The Python side (`shear_twin/__init__.py`) wraps the reports in objects.

use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

mod record;
mod run;
mod twin;

create_exception!(
    _native,
    ShearTwinError,
    PyException,
    "Every error of shear_twin; the message is the `twin` CLI's."
);
create_exception!(
    _native,
    DataError,
    ShearTwinError,
    "A measurement record that cannot be read or used (the file, line and problem)."
);
create_exception!(
    _native,
    TwinError,
    ShearTwinError,
    "A twin archive or FMU that cannot be opened or run."
);
create_exception!(
    _native,
    CalibrateError,
    ShearTwinError,
    "A calibration that cannot run or did not converge."
);
create_exception!(
    _native,
    DiagnoseError,
    ShearTwinError,
    "A diagnosis or an added effect that cannot be made."
);
create_exception!(
    _native,
    ControlError,
    ShearTwinError,
    "An LQR design or closed-loop run that cannot be made."
);
create_exception!(
    _native,
    WatchError,
    ShearTwinError,
    "A stream the watcher cannot follow."
);
create_exception!(
    _native,
    TrainError,
    ShearTwinError,
    "A GP corrector that cannot be trained or learned."
);
create_exception!(
    _native,
    RunError,
    ShearTwinError,
    "An FMU or SSP system that cannot be run (`twin run`), or an FMU that cannot be packed."
);
create_exception!(
    _native,
    HybridError,
    ShearTwinError,
    "A simulated hybrid test that cannot be set up or run."
);
create_exception!(
    _native,
    SynthError,
    ShearTwinError,
    "A synthetic scenario that cannot be made."
);

/// Which exception class an error becomes.
#[derive(Clone, Copy)]
pub(crate) enum Kind {
    Data,
    Twin,
    Calibrate,
    Diagnose,
    Control,
    Watch,
    Synth,
    Train,
    Run,
    Hybrid,
}

/// The error as the CLI prints it (`twin: error: {err:#}` without the prefix), as `kind`.
pub(crate) fn to_py(kind: Kind, err: impl Into<anyhow::Error>) -> PyErr {
    let message = format!("{:#}", err.into());
    match kind {
        Kind::Data => DataError::new_err(message),
        Kind::Twin => TwinError::new_err(message),
        Kind::Calibrate => CalibrateError::new_err(message),
        Kind::Diagnose => DiagnoseError::new_err(message),
        Kind::Control => ControlError::new_err(message),
        Kind::Watch => WatchError::new_err(message),
        Kind::Synth => SynthError::new_err(message),
        Kind::Train => TrainError::new_err(message),
        Kind::Run => RunError::new_err(message),
        Kind::Hybrid => HybridError::new_err(message),
    }
}

/// The message of an option Python passed that the library would refuse less clearly.
pub(crate) fn invalid(kind: Kind, message: impl Into<String>) -> PyErr {
    to_py(kind, anyhow::Error::msg(message.into()))
}

/// A keyword argument naming one of a CLI flag's values (`estimator="kalman"`), read as the
/// CLI reads `--FLAG VALUE`.
pub(crate) fn choice<T: orchestrator::choice::Choice>(
    kind: Kind,
    flag: &str,
    text: &str,
) -> PyResult<T> {
    T::from_name(text).ok_or_else(|| {
        invalid(
            kind,
            format!("--{flag} {text}: expected one of {}", T::names().join(", ")),
        )
    })
}

/// Run `work` without the GIL, a panic caught and turned into `ShearTwinError`.
pub(crate) fn detached<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> PyResult<T> + Send,
) -> PyResult<T> {
    py.detach(|| match catch_unwind(AssertUnwindSafe(work)) {
        Ok(result) => result,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(ShearTwinError::new_err(format!("internal error: {what}")))
        }
    })
}

/// A serde value (a report) as Python objects: dicts, lists, floats.
pub(crate) fn to_object<'py>(
    py: Python<'py>,
    value: &impl serde::Serialize,
) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, value).map_err(|e| ShearTwinError::new_err(e.to_string()))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    // The FMUs' log messages on stderr when TWIN_FMU_LOG is set, as `twin` prints them.
    if std::env::var_os("TWIN_FMU_LOG").is_some() {
        orchestrator::notice::set_sink(|n| {
            if n.topic == orchestrator::notice::Topic::FmuLog {
                eprintln!("{}", n.text);
            }
        });
    }
    m.add("ShearTwinError", py.get_type::<ShearTwinError>())?;
    m.add("DataError", py.get_type::<DataError>())?;
    m.add("TwinError", py.get_type::<TwinError>())?;
    m.add("CalibrateError", py.get_type::<CalibrateError>())?;
    m.add("DiagnoseError", py.get_type::<DiagnoseError>())?;
    m.add("ControlError", py.get_type::<ControlError>())?;
    m.add("WatchError", py.get_type::<WatchError>())?;
    m.add("SynthError", py.get_type::<SynthError>())?;
    m.add("TrainError", py.get_type::<TrainError>())?;
    m.add("RunError", py.get_type::<RunError>())?;
    m.add("HybridError", py.get_type::<HybridError>())?;
    m.add_class::<record::Record>()?;
    m.add_class::<twin::Twin>()?;
    m.add_function(wrap_pyfunction!(record::synth, m)?)?;
    m.add_function(wrap_pyfunction!(record::identify_modes, m)?)?;
    m.add_function(wrap_pyfunction!(run::run, m)?)?;
    m.add_function(wrap_pyfunction!(run::pack_fmu, m)?)?;
    m.add_function(wrap_pyfunction!(run::export_fmus, m)?)?;
    m.add_function(wrap_pyfunction!(twin::read_frf, m)?)?;
    Ok(())
}
