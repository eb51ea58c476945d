//! `twin calibrate` as a whole, for the CLI and the Python package: the options checked, the
//! calibration over one or more records (runs), the calibrated twin and its NMSE on the
//! validation records (the worst of which sets its default tolerance).

use serde::Serialize;

use super::{
    calibrate_records, calibrated_twin, physics_structure, CalibrateError, Calibration,
    CalibrationSetup, RecordInput,
};
use ::structure::Structure;

use crate::twin::data::Measurement;
use crate::twin::run::{accepted_for_validation, nmse_on, RunError, Tolerance};
use crate::twin::simulator::Simulator;
use crate::twin::{Twin, TwinError, PHYSICS};
use crate::workflows::options::{check_threads, check_transient_leaves, InvalidOption};

#[derive(Debug, thiserror::Error)]
pub enum CalibrateRunError {
    #[error(transparent)]
    Options(#[from] InvalidOption),
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
    #[error(transparent)]
    Run(#[from] RunError),
}

impl CalibrationSetup {
    /// The options against the record they calibrate on.
    pub fn validate(&self, data: &Measurement) -> Result<(), InvalidOption> {
        check_threads(self.threads)?;
        check_transient_leaves(self.transient, data)
    }
}

/// A record's NMSE (%) per measured channel.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelNmse {
    pub data: String,
    pub channels: Vec<String>,
    pub nmse: Vec<f64>,
    /// Whether it counts as the twin's validation level ([`accepted_for_validation`]: its
    /// worst channel under the cap).
    pub accepted: bool,
}

impl ChannelNmse {
    fn new(data: String, channels: Vec<String>, nmse: Vec<f64>) -> Self {
        let accepted = accepted_for_validation(&nmse);
        ChannelNmse {
            data,
            channels,
            nmse,
            accepted,
        }
    }
}

/// What `twin calibrate` computes.
pub struct Validated {
    pub twin: Twin,
    pub calibration: Calibration,
    /// Each validation record's NMSE % per channel under the calibrated twin.
    pub validated: Vec<ChannelNmse>,
    /// The calibrated twin's default tolerance of compare and diagnose (from its worst
    /// accepted validation NMSE).
    pub tolerance: Tolerance,
}

/// The building of `twin`'s physics component.
fn twin_structure(twin: &Twin) -> Result<Structure, CalibrateError> {
    let physics = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    physics_structure(&physics.fmu_path)
}

/// Whether a twin of `structure` and `data` are the paper's rig as the three-floor workflows
/// know it (its comparison, band and plot): the structure is the paper's and the record has a
/// force and `acc1..acc3`.
fn paper_rig(structure: &Structure, data: &Measurement) -> bool {
    ::structure::paper::is_paper_rig(structure)
        && ::structure::paper::is_paper_rig(&data.rig_channels())
}

/// The calibrated twin's NMSE % per channel of `data` after the transient: on the paper's rig
/// the whole twin's (as `twin compare`), on any other structure its physics component run on
/// the record's excitation, each measured channel against its output. `structure`: the
/// twin's physics component's.
pub fn channel_nmse(
    twin: &Twin,
    structure: &Structure,
    data: &Measurement,
    transient: f64,
) -> Result<ChannelNmse, CalibrateRunError> {
    let name = data.path.display().to_string();
    if paper_rig(structure, data) {
        return Ok(ChannelNmse::new(
            name,
            data.responses.iter().map(|s| s.channel.name()).collect(),
            nmse_on(twin, data, transient)?,
        ));
    }
    let physics = twin
        .component(PHYSICS)
        .ok_or_else(|| CalibrateError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let fmu = crate::cosim::import::Fmu::open(&physics.fmu_path)
        .map_err(|e| CalibrateError::from(TwinError::from(e)))?;
    let mut sim = Simulator::for_record(&fmu, physics.parameters.clone(), data, "validation")
        .map_err(CalibrateError::from)?;
    let outputs = data
        .responses
        .iter()
        .map(|s| fmu.value_reference(&s.channel.name()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| CalibrateError::from(TwinError::from(e)))?;
    let mut out = vec![Vec::new(); outputs.len()];
    sim.record(&[], &[], &outputs, &mut out)
        .map_err(CalibrateError::from)?;
    let first = crate::evaluation::stats::first_after_transient(&data.time, transient);
    Ok(ChannelNmse::new(
        name,
        data.responses.iter().map(|s| s.channel.name()).collect(),
        data.responses
            .iter()
            .zip(&out)
            .map(|(s, p)| crate::evaluation::compare::nmse(&s.values[first..], &p[first..]))
            .collect(),
    ))
}

/// Calibrate `twin` on the runs `data` (one MAP over all of them: the structure's parameters
/// shared, each run its own excitation, channels and noise variances), and report the
/// calibrated twin's NMSE on `validation`.
pub fn calibrate_validated(
    twin: &Twin,
    data: &[&Measurement],
    validation: &[&Measurement],
    setup: &CalibrationSetup,
) -> Result<Validated, CalibrateRunError> {
    for d in data {
        setup.validate(d)?;
    }
    // A single record takes the setup's sample mask, as `calibrate` does.
    let mask = if data.len() == 1 {
        setup.mask.as_deref()
    } else {
        None
    };
    let inputs: Vec<RecordInput> = data.iter().map(|d| RecordInput { data: d, mask }).collect();
    let calibration = calibrate_records(twin, &inputs, setup)?;
    let mut new_twin = calibrated_twin(twin, &calibration)?;
    let mut validated = Vec::new();
    if !validation.is_empty() {
        let structure = twin_structure(&new_twin)?;
        for v in validation {
            validated.push(channel_nmse(&new_twin, &structure, v, setup.transient)?);
        }
    }
    // The worst validation NMSE sets the default tolerance of compare and diagnose.
    new_twin.validation_nmse = crate::twin::run::validation_nmse(
        &validated
            .iter()
            .map(|v| (v.data.clone(), v.nmse.clone()))
            .collect::<Vec<_>>(),
    );
    let tolerance = Tolerance::resolve(&new_twin, None);
    Ok(Validated {
        twin: new_twin,
        calibration,
        validated,
        tolerance,
    })
}

/// Refuse `--plot` at once where it cannot be drawn: the plot is the paper rig's three floors.
pub fn check_plot(twin: &Twin, data: &[&Measurement]) -> Result<(), CalibrateRunError> {
    match data {
        [one] if paper_rig(&twin_structure(twin)?, one) => Ok(()),
        [_] => Err(CalibrateError::Setup(
            "--plot draws the paper rig's three floors (a force and acc1..acc3 on the paper's \
             structure); leave it out for this structure or record"
                .into(),
        )
        .into()),
        _ => Err(CalibrateError::Setup(
            "--plot draws one calibration record; leave it out when calibrating on several".into(),
        )
        .into()),
    }
}
