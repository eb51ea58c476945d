//! Running a twin on a measurement: the system of the twin's FMUs, the measured force replayed
//! as its input, the accelerations recorded.

use std::time::{Duration, Instant};

use crate::cosim::import::Instance;
use crate::cosim::master::{Clock, MasterError, Port, Recorder, System};
use crate::evaluation::compare::{compare, CompareOptions, Comparison};
use crate::evaluation::stats::variance;
use crate::twin::data::Measurement;
use crate::twin::{Twin, TwinError, OUTPUTS};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Twin(#[from] TwinError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error("twin: {0}")]
    Wiring(String),
}

/// Predicted accelerations at every sample of the measurement.
#[derive(Debug, Clone)]
pub struct Prediction {
    pub time: Vec<f64>,
    pub acc: [Vec<f64>; 3],
    /// The corrector's latent variance V(f) per floor, when the twin has a corrector.
    pub latent_var: Option<[Vec<f64>; 3]>,
    /// The corrector's predictive standard deviation per floor, likewise.
    pub sd: Option<[Vec<f64>; 3]>,
}

/// Calls `on_progress(done, total)`, but only once a run has lasted more than a second, so short
/// runs print nothing.
pub struct Progress<F: FnMut(u64, u64)> {
    started: Instant,
    report: F,
}

impl<F: FnMut(u64, u64)> Progress<F> {
    pub fn new(report: F) -> Self {
        Progress {
            started: Instant::now(),
            report,
        }
    }
    pub fn tick(&mut self, done: u64, total: u64) {
        if self.started.elapsed() > Duration::from_secs(1) {
            (self.report)(done, total);
        }
    }
}

/// Run `twin` on `data`'s force (the control force, if the data has a `control` column and the
/// twin takes it, is replayed too).
pub fn run_twin(
    twin: &Twin,
    data: &Measurement,
    mut progress: impl FnMut(u64, u64),
) -> Result<Prediction, RunError> {
    let start = data.time[0];
    let instances = twin.instantiate(start)?;
    let mut system = System::new();
    let mut nodes = Vec::new();
    // Keep the FMUs loaded for as long as their instances run.
    let mut loaded = Vec::new();
    for (component, fmu, instance) in instances {
        // Ports: every connector the twin's connections use on this component.
        let inputs: Vec<String> = twin
            .connections
            .iter()
            .filter(|c| c.end_element.as_deref() == Some(&component.name))
            .map(|c| c.end_connector.clone())
            .collect();
        let outputs: Vec<String> = twin
            .connections
            .iter()
            .filter(|c| c.start_element.as_deref() == Some(&component.name))
            .map(|c| c.start_connector.clone())
            .collect();
        let vr = |name: &String| fmu.value_reference(name).map_err(TwinError::from);
        let input_vrs = inputs.iter().map(vr).collect::<Result<Vec<_>, _>>()?;
        let output_vrs = outputs.iter().map(vr).collect::<Result<Vec<_>, _>>()?;
        let boxed: Box<Instance> = Box::new(instance);
        let id = system.add_slave(&component.name, boxed, input_vrs, output_vrs);
        nodes.push((component.name.clone(), id, inputs, outputs));
        loaded.push(fmu);
    }
    let signal_for = |name: &str| -> Option<Vec<f64>> {
        match name {
            "force" => Some(data.force.clone()),
            "control_force" => data.extra.get("control").cloned(),
            _ => None,
        }
    };
    // Ports by name: (node, index of the named connector among its inputs or outputs).
    let find_node = |name: &str| {
        nodes
            .iter()
            .find(|(n, ..)| n == name)
            .ok_or_else(|| RunError::Wiring(format!("no component '{name}'")))
    };
    let port_of =
        |names: &[String], connector: &str| names.iter().position(|c| c == connector).unwrap_or(0);
    let mut signals = std::collections::HashMap::new();
    for conn in &twin.connections {
        let Some(end) = &conn.end_element else {
            continue;
        };
        let (_, to, inputs, _) = find_node(end)?;
        let port_index = port_of(inputs, &conn.end_connector);
        let from = match &conn.start_element {
            None => {
                let Some(samples) = signal_for(&conn.start_connector) else {
                    continue;
                };
                *signals
                    .entry(conn.start_connector.clone())
                    .or_insert_with(|| system.add_signal(&conn.start_connector, samples))
            }
            Some(start_el) => {
                let (_, from_id, _, outputs) = find_node(start_el)?;
                Port::Output(*from_id, port_of(outputs, &conn.start_connector))
            }
        };
        system.connect(from, *to, port_index)?;
    }
    let mut watched = Vec::new();
    let system_outputs = twin.system_outputs();
    let optional = [
        "latent_var1",
        "latent_var2",
        "latent_var3",
        "sd1",
        "sd2",
        "sd3",
    ];
    for output in OUTPUTS.iter().chain(
        optional
            .iter()
            .filter(|o| system_outputs.iter().any(|s| s == *o)),
    ) {
        let conn = twin
            .connections
            .iter()
            .find(|c| c.end_element.is_none() && c.end_connector == *output)
            .ok_or_else(|| {
                RunError::Wiring(format!("no connection feeds the system output '{output}'"))
            })?;
        let start_el = conn
            .start_element
            .as_ref()
            .ok_or_else(|| RunError::Wiring(format!("'{output}' is fed by no component")))?;
        let (_, id, _, outputs) = find_node(start_el)?;
        watched.push((
            (*output).to_owned(),
            Port::Output(*id, port_of(outputs, &conn.start_connector)),
        ));
    }
    let mut recorder = Recorder::new(watched);
    let clock = Clock::new(start, data.dt, (data.len() - 1) as u64);
    system.run(clock, &mut [&mut recorder], &mut progress)?;
    drop(system);
    drop(loaded);
    let column = |name: &str| recorder.column(name).map(<[f64]>::to_vec);
    let triple = |prefix: &str| -> Option<[Vec<f64>; 3]> {
        Some([
            column(&format!("{prefix}1"))?,
            column(&format!("{prefix}2"))?,
            column(&format!("{prefix}3"))?,
        ])
    };
    let acc = triple("acc")
        .ok_or_else(|| RunError::Wiring("the accelerations were not recorded".into()))?;
    Ok(Prediction {
        time: recorder.time.clone(),
        acc,
        latent_var: triple("latent_var"),
        sd: triple("sd"),
    })
}

/// Noise variance when the twin has none (not calibrated): 2 % of each floor's measured
/// variance, the centre the calibration's noise prior uses.
pub const PRIOR_NOISE_FRACTION: f64 = 0.02;

/// A twin run on a record and compared with it.
pub struct Compared {
    pub prediction: Prediction,
    pub comparison: Comparison,
    /// The ±3σ band's noise variances: the twin's, else [`PRIOR_NOISE_FRACTION`] of the record's.
    pub noise_variance: [f64; 3],
    pub noise_source: &'static str,
}

/// Run `twin` on `data` and compare the accelerations after `transient`: the one sequence
/// behind `twin compare`, the calibrated twin's plot and the NMSE after calibrating or training.
pub fn run_and_compare(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    progress: impl FnMut(u64, u64),
) -> Result<Compared, RunError> {
    let prediction = run_twin(twin, data, progress)?;
    Ok(compare_prediction(twin, data, transient, prediction))
}

/// Compare a prediction the twin made some other way (e.g. in a closed loop) with `data`, as
/// [`run_and_compare`] does.
pub fn compare_prediction(
    twin: &Twin,
    data: &Measurement,
    transient: f64,
    prediction: Prediction,
) -> Compared {
    let (noise_variance, noise_source) = match twin.noise_variance {
        Some(v) => (v, "twin (calibrated)"),
        None => (
            [0, 1, 2].map(|f| PRIOR_NOISE_FRACTION * variance(&data.acc[f])),
            "prior: 2 % of the measured variance",
        ),
    };
    let options = CompareOptions {
        transient,
        ..CompareOptions::default()
    };
    let comparison = compare(
        &data.time,
        &data.acc,
        &prediction.acc,
        noise_variance,
        prediction.sd.as_ref(),
        options,
    );
    Compared {
        prediction,
        comparison,
        noise_variance,
        noise_source,
    }
}

/// NMSE per floor of `twin` on `data` after the transient.
pub fn nmse_on(twin: &Twin, data: &Measurement, transient: f64) -> Result<[f64; 3], RunError> {
    Ok(run_and_compare(twin, data, transient, |_, _| {})?
        .comparison
        .nmse)
}
