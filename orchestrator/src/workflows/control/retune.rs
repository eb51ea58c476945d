//! `retune`: the smallest state weight of the grid that keeps the contacts at the target.

use super::closed_loop::Response;
use super::design::Design;
use super::options::{Retune, RETUNE_GRID};
use super::report::{DesignRun, RetuneReport, RetuneRow};
use super::runs::{DesignRuns, Runner};
use super::ControlError;

/// `--retune`: run the grid's designs (multiples of `q0`, the smallest q) in order and choose
/// the first that meets the target; the chosen run joins `designs` unless its q is there.
pub(super) fn run_retune(
    runner: &mut Runner,
    rt: &Retune,
    grid_designs: Vec<Design>,
    q0: f64,
    designs: &mut DesignRuns,
) -> Result<RetuneReport, ControlError> {
    let mut grid = Vec::new();
    let mut chosen: Option<(DesignRun, Option<Response>)> = None;
    for d in grid_designs {
        let (run, response) = runner.design_run(d, "retuned")?;
        grid.push(RetuneRow {
            q: run.design.q,
            contacts: run.unstable.is_none().then_some(run.contacts),
            control_rms: run.unstable.is_none().then_some(run.control_rms),
            control_peak: run.unstable.is_none().then_some(run.control_peak),
            mean_attenuation_db: run.unstable.is_none().then_some(run.mean_attenuation_db),
            unstable: run.unstable.clone(),
        });
        let ok = run.unstable.is_none()
            && run.contacts <= rt.target
            && rt.max_force.is_none_or(|m| run.control_peak <= m);
        if ok && chosen.is_none() {
            chosen = Some((run, response));
        }
    }
    let verdict = retune_verdict(rt, chosen.as_ref().map(|(run, _)| run), q0);
    let chosen_q = chosen.as_ref().map(|(r, _)| r.design.q);
    if let Some((run, response)) = chosen {
        if !designs.runs.iter().any(|d| d.design.q == run.design.q) {
            designs.push(run, response);
        }
    }
    Ok(RetuneReport {
        target_contacts: rt.target,
        max_force: rt.max_force,
        grid,
        chosen_q,
        verdict,
    })
}

/// The retune's verdict in words: the chosen q and what it keeps, or that no q on the grid
/// (multiples of `q0`) does.
pub(super) fn retune_verdict(rt: &Retune, chosen: Option<&DesignRun>, q0: f64) -> String {
    match chosen {
        Some(run) => format!(
            "q = {} is the smallest on the grid with at most {} contact initiations ({}){}",
            run.design.q,
            rt.target,
            run.contacts,
            rt.max_force
                .map(|m| format!(
                    " and a peak control force within {m} N ({:.3} N)",
                    run.control_peak
                ))
                .unwrap_or_default()
        ),
        None => format!(
            "no q on the grid ({} … {}) keeps the contact initiations at or below {}{}",
            q0 * RETUNE_GRID[0],
            q0 * RETUNE_GRID[RETUNE_GRID.len() - 1],
            rt.target,
            rt.max_force
                .map(|m| format!(" within {m} N"))
                .unwrap_or_default()
        ),
    }
}
