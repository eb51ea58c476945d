//! The run's plan: the communication points (fmpy's `simulate_fmu` schedule, the input file's
//! events for an FMU that handles variable steps), the step and the inputs, checked before any
//! FMU's code is loaded.

use std::path::Path;

use crate::cosim::import::{Causality, ScalarType, ScalarVariable};

use super::inputs::{isclose, InputTable};
use super::model::{parse_value, settable, ssv_value, Model, Value};
use super::{RunError, RunOptions};

/// fmpy's `auto_interval`: a round step giving 500 to 1000 points.
pub(super) fn auto_interval(span: f64) -> f64 {
    let mut h = 10f64.powf(span.log10().round() - 3.0);
    let n = span / h;
    if n >= 2500.0 {
        h *= 5.0;
    } else if n >= 2000.0 {
        h *= 4.0;
    } else if n >= 1000.0 {
        h *= 2.0;
    } else if n <= 200.0 {
        h /= 5.0;
    } else if n <= 250.0 {
        h /= 4.0;
    } else if n <= 500.0 {
        h /= 2.0;
    }
    h
}

/// The communication points, as fmpy's co-simulation loop takes them.
pub(super) fn schedule(
    start: f64,
    stop: f64,
    step: f64,
    events: &[f64],
    variable_step: bool,
) -> Vec<f64> {
    let mut times = vec![start];
    let mut time = start;
    let mut n: u64 = 0;
    let mut pending = 0;
    loop {
        if time > stop || isclose(time, stop) {
            break;
        }
        let regular = start + (n + 1) as f64 * step;
        let mut next = regular;
        // The next event after `time`: time only grows, so the search resumes where it
        // stopped (one pass over the events for the whole schedule, not one per point).
        while pending < events.len() && (events[pending] <= time || isclose(events[pending], time))
        {
            pending += 1;
        }
        let event = events.get(pending).copied().unwrap_or(f64::INFINITY);
        if variable_step && next > event && !isclose(next, event) {
            next = event;
        }
        if next > stop && !isclose(next, stop) {
            if variable_step {
                next = stop;
            } else {
                break;
            }
        }
        times.push(next);
        time = next;
        if isclose(time, regular) {
            n += 1;
        }
    }
    times
}

// ---------------------------------------------------------------------------------------------
// The recorder

/// Checked configuration: everything decided before an FMU is loaded.
pub(super) struct Plan {
    pub(super) start: f64,
    pub(super) stop: f64,
    pub(super) step: f64,
    /// Per component: start values.
    pub(super) starts: Vec<Vec<(ScalarVariable, Value)>>,
    pub(super) input: Option<InputTable>,
    /// Recorded variables: (component, variable, name in the run).
    pub(super) recorded: Vec<(usize, ScalarVariable, String)>,
    pub(super) times: Vec<f64>,
}

/// The run's plan: the experiment, the start values, the input file and the recorded
/// variables, each checked against the model before any FMU's code is loaded, and the
/// communication points.
pub(super) fn plan(model: &Model, options: &RunOptions) -> Result<Plan, RunError> {
    let Experiment { start, stop, step } = experiment(model, options)?;
    let starts = start_values(model, options)?;
    let input = input_table(model, options)?;
    let recorded = recorded(model, options);
    let events = input.as_ref().map(InputTable::events).unwrap_or_default();
    let times = schedule(start, stop, step, &events, model.can_vary_step());
    Ok(Plan {
        start,
        stop,
        step,
        starts,
        input,
        recorded,
        times,
    })
}

/// The run's experiment: start and stop times and the communication step.
struct Experiment {
    start: f64,
    stop: f64,
    step: f64,
}

/// The options' experiment, else the model's default one, else `0`, `start + 1` and fmpy's
/// round step; checked (finite, stop after start, a positive step, at most 10⁸ steps).
fn experiment(model: &Model, options: &RunOptions) -> Result<Experiment, RunError> {
    let start = options.start.or(model.default_start).unwrap_or(0.0);
    let stop = options.stop.or(model.default_stop).unwrap_or(start + 1.0);
    if !start.is_finite() || !stop.is_finite() {
        return Err(RunError::Config(format!(
            "start {start} and stop {stop} must be finite"
        )));
    }
    if stop <= start {
        return Err(RunError::Config(format!(
            "the stop time {stop} is not after the start time {start}"
        )));
    }
    let step = options
        .step
        .or(model.default_step)
        .unwrap_or_else(|| auto_interval(stop - start));
    if !(step > 0.0 && step.is_finite()) {
        return Err(RunError::Config(format!(
            "the step must be a positive number of seconds, was {step}"
        )));
    }
    if (stop - start) / step > 1e8 {
        return Err(RunError::Config(format!(
            "{} steps of {step} s from {start} to {stop} s: more than 10⁸",
            ((stop - start) / step).ceil()
        )));
    }
    Ok(Experiment { start, stop, step })
}

/// Per component, its start values: the system's parameter bindings, then the options'
/// `--set NAME=VALUE` (a later one replacing an earlier value of the same variable).
fn start_values(
    model: &Model,
    options: &RunOptions,
) -> Result<Vec<Vec<(ScalarVariable, Value)>>, RunError> {
    let mut starts = bound_values(model)?;
    for set in &options.sets {
        let (i, variable, value) = set_value_of(model, set)?;
        starts[i].retain(|(v, _)| v.name != variable.name);
        starts[i].push((variable, value));
    }
    Ok(starts)
}

/// Per component, the values its parameter set binds (an SSP system's), each checked against
/// the component's modelDescription.
fn bound_values(model: &Model) -> Result<Vec<Vec<(ScalarVariable, Value)>>, RunError> {
    let mut starts: Vec<Vec<(ScalarVariable, Value)>> = vec![Vec::new(); model.components.len()];
    for (i, c) in model.components.iter().enumerate() {
        for (name, value) in &c.bound {
            let variable = c.md.variable(name).ok_or_else(|| {
                RunError::Config(format!(
                    "{}: component '{}': its parameter set names '{name}', which {} does not have",
                    model.path.display(),
                    c.name,
                    c.md.model_name
                ))
            })?;
            let value = ssv_value(variable, value).map_err(|m| {
                RunError::Config(format!(
                    "{}: component '{}': parameter '{name}' {m}",
                    model.path.display(),
                    c.name
                ))
            })?;
            starts[i].push((variable.clone(), value));
        }
    }
    Ok(starts)
}

/// One `--set NAME=VALUE`: the component, the variable (one that takes a start value) and the
/// value parsed as its type.
fn set_value_of(model: &Model, set: &str) -> Result<(usize, ScalarVariable, Value), RunError> {
    let (name, text) = set
        .split_once('=')
        .ok_or_else(|| RunError::Config(format!("--set '{set}': expected NAME=VALUE")))?;
    let name = name.trim();
    let (i, variable) = model
        .find(name)
        .ok_or_else(|| model.unknown("--set", name, model.all_variable_names()))?;
    if !settable(variable) {
        return Err(RunError::Config(format!(
            "--set '{name}': a {:?} variable of variability '{}' cannot be given a start value",
            variable.causality, variable.variability
        )));
    }
    let value = parse_value(variable, text).map_err(|expected| {
        RunError::Config(format!(
            "--set '{name}': '{text}' is not {expected} ('{name}' is {:?})",
            variable.scalar_type
        ))
    })?;
    Ok((i, variable.clone(), value))
}

/// The options' input file, read against the model; no column may drive an input a connection
/// already feeds, nor a String input.
fn input_table(model: &Model, options: &RunOptions) -> Result<Option<InputTable>, RunError> {
    let input = options
        .input
        .as_deref()
        .map(|path| InputTable::read(path, model))
        .transpose()?;
    if let Some(table) = &input {
        for column in &table.columns {
            for (i, v) in &column.targets {
                let c = &model.components[*i];
                let fed = model.connections.iter().any(|k| {
                    k.start_element.is_some()
                        && k.end_element.as_deref() == Some(c.name.as_str())
                        && k.end_connector == v.name
                });
                if fed {
                    return Err(RunError::Config(format!(
                        "{}: column '{}' drives {}{}, which a connection already feeds",
                        options.input.as_deref().unwrap_or(Path::new("")).display(),
                        column.name,
                        c.prefix,
                        v.name
                    )));
                }
                if column.variable.scalar_type == ScalarType::String {
                    return Err(RunError::Config(format!(
                        "column '{}': String inputs from a file are not supported; set them \
                         with --set",
                        column.name
                    )));
                }
            }
        }
    }
    Ok(input)
}

/// The variables recorded: every component's outputs (and its locals with `output_all`), each
/// as (component, variable, its name in the run).
fn recorded(model: &Model, options: &RunOptions) -> Vec<(usize, ScalarVariable, String)> {
    let mut recorded = Vec::new();
    for (i, c) in model.components.iter().enumerate() {
        for v in &c.md.variables {
            let keep = v.causality == Causality::Output
                || (options.output_all && v.causality == Causality::Local);
            if keep {
                recorded.push((i, v.clone(), format!("{}{}", c.prefix, v.name)));
            }
        }
    }
    recorded
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_schedule_is_fmpys() {
        // Fixed step: stops at the last point not past the stop time.
        assert_eq!(schedule(0.0, 1.05, 0.5, &[], false), vec![0.0, 0.5, 1.0]);
        // Variable step: a last short step to the stop time, and input events in between.
        assert_eq!(
            schedule(0.0, 1.05, 0.5, &[0.7], true),
            vec![0.0, 0.5, 0.7, 1.0, 1.05]
        );
        // Points are start + k·h, never a running sum.
        let times = schedule(0.0, 1.0, 0.1, &[], false);
        assert_eq!(times.len(), 11);
        assert_eq!(times[3], 3.0 * 0.1);
        assert_eq!(times[10], 1.0);
    }

    #[test]
    fn auto_interval_gives_fmpys_round_steps() {
        assert_eq!(auto_interval(1.0), 0.002);
        assert_eq!(auto_interval(10.0), 0.02);
    }
}
