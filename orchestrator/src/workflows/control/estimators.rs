//! The estimators compared: each choice run on the record, its cost beside the others'.

use super::closed_loop::{Gains, StateSource};
use super::options::{ControlOptions, EstimatorChoice};
use super::report::{DesignRun, EstimatorCost};
use super::runs::{check_estimator, estimator_of, ControlBasis, Runner};
use super::ControlError;
use crate::twin::data::Measurement;

/// The states `--estimator-costs` compares: the exact one, and each estimator that can run on
/// the record's channels (the integrating one needs every floor's acceleration).
pub(super) fn estimator_choices(
    basis: &ControlBasis,
    options: &ControlOptions,
    noise_sd: Option<&[f64]>,
    data: &Measurement,
) -> Vec<(&'static str, StateSource)> {
    let (structure, plant, measured) = (&basis.structure, &basis.plant, &basis.measured);
    let mut choices = vec![("exact", StateSource::Exact)];
    // The integrating estimator needs every floor's acceleration.
    if check_estimator(EstimatorChoice::Integrate, structure, plant, measured).is_ok() {
        choices.push((
            "integrate",
            StateSource::Estimated(estimator_of(
                EstimatorChoice::Integrate,
                options,
                noise_sd,
                data,
                measured,
            )),
        ));
    }
    if check_estimator(EstimatorChoice::Kalman, structure, plant, measured).is_ok() {
        choices.push((
            "kalman",
            StateSource::Estimated(estimator_of(
                EstimatorChoice::Kalman,
                options,
                noise_sd,
                data,
                measured,
            )),
        ));
    }
    choices
}

/// The first design's cost under each state in `choices`: the chosen estimator's is the
/// design's own run, the others are run; an unstable loop fails, naming the state.
pub(super) fn run_estimator_costs(
    runner: &mut Runner,
    first: &DesignRun,
    choices: Vec<(&'static str, StateSource)>,
) -> Result<Vec<EstimatorCost>, ControlError> {
    let mut estimator_costs = Vec::new();
    for (name, state) in choices {
        // The chosen estimator's run is the design's own.
        let same = matches!(&state, StateSource::Estimated(e) if *e == runner.estimator);
        let (att, mean, rms_u, contacts) = if same {
            (
                first.attenuation_db.clone(),
                first.mean_attenuation_db,
                first.control_rms,
                first.contacts,
            )
        } else {
            match runner.run_law(Gains::Fixed(first.design.gain.clone()), state)? {
                Ok(r) => {
                    let (att, mean) = runner.attenuation_of(&r);
                    (att, mean, r.control_rms, r.contacts.len())
                }
                Err(message) => {
                    return Err(ControlError::Unstable(format!(
                        "with the {name} state: {message}"
                    )))
                }
            }
        };
        estimator_costs.push(EstimatorCost {
            estimator: name.into(),
            mean_attenuation_db: mean,
            attenuation_db: att,
            control_rms: rms_u,
            contacts,
        });
    }
    Ok(estimator_costs)
}
