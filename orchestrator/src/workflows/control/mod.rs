//! Active control on the twin (the reference paper's section 6, automated): LQR designs on the
//! twin's calibrated linear structure, the structure (the twin's physics, with whatever effects it
//! has) driven by a record's force passive and under each design, the frequency responses and the
//! attenuation at each resonance, the control effort and the contact initiations; then the twin
//! informs the control: the smallest state weight that keeps the contacts at a target
//! (`retune`), and a gain schedule that switches to the high gain when the estimated drift
//! approaches the gap.
//!
//! [`run_control`] reads as its stages, one submodule each: `runs` (the record and options
//! checked, the twin's linear basis, the designs, the loop's plan, the runs), `response` (the
//! FRFs and attenuations), `retune`, `schedule`, `estimators` (their costs compared), `report`
//! (the outcome); `predict` runs a controller given as a spec.

pub mod closed_loop;
pub mod design;
pub mod options;
pub mod ssp;

mod estimators;
mod outcome;
mod predict;
mod report;
mod response;
mod retune;
mod runs;
mod schedule;

use crate::cosim::master::MasterError;
use crate::twin::data::Measurement;
use crate::twin::{Twin, TwinError};
pub use design::{
    design, physics_resource, plant_measuring, plant_of, structure_of, with_actuator_at, Design,
    StateUnit,
};
pub use options::{
    sensor_noise, twin_for_control, ControlOptions, EstimatorChoice, Retune, ScheduleOptions,
    VarianceTrigger, RESONANCE_BAND, RETUNE_GRID,
};
pub use predict::{predict_controlled, ControllerSpec, SpecDesign};
pub use report::{
    Attenuation, ControlOutcome, ControlReport, DesignRun, EstimatorCost, GapReport, Passive,
    RetuneReport, RetuneRow, ScheduleReport, Switch,
};
pub use response::floor_frfs;
pub use runs::{check_estimator, check_record, measured_channels, substeps_for};

// What the stages share: each submodule reads the others' through `use super::*`.
use estimators::*;
use outcome::control_outcome;
use response::*;
use retune::*;
use runs::*;
use schedule::*;

/// Errors of `twin control`.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    #[error("{0}")]
    Options(String),
    #[error("{0}")]
    Twin(String),
    #[error("the LQR design for q = {q} failed: {message}")]
    Design { q: f64, message: String },
    #[error("{0}")]
    Unstable(String),
    #[error(transparent)]
    Lqr(#[from] numerics::lqr::LqrError),
    #[error(transparent)]
    Master(#[from] MasterError),
    #[error(transparent)]
    TwinFile(#[from] TwinError),
}

/// The whole of `twin control`.
pub fn run_control(
    twin: &Twin,
    data: &Measurement,
    options: &ControlOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ControlOutcome, ControlError> {
    check_options(options)?;
    let basis = control_basis(twin, data, options)?;
    let set = design_set(&basis.plant, data, options)?;
    let plan = loop_plan(&basis, data, options)?;
    let mut runner = runner(&basis, data, options, &set, &plan, progress);
    let passive = runner.run(None)?;
    runner.passive_peaks =
        resonance_peaks(&data.excitation.values, &passive, data.dt, &plan.resonances);
    let mut designs = run_designs(&mut runner, set.designs)?;
    let retune = match &options.retune {
        None => None,
        Some(rt) => Some(run_retune(
            &mut runner,
            rt,
            set.retune,
            set.qs[0],
            &mut designs,
        )?),
    };
    let schedule = match &options.schedule {
        None => None,
        Some(so) => Some(run_schedule(
            &mut runner,
            so,
            &basis,
            &plan.gaps,
            &designs.runs,
            retune.as_ref(),
            &set.qs,
        )?),
    };
    let estimator_costs = if options.estimator_costs {
        let choices = estimator_choices(&basis, options, plan.noise_sd.as_deref(), data);
        run_estimator_costs(&mut runner, &designs.runs[0], choices)?
    } else {
        Vec::new()
    };
    let runs = Runs {
        passive,
        designs,
        retune,
        schedule,
        estimator_costs,
    };
    Ok(control_outcome(
        &basis,
        data,
        options,
        set.substeps,
        plan,
        runs,
    ))
}
