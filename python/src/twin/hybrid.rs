//! `Twin`'s simulated real-time hybrid tests: the threshold of the bumper's contact and one run.

use super::Twin;
use crate::{choice, detached, invalid, to_object, to_py, Kind};
use pyo3::prelude::*;
use std::path::PathBuf;

#[pymethods]
impl Twin {
    /// `twin hybrid threshold`: the simulated real-time hybrid test on this twin's structure —
    /// the peak excitation force at which the bumper above the driven floor first closes, for
    /// each amplitude error `a_err` (default −0.1 to 0.1 by 0.02), the structure (the twin's,
    /// any storey count) cut as `split` says (`--split`: "J" or a name; default the paper's cut
    /// at floor 2, "specimen-floors-2-3" on three storeys). Returns the CLI's report.
    #[pyo3(signature = (*, a_err = None, excitation = None, seed = None, duration = None,
                        sample_rate = None, substeps = None, gap = None,
                        contact_stiffness = None, delay = None, lag = None, compensate = None,
                        energy_factor = None, split = None, coupling = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn hybrid_threshold<'py>(
        &self,
        py: Python<'py>,
        a_err: Option<Vec<f64>>,
        excitation: Option<PathBuf>,
        seed: Option<u64>,
        duration: Option<f64>,
        sample_rate: Option<f64>,
        substeps: Option<u32>,
        gap: Option<f64>,
        contact_stiffness: Option<f64>,
        delay: Option<f64>,
        lag: Option<f64>,
        compensate: Option<usize>,
        energy_factor: Option<f64>,
        split: Option<&str>,
        coupling: Option<&str>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kind = Kind::Hybrid;
        let options = hybrid_options(
            excitation,
            seed,
            duration,
            sample_rate,
            substeps,
            gap,
            contact_stiffness,
            delay,
            lag,
            compensate,
            energy_factor,
            split,
            coupling,
        )?;
        let report = detached(py, || {
            let (report, curve, _) = orchestrator::workflows::hybrid::options::threshold(
                &self.twin,
                &options,
                a_err.as_deref(),
            )
            .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let svg = orchestrator::report::hybrid_plot::threshold_svg(&curve)
                    .map_err(|m| invalid(kind, m))?;
                orchestrator::fsutil::write_text_atomically(path, &svg)
                    .map_err(|e| to_py(kind, e))?;
            }
            serde_json::to_value(&report).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &report)
    }

    /// `twin hybrid run`: the simulated real-time hybrid test on this twin's structure at
    /// `peak` N (5) for each amplitude error `a_err` (default 0 and 0.05): contacts, floor 2's
    /// spectrum and harmonics, the contact law identified from the interface measured with
    /// `displacement_noise` (1 µm), `force_noise` (1 mN) and, when the specimen holds floor 2,
    /// its accelerometer's `acceleration_noise` (1 mm/s²). Returns the CLI's report.
    #[pyo3(signature = (*, peak = None, a_err = None, displacement_noise = None,
                        force_noise = None, acceleration_noise = None, excitation = None, seed = None, duration = None,
                        sample_rate = None, substeps = None, gap = None,
                        contact_stiffness = None, delay = None, lag = None, compensate = None,
                        energy_factor = None, split = None, coupling = None, plot = None))]
    #[allow(clippy::too_many_arguments)]
    fn hybrid_run<'py>(
        &self,
        py: Python<'py>,
        peak: Option<f64>,
        a_err: Option<Vec<f64>>,
        displacement_noise: Option<f64>,
        force_noise: Option<f64>,
        acceleration_noise: Option<f64>,
        excitation: Option<PathBuf>,
        seed: Option<u64>,
        duration: Option<f64>,
        sample_rate: Option<f64>,
        substeps: Option<u32>,
        gap: Option<f64>,
        contact_stiffness: Option<f64>,
        delay: Option<f64>,
        lag: Option<f64>,
        compensate: Option<usize>,
        energy_factor: Option<f64>,
        split: Option<&str>,
        coupling: Option<&str>,
        plot: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        use orchestrator::workflows::hybrid::experiment::InterfaceNoise;
        let kind = Kind::Hybrid;
        let options = hybrid_options(
            excitation,
            seed,
            duration,
            sample_rate,
            substeps,
            gap,
            contact_stiffness,
            delay,
            lag,
            compensate,
            energy_factor,
            split,
            coupling,
        )?;
        let d = InterfaceNoise::default();
        let noise = InterfaceNoise {
            displacement: displacement_noise.unwrap_or(d.displacement),
            force: force_noise.unwrap_or(d.force),
            acceleration: acceleration_noise.unwrap_or(d.acceleration),
            seed: options.seed,
        };
        let peak = peak.unwrap_or(orchestrator::workflows::hybrid::options::RUN_PEAK);
        let report = detached(py, || {
            let (report, outcomes, setup) = orchestrator::workflows::hybrid::options::run(
                &self.twin,
                &options,
                peak,
                a_err.as_deref(),
                noise,
            )
            .map_err(|e| to_py(kind, e))?;
            if let Some(path) = &plot {
                let svg = orchestrator::report::hybrid_plot::runs_svg(&outcomes, setup.dt)
                    .map_err(|m| invalid(kind, m))?;
                orchestrator::fsutil::write_text_atomically(path, &svg)
                    .map_err(|e| to_py(kind, e))?;
            }
            serde_json::to_value(&report).map_err(|e| to_py(kind, e))
        })?;
        to_object(py, &report)
    }
}

/// `twin hybrid`'s shared options from keyword arguments (None: the library's default).
#[allow(clippy::too_many_arguments)]
fn hybrid_options(
    excitation: Option<PathBuf>,
    seed: Option<u64>,
    duration: Option<f64>,
    sample_rate: Option<f64>,
    substeps: Option<u32>,
    gap: Option<f64>,
    contact_stiffness: Option<f64>,
    delay: Option<f64>,
    lag: Option<f64>,
    compensate: Option<usize>,
    energy_factor: Option<f64>,
    split: Option<&str>,
    coupling: Option<&str>,
) -> PyResult<orchestrator::workflows::hybrid::options::HybridOptions> {
    let d = orchestrator::workflows::hybrid::options::HybridOptions::default();
    Ok(orchestrator::workflows::hybrid::options::HybridOptions {
        excitation,
        seed: seed.unwrap_or(d.seed),
        duration: duration.unwrap_or(d.duration),
        sample_rate: sample_rate.unwrap_or(d.sample_rate),
        substeps: substeps.unwrap_or(d.substeps),
        gap: gap.unwrap_or(d.gap),
        contact_stiffness: contact_stiffness.unwrap_or(d.contact_stiffness),
        delay: delay.unwrap_or(d.delay),
        lag: lag.unwrap_or(d.lag),
        compensate: compensate.or(d.compensate),
        energy_factor: energy_factor.unwrap_or(d.energy_factor),
        storeys: None,
        split: match split {
            Some(text) => Some(
                text.parse()
                    .map_err(|m: String| invalid(Kind::Hybrid, format!("--split: {m}")))?,
            ),
            None => d.split,
        },
        coupling: match coupling {
            Some(c) => choice(Kind::Hybrid, "coupling", c)?,
            None => d.coupling,
        },
    })
}
