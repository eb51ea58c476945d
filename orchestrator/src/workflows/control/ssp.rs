//! `twin control --ssp`: the controlled system as an SSP 1.0 archive any SSP tool runs — the
//! twin's shear FMU with its parameters, and the controller as the `fmu_lqr` FMU (the same
//! `numerics::lqr` law as the master's `LqrBlock`) with a design's gain and the report's
//! estimator, sampling at the report's control rate.
//!
//! Connections: the system's excitation (`force` or `ground_acc`) → the physics' and the
//! controller's; the measured channels (`physics.acc1`, `physics.vel3`, …: the report's
//! `measured`) → the controller's inputs of those names; `lqr.control_force` →
//! `physics.control_force` (the physics FMU's control force on the report's actuator floor);
//! system outputs every floor's `acc<i>` (the physics') and `control_force` (the
//! controller's). The controller FMU is the built-in library with the modelDescription of the
//! report's layout (structure, actuator, channels) and that layout in
//! `resources/structure.json`; for the paper's rig, the built-in FMU as it is. The noise-free
//! loop: the sensor noise of a `twin control` run is not part of it.
//!
//! What the masters make of it (the controller's output has no feedthrough, the shear's `acc1`
//! has: it jumps with `force − control_force`). In every case the structure steps over
//! `[t_k, t_{k+1}]` with the command the controller computed at its step from `t_{k−1}`:
//! - a Jacobi master (`twin run --algorithm jacobi`; fmpy's `simulate_ssp`, which also hands the
//!   system input to the components a step late) gives the controller the accelerations as the
//!   structure's last step left them, before the new command acts: the system `twin control`
//!   runs with its block and sampled connections;
//! - a Gauss–Seidel master (`twin run`'s default) sets the new command first and gives the
//!   controller the accelerations at `t_k` with it acting: floor 1's reading differs by
//!   `(u_{k−2} − u_{k−1})/m1`, a slightly different (still stable) system.
//!
//! SSP 1.0's `DefaultExperiment` has no step: both FMUs declare 1/51.2 s, the step `twin run`
//! takes by default; at another control rate give `--step` (the controller refuses any other
//! step, saying which it needs).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{ControlError, ControllerSpec};
use crate::twin::{find_fmu, Component, Connection, ParameterValue, Twin, PHYSICS};
use numerics::lqr::Estimator;

/// The controller component's name.
pub const CONTROLLER: &str = "lqr";
/// The controller FMU's archive name.
pub const LQR_FMU: &str = "fmu_lqr.fmu";

/// The `fmu_lqr` parameters of design `q` (None: the first stable one) of `spec`.
pub fn controller_parameters(
    spec: &ControllerSpec,
    q: Option<f64>,
) -> Result<BTreeMap<String, ParameterValue>, ControlError> {
    let design = spec.design(q)?;
    let structure = spec.structure()?;
    if !(spec.control_rate_hz.is_finite() && spec.control_rate_hz > 0.0) {
        return Err(ControlError::Options(format!(
            "the report's control rate {} Hz is not positive",
            spec.control_rate_hz
        )));
    }
    let mut p = BTreeMap::new();
    let mut real = |name: String, x: f64| {
        p.insert(name, ParameterValue::Real(x));
    };
    for (i, g) in design.gain.iter().enumerate() {
        real(format!("gain{}", i + 1), *g);
    }
    real("state_scale".into(), spec.state_scale);
    for (name, value) in structure
        .parameter_names()
        .into_iter()
        .zip(structure.parameters())
    {
        real(name, value);
    }
    real("sample_interval".into(), 1.0 / spec.control_rate_hz);
    let estimator = match &spec.estimator_settings {
        Estimator::Integrate { highpass_hz } => {
            real("highpass_hz".into(), *highpass_hz);
            0
        }
        Estimator::Kalman {
            process_sd,
            sensor_sd,
        } => {
            real("process_sd".into(), *process_sd);
            for (i, s) in sensor_sd.iter().enumerate() {
                real(format!("sensor_sd{}", i + 1), *s);
            }
            1
        }
    };
    p.insert("estimator".into(), ParameterValue::Integer(estimator));
    Ok(p)
}

fn link(from: Option<&str>, out: &str, to: Option<&str>, input: &str) -> Connection {
    Connection {
        start_element: from.map(str::to_owned),
        start_connector: out.to_owned(),
        end_element: to.map(str::to_owned),
        end_connector: input.to_owned(),
    }
}

/// The controller FMU's layout for `spec`: its structure, actuator floor and measured channels.
pub fn controller_layout(spec: &ControllerSpec) -> Result<fmu_lqr::model::Layout, ControlError> {
    fmu_lqr::model::Layout {
        structure: spec.structure()?,
        actuator_floor: spec.actuator_floor(),
        measured: spec.measured()?,
    }
    .checked()
    .map_err(|e| ControlError::Options(format!("the report's controller: {e}")))
}

/// The controller FMU for `layout`: the built-in one for the paper's rig, else the built-in
/// library with the modelDescription of that layout's table and `resources/structure.json`,
/// written into `dir`.
fn controller_fmu(layout: &fmu_lqr::model::Layout, dir: &Path) -> Result<PathBuf, ControlError> {
    if layout.is_paper() {
        return Ok(find_fmu(LQR_FMU)?);
    }
    let xml = fmu_lqr::variables::table(layout).to_model_description_xml();
    let json = serde_json::to_string_pretty(layout)
        .map_err(|e| ControlError::Options(format!("the controller's layout as JSON: {e}")))?;
    let bytes = crate::twin::structure::fmu_for_structure(LQR_FMU, &xml, &json)?;
    let path = dir.join(LQR_FMU);
    std::fs::write(&path, bytes)
        .map_err(|e| ControlError::Twin(format!("{}: {e}", path.display())))?;
    Ok(path)
}

/// The controlled system: `twin`'s physics component (with its control force on the
/// actuator's floor) and the controller of design `q`, with `experiment` (start, stop) as its
/// DefaultExperiment. `lqr_fmu`: the controller FMU (None: the built-in one, written for the
/// report's layout).
pub fn controlled_system(
    twin: &Twin,
    spec: &ControllerSpec,
    q: Option<f64>,
    experiment: Option<(f64, f64)>,
    lqr_fmu: Option<PathBuf>,
) -> Result<Twin, ControlError> {
    let layout = controller_layout(spec)?;
    let mut system = super::with_actuator_at(twin, layout.actuator_floor)?;
    let physics = system
        .component(PHYSICS)
        .ok_or_else(|| {
            ControlError::Twin(format!("{} has no '{PHYSICS}' component", twin.describe()))
        })?
        .clone();
    let dir = tempfile::tempdir()
        .map_err(|e| ControlError::Twin(format!("a temporary directory: {e}")))?;
    let fmu_path = match lqr_fmu {
        Some(p) => p,
        None => controller_fmu(&layout, dir.path())?,
    };
    system.keep_alive(std::sync::Arc::new(dir));
    let controller = Component {
        name: CONTROLLER.into(),
        fmu_name: LQR_FMU.into(),
        fmu_path,
        parameters: controller_parameters(spec, q)?,
    };
    let input = layout.structure.excitation.input_name();
    let mut connections = vec![
        link(None, input, Some(PHYSICS), input),
        link(None, input, Some(CONTROLLER), input),
    ];
    for channel in &layout.measured {
        let name = channel.name();
        connections.push(link(Some(PHYSICS), &name, Some(CONTROLLER), &name));
    }
    connections.push(link(
        Some(CONTROLLER),
        "control_force",
        Some(PHYSICS),
        "control_force",
    ));
    for f in 1..=layout.storeys() {
        let acc = format!("acc{f}");
        connections.push(link(Some(PHYSICS), &acc, None, &acc));
    }
    connections.push(link(
        Some(CONTROLLER),
        "control_force",
        None,
        "control_force",
    ));
    system.name = "shear-twin-controlled".into();
    system.components = vec![physics, controller];
    system.connections = connections;
    system.noise_variance = None;
    system.default_experiment = experiment;
    Ok(system)
}

/// `twin control --ssp`: write the controlled system of design `q` of `report` (a
/// `ControlReport`'s JSON) to `path`.
pub fn write_controlled_ssp(
    twin: &Twin,
    report: &impl serde::Serialize,
    q: Option<f64>,
    experiment: Option<(f64, f64)>,
    path: &Path,
) -> Result<(), ControlError> {
    let text = serde_json::to_string(report)
        .map_err(|e| ControlError::Options(format!("the control report: {e}")))?;
    let spec = ControllerSpec::from_json(&text, "the control report")?;
    controlled_system(twin, &spec, q, experiment, None)?.write(path)?;
    Ok(())
}
