//! One alternative's fit: the physics (or a candidate's parameters) fitted through FMI on the
//! fitted blocks, at the fits' RK4 sub-steps, and scored on the whole record and on the held-out
//! blocks. Every round of a diagnosis fits through [`fit`].

use std::collections::BTreeMap;

use super::channels::Channels;
use super::physics::{run_physics, PhysicsReals, PhysicsRun};
use super::{Candidate, DiagnoseError, DiagnoseOptions, Result};
use crate::evaluation::compare::FailingWindow;
use crate::twin::data::Measurement;
use crate::twin::{ParameterValue, Twin, PHYSICS};
use crate::workflows::calibrate::{calibrate, Calibration, CalibrationSetup, Prior};

/// The largest phase (radians) of the structure's fastest mode over one RK4 sub-step of a fit.
/// The paper's rig at its prior means (fastest mode 7.97 Hz) sampled at 51.2 Hz takes 0.98 rad
/// a sample, so [`FIT_SUBSTEPS`](super::FIT_SUBSTEPS) there (0.12 rad each, whose error is measured above). A record
/// sampled far above its structure's modes needs fewer for the same error per period: the
/// 4-storey frame at 322.58 Hz (fastest mode 8.4 Hz) takes 2. Below the rig's 0.12 so
/// that its records and every slower-sampled one keep the full [`FIT_SUBSTEPS`](super::FIT_SUBSTEPS).
pub const FIT_STEP_PHASE: f64 = 0.1;

/// The RK4 sub-steps a sample of the fits take: as many as keep the structure's fastest mode
/// (`fastest_hz`) within [`FIT_STEP_PHASE`] a sub-step at the sampling step `dt`, at most
/// `most`, at least one.
pub fn fit_substeps(most: i32, fastest_hz: f64, dt: f64) -> i32 {
    let phase = 2.0 * std::f64::consts::PI * fastest_hz * dt;
    if !(phase.is_finite() && phase > 0.0) {
        return most;
    }
    ((phase / FIT_STEP_PHASE).ceil() as i32).clamp(1, most.max(1))
}

/// What one alternative's fit gives.
#[derive(Clone)]
pub(super) struct Fitted {
    pub(super) calibration: Calibration,
    pub(super) evidence: f64,
    /// Per channel.
    pub(super) nmse_after: Vec<f64>,
    pub(super) nmse_held_out: Vec<f64>,
    pub(super) run: PhysicsRun,
}

/// The physics twin with a candidate's switches on.
pub(super) fn with_switches(physics: &Twin, candidate: Option<&Candidate>) -> Result<Twin> {
    let mut out = physics.duplicate();
    if let Some(c) = candidate {
        let component = out.component_mut(PHYSICS).ok_or_else(|| {
            DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component"))
        })?;
        component.parameters.extend(c.switches());
    }
    Ok(out)
}

/// The twin a candidate is fitted with on a record sampled every `dt`: the shear FMU at
/// `most` RK4 sub-steps, fewer when every effect switched on is a contact or a cubic spring
/// (the structure's fastest mode sets them, [`fit_substeps`]; friction and discovered terms
/// keep `most`, as their force laws have time scales of their own — a friction fitted at two
/// sub-steps a sample on the 4-storey contact record went to a sharp law the finer scoring run
/// rejected), and, where the FMU has the choice (`integrator` = 2), contacts alone still
/// stepped exactly (they are cheaper so than by sub-steps) while every other effect takes the
/// fixed sub-steps instead of the error-controlled path, whose tolerance the scoring run keeps.
pub(super) fn fitting_twin(twin: &Twin, most: i32, dt: f64) -> Result<Twin> {
    let mut coarse = twin.duplicate();
    let reals = PhysicsReals::of(&coarse)?;
    let component = coarse
        .component_mut(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let polynomial = component
        .parameters
        .iter()
        .filter(|(name, value)| {
            name.ends_with("_enabled") && **value == ParameterValue::Boolean(true)
        })
        .all(|(name, _)| name.starts_with("cubic") || name.starts_with("contact"));
    let substeps = if polynomial {
        fit_substeps(most, reals.fastest_mode_hz()?, dt)
    } else {
        most
    };
    let chooses = reals.model_description.variable("integrator").is_some();
    component
        .parameters
        .insert("substeps".into(), ParameterValue::Integer(substeps));
    if chooses {
        component
            .parameters
            .insert("integrator".into(), ParameterValue::Integer(2));
    }
    Ok(coarse)
}

/// The samples a fit uses: the fitted ones (`mask`), the held-out ones it is scored on, the
/// first after the transient, and whether its starts climb the ladder of the record's heads
/// (`calibrate::ladder`; see [`climbs`]).
#[derive(Clone, Copy)]
pub(super) struct Split<'a> {
    pub mask: &'a [bool],
    pub held_out: &'a [usize],
    pub first: usize,
    pub climb: bool,
}

/// Whether a diagnosis's fits on a record of `n` samples climb the ladder of its heads: when
/// the record is long enough to have one (`ladder::rungs`) and the twin's error shows on its
/// first rung (a failing window starts there), so that an effect or a change the fits are to
/// find is in the samples the starts are screened on. An effect that shows only late in the
/// record is fitted on every sample from every start.
pub(super) fn climbs(n: usize, time: &[f64], failing: &[FailingWindow]) -> bool {
    let rungs = crate::workflows::calibrate::ladder::rungs(n);
    let Some(&head) = rungs.first() else {
        return false;
    };
    let head_end = time
        .get(head.saturating_sub(1))
        .copied()
        .unwrap_or(f64::NEG_INFINITY);
    failing.iter().any(|w| w.start < head_end)
}

/// Fit `parameters` (with `priors`) of `twin`'s physics on the `split`'s fitted samples and
/// score the fit on the whole record and on the held-out samples.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit(
    twin: &Twin,
    data: &Measurement,
    parameters: Vec<String>,
    priors: BTreeMap<String, Prior>,
    split: Split,
    starts: usize,
    threads: usize,
    simulations_per_start: usize,
    options: &DiagnoseOptions,
    baseline_evidence: f64,
    initial: &BTreeMap<String, f64>,
    starts_at: Vec<BTreeMap<String, f64>>,
) -> Result<Fitted> {
    let setup = CalibrationSetup {
        parameters: parameters.clone(),
        priors,
        transient: options.transient,
        starts,
        seed: options.seed,
        threads,
        mask: Some(split.mask.to_vec()),
        simulations_per_start,
        initial: initial.clone(),
        starts_at,
        climb: split.climb,
        ..CalibrationSetup::default()
    };
    let calibration = match options.fit_substeps {
        Some(most) => calibrate(&fitting_twin(twin, most, data.dt)?, data, &setup)?,
        None => calibrate(twin, data, &setup)?,
    };
    let values: Vec<f64> = calibration.parameters.iter().map(|p| p.value).collect();
    let run = run_physics(twin, data, &BTreeMap::new(), &parameters, &values)?;
    let after: Vec<usize> = (split.first..data.len()).collect();
    let channels = Channels::of(data, run.acc.len())?;
    let predicted = channels.predicted(&run);
    Ok(Fitted {
        evidence: calibration.log_evidence - baseline_evidence,
        nmse_after: channels.nmse_on(&predicted, &after),
        nmse_held_out: channels.nmse_on(&predicted, split.held_out),
        run,
        calibration,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workflows::diagnose::FIT_SUBSTEPS;

    /// The fits' sub-steps follow the structure's fastest mode: the rig at 51.2 Hz keeps all
    /// eight, the 4-storey frame sampled at 322.58 Hz takes two, a building whose fastest mode
    /// is unknown keeps all, and none takes fewer than one or more than asked.
    #[test]
    fn the_fits_sub_steps_follow_the_fastest_mode() {
        let rig = ::structure::building::Structure::default().natural_frequencies();
        let fastest = *rig.last().unwrap();
        assert!((fastest - 7.97).abs() < 0.01, "{fastest}");
        assert_eq!(
            fit_substeps(FIT_SUBSTEPS, fastest, 1.0 / 51.2),
            FIT_SUBSTEPS
        );
        assert_eq!(fit_substeps(FIT_SUBSTEPS, 8.4, 1.0 / 322.58), 2);
        assert_eq!(fit_substeps(FIT_SUBSTEPS, f64::NAN, 0.01), FIT_SUBSTEPS);
        assert_eq!(fit_substeps(FIT_SUBSTEPS, 0.01, 0.001), 1);
        assert_eq!(fit_substeps(4, 100.0, 0.01), 4);
    }

    /// The fits climb only on records long enough for a ladder, and only when the error shows
    /// on its first rung: a window failing from the start of the record, not one that opens
    /// after the head the starts are screened on.
    #[test]
    fn the_fits_climb_only_where_the_error_shows_on_the_first_rung() {
        let dt = 0.01;
        let time = |n: usize| (0..n).map(|k| k as f64 * dt).collect::<Vec<f64>>();
        let window = |start: f64, end: f64| FailingWindow {
            start,
            end,
            channels: vec!["acc1".into()],
            floors: vec![1],
            nmse: vec![10.0],
        };
        let head_end = (crate::workflows::calibrate::ladder::STRETCH - 1) as f64 * dt;
        let long = 3 * crate::workflows::calibrate::ladder::STRETCH;
        assert!(climbs(long, &time(long), &[window(2.0, 5.0)]));
        assert!(climbs(
            long,
            &time(long),
            &[window(head_end - 0.5, head_end + 9.0)]
        ));
        assert!(!climbs(
            long,
            &time(long),
            &[window(head_end + 0.5, head_end + 9.0)]
        ));
        assert!(!climbs(long, &time(long), &[]));
        let short = 2 * crate::workflows::calibrate::ladder::STRETCH;
        assert!(!climbs(short, &time(short), &[window(2.0, 5.0)]));
    }
}
