//! A record in which the structure changed at a known time (a change the watch located): the
//! twin holds before it, so what came after is diagnosed on its own — every alternative fitted
//! from the state the twin reached at the change, not from rest at the record's start.
//!
//! A single structure fitted over samples from both sides explains neither (on a stream whose
//! storey 2 lost 15 % of its stiffness, a recalibration over the ten seconds before the change
//! and the ten after left 11.8 % of NMSE, and the verdict was `update_data_model`). Started
//! from rest at the change, a fit would instead spend its first seconds on the response it
//! does not know (with 2–3 % damping the first mode keeps a tenth of it for about ten seconds).
//! The hypothesis "the old structure until t₀, the new one after" is what is fitted: the twin as
//! it is runs on the samples before the change, its displacements and velocities there become
//! the shear FMU's start values (`disp{i}_start`, `vel{i}_start`), and the diagnosis runs on the
//! samples from the change on, with no transient left out (there is none: the run continues).

use std::collections::BTreeMap;

use crate::cosim::import::Fmu;
use crate::twin::data::Measurement;
use crate::twin::{ParameterValue, Twin, PHYSICS};

use super::{run_physics, DiagnoseError, DiagnoseOptions, Result};

/// What is diagnosed after a change.
pub struct AfterTheChange {
    /// The change's time (s of the record).
    pub at: f64,
    /// The twin, its physics starting from the state it reached at the change.
    pub twin: Twin,
    /// The samples from the change on.
    pub data: Measurement,
    /// The options, with no transient and no change left to cut at.
    pub options: DiagnoseOptions,
}

/// The diagnosis after `options.changed_at`: None when there is no change to cut at, when it
/// falls at the record's first sample, or when the twin's physics cannot start from a given
/// state (a shear FMU from before the start values: the record is diagnosed whole, with its
/// transient). An error when fewer than two samples follow the change.
pub fn after_the_change(
    twin: &Twin,
    data: &Measurement,
    options: &DiagnoseOptions,
) -> Result<Option<AfterTheChange>> {
    let Some(at) = options.changed_at else {
        return Ok(None);
    };
    let Some(k0) = data.time.iter().position(|&t| t >= at - 1e-9 * data.dt) else {
        return Err(DiagnoseError::Setup(format!(
            "the change at {at:.3} s is after the record's last sample ({:.3} s)",
            data.time.last().copied().unwrap_or(f64::NAN)
        )));
    };
    if data.len() - k0 < 2 {
        return Err(DiagnoseError::Setup(format!(
            "the change at {at:.3} s leaves {} sample(s) of the record to diagnose",
            data.len() - k0
        )));
    }
    if k0 == 0 {
        return Ok(None);
    }
    let Some(state) = reached_state(twin, &data.head(k0 + 1))? else {
        return Ok(None);
    };
    Ok(Some(AfterTheChange {
        at: data.time[k0],
        twin: starting_from(twin, &state)?,
        data: data.samples(k0..data.len()),
        options: DiagnoseOptions {
            transient: 0.0,
            changed_at: None,
            ..options.clone()
        },
    }))
}

/// The times of the samples from a change on, and per response channel its residuals there.
pub type Residuals = (Vec<f64>, Vec<Vec<f64>>);

/// The residuals of `candidate` (physics parameters set on `twin`) after the change at `at`,
/// run from the state `twin` as it is reached there on the samples before — the hypothesis a
/// diagnosis after the change fits: per response channel of `data`, the measured minus the
/// predicted from the change on, with those samples' times. None as for [`after_the_change`].
pub fn residuals_after(
    twin: &Twin,
    candidate: &[(String, ParameterValue)],
    data: &Measurement,
    at: f64,
) -> Result<Option<Residuals>> {
    let options = DiagnoseOptions {
        changed_at: Some(at),
        ..DiagnoseOptions::default()
    };
    let Some(after) = after_the_change(twin, data, &options)? else {
        return Ok(None);
    };
    let mut twin = after.twin;
    if let Some(physics) = twin.component_mut(PHYSICS) {
        physics.parameters.extend(candidate.iter().cloned());
    }
    let run = run_physics(&twin, &after.data, &BTreeMap::new(), &[], &[])?;
    let mut residuals = Vec::with_capacity(after.data.responses.len());
    for signal in &after.data.responses {
        let ::structure::channel::Channel::Response { quantity, floor } = signal.channel else {
            return Ok(None);
        };
        let predicted = run.at(floor - 1, quantity);
        residuals.push(
            signal
                .values
                .iter()
                .zip(predicted)
                .map(|(y, p)| y - p)
                .collect(),
        );
    }
    Ok(Some((after.data.time, residuals)))
}

/// How `candidate` (physics parameters set on `twin`: an effect switched on) fits the samples
/// of `data` before a change at `at` — the hypothesis that it was there all along against the
/// twin as it is: per response channel, the twin's and the candidate's residual sums of
/// squares there, both run from `twin`'s start (rest, or its start values), the samples of the
/// first `skip` s left out. None when fewer than two samples precede the change or a channel
/// is no floor's response.
pub fn before_the_change(
    twin: &Twin,
    candidate: &[(String, ParameterValue)],
    data: &Measurement,
    at: f64,
    skip: f64,
) -> Result<Option<(Vec<f64>, Vec<f64>)>> {
    let k0 = data
        .time
        .iter()
        .position(|&t| t >= at - 1e-9 * data.dt)
        .unwrap_or(data.len());
    if k0 < 2 {
        return Ok(None);
    }
    let before = data.head(k0);
    let mut with = twin.duplicate();
    if let Some(physics) = with.component_mut(PHYSICS) {
        physics.parameters.extend(candidate.iter().cloned());
    }
    let runs = [
        run_physics(twin, &before, &BTreeMap::new(), &[], &[])?,
        run_physics(&with, &before, &BTreeMap::new(), &[], &[])?,
    ];
    let from = before.time[0] + skip.min(0.5 * (before.time[k0 - 1] - before.time[0]));
    let mut rss = [Vec::new(), Vec::new()];
    for signal in &before.responses {
        let ::structure::channel::Channel::Response { quantity, floor } = signal.channel else {
            return Ok(None);
        };
        for (run, sums) in runs.iter().zip(&mut rss) {
            let predicted = run.at(floor - 1, quantity);
            sums.push(
                signal
                    .values
                    .iter()
                    .zip(predicted)
                    .zip(&before.time)
                    .filter(|(_, &t)| t >= from)
                    .map(|((y, p), _)| (y - p) * (y - p))
                    .sum(),
            );
        }
    }
    let [old, new] = rss;
    Ok(Some((old, new)))
}

/// The state `twin`'s physics reaches at `data`'s last sample, run from rest at its first, as
/// the start values another run takes to go on from there (`disp{i}_start`, `vel{i}_start`);
/// None when its shear FMU has no start values.
pub fn reached_state(twin: &Twin, data: &Measurement) -> Result<Option<Vec<(String, f64)>>> {
    let Some(starts) = start_values(twin)? else {
        return Ok(None);
    };
    let run = run_physics(twin, data, &BTreeMap::new(), &[], &[])?;
    let last = data.len().saturating_sub(1);
    let reached = run.displacement.iter().chain(&run.velocity);
    Ok(Some(
        starts
            .into_iter()
            .zip(reached)
            .map(|(name, series)| (name, series.get(last).copied().unwrap_or(0.0)))
            .collect(),
    ))
}

/// `twin` with its physics starting from `state` (start values, as [`reached_state`] gives).
pub fn starting_from(twin: &Twin, state: &[(String, f64)]) -> Result<Twin> {
    let mut twin = twin.duplicate();
    let physics = twin
        .component_mut(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    for (name, value) in state {
        physics
            .parameters
            .insert(name.clone(), ParameterValue::Real(*value));
    }
    Ok(twin)
}

/// Twins each live from a time on: the structure the stream had, as the answers to its
/// changes found it — `(since, twin)` in time order, the first live from the record's start.
pub type History<'a> = [(f64, &'a Twin)];

/// The state the chain of twins `history` reaches at `data`'s last sample: the first runs from
/// rest at `data`'s first sample, each next from the state the one before reached at the first
/// sample at or after its `since` (the structure's history rather than today's twin run over
/// samples of a structure it no longer is). None when a shear FMU has no start values.
pub fn chained_state(
    history: &History<'_>,
    data: &Measurement,
) -> Result<Option<Vec<(String, f64)>>> {
    let n = data.len();
    let first = |since: f64| data.time.iter().position(|&t| t >= since - 1e-9 * data.dt);
    // The twins live over some of the samples, each from its first sample there.
    let mut segments: Vec<(usize, &Twin)> = Vec::new();
    for &(since, twin) in history {
        let k = first(since).unwrap_or(n);
        match segments.last_mut() {
            // Live from the same sample as the one before, or from before the record: it alone.
            Some(last) if k <= last.0 => last.1 = twin,
            None => segments.push((0, twin)),
            Some(_) if k + 1 < n => segments.push((k, twin)),
            // Live only from the record's last sample on: the state there is the last one's.
            Some(_) => {}
        }
    }
    let mut state: Option<Vec<(String, f64)>> = None;
    for (i, &(from, twin)) in segments.iter().enumerate() {
        let to = segments.get(i + 1).map_or(n, |s| s.0 + 1);
        let twin = match &state {
            Some(s) => starting_from(twin, s)?,
            None => twin.duplicate(),
        };
        match reached_state(&twin, &data.samples(from..to))? {
            Some(s) => state = Some(s),
            None => return Ok(None),
        }
    }
    Ok(state)
}

/// The physics FMU's start values, `disp1_start..dispN_start` then `vel1_start..velN_start`;
/// None when it has none.
fn start_values(twin: &Twin) -> Result<Option<Vec<String>>> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let md = Fmu::open(&component.fmu_path)?.model_description;
    let storeys = super::storeys_of(twin)?;
    let names: Vec<String> = ["disp", "vel"]
        .iter()
        .flat_map(|q| (1..=storeys).map(move |i| format!("{q}{i}_start")))
        .collect();
    Ok(names
        .iter()
        .all(|n| md.variable(n).is_some())
        .then_some(names))
}
