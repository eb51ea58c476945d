//! `twin diagnose`'s options and decision gates, the options checked, and its `--effects` read,
//! once for the CLI and the Python package.

use serde::Serialize;
use structure::building::MAX_STOREYS;

use super::{Addition, Candidate};
use crate::twin::data::Measurement;
use crate::workflows::options::{
    check_threads, check_tolerance, check_transient_leaves, InvalidOption,
};

/// Sub-steps while fitting candidates. The fits run the shear FMU with `integrator` = 2: contacts
/// alone step exactly (their cost does not depend on sub-steps), every other effect (cubic,
/// friction, discovered terms) with this many fixed RK4 sub-steps, and a fit's cost is
/// proportional to them. RK4's error falls 16× per doubling: 64 sub-steps give 1.1e-9 %
/// worst-floor NMSE for a 1e9 N/m³ cubic on the paper's prior damping
/// (`fmu-shear/tests/effects_accuracy.rs`), so about 2e-2 % at 8, below the differences the
/// decision gates look at (factors of 2 and 4 on NMSEs of 0.1 % and up). Measured on dataset3:
/// every candidate's NMSE after its fit within 2e-3 % of the fit at 16 sub-steps, the same
/// decision, 30 % less CPU. The fitted parameters are then scored with the twin's own integrator.
pub const FIT_SUBSTEPS: i32 = 8;

impl DiagnoseOptions {
    /// The options alone.
    pub fn validate(&self) -> Result<(), InvalidOption> {
        check_threads(self.threads)?;
        check_tolerance(self.tolerance)
    }

    /// The options against the record diagnosed: the transient must leave something of it.
    pub fn validate_for(&self, data: &Measurement) -> Result<(), InvalidOption> {
        self.validate()?;
        check_transient_leaves(self.transient, data)
    }
}

/// `--effects KIND@LOCATION[:SIDE] …` as candidates, read by the grammar alone: whether each
/// site is one of the twin's building is checked against its structure when the diagnosis or
/// add-physics starts ([`check_sites`]).
pub fn parse_candidates(effects: &[String]) -> Result<Vec<Candidate>, InvalidOption> {
    effects
        .iter()
        .map(|e| Candidate::parse(e, MAX_STOREYS).map_err(InvalidOption))
        .collect()
}

/// Every candidate at a site of a building of `storeys` storeys, else the first that is not,
/// named with the reason.
pub fn check_sites<'a>(
    candidates: impl IntoIterator<Item = &'a Candidate>,
    storeys: usize,
) -> Result<(), String> {
    for c in candidates {
        Candidate::parse(&c.label(), storeys)
            .map_err(|e| format!("{e} (the twin's building has {storeys} storeys)"))?;
    }
    Ok(())
}

/// `add-physics --effect KIND@LOCATION[:SIDE] …`: the library's effects to switch on.
pub fn parse_additions(effects: &[String]) -> Result<Vec<Addition>, InvalidOption> {
    Ok(parse_candidates(effects)?
        .into_iter()
        .map(Addition::Library)
        .collect())
}

/// The decision thresholds (see the module documentation).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Gates {
    /// `none` when every floor's NMSE ≤ this × the NMSE noise alone explains.
    pub none_factor: f64,
    /// An alternative must cut the worst-floor held-out NMSE by at least this factor.
    pub required_cut: f64,
    /// An effect must beat recalibration's worst-floor held-out NMSE by this factor.
    pub beat_recalibration: f64,
    /// Recalibration explains the error when every floor's held-out NMSE is within this factor
    /// of the noise level.
    pub recalibration_noise_factor: f64,
    /// Forward selection adds an effect that cuts the model's worst-floor held-out NMSE by at
    /// least this factor (the combination must still meet `required_cut` and
    /// `beat_recalibration` as a whole).
    pub step_cut: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
}

impl Default for Gates {
    fn default() -> Self {
        Gates {
            none_factor: 2.0,
            required_cut: 4.0,
            beat_recalibration: 2.0,
            recalibration_noise_factor: 3.0,
            step_cut: 1.5,
            max_effects: 3,
        }
    }
}

#[derive(Clone, Debug)]
pub struct DiagnoseOptions {
    pub transient: f64,
    /// Length (s) of the alternating fitted and held-out blocks.
    pub block: f64,
    pub gates: Gates,
    /// The candidates tried (None: the whole library at every site of the twin's building,
    /// [`Candidate::library`]).
    pub candidates: Option<Vec<Candidate>>,
    /// Optimiser starts per candidate, and for the recalibration.
    pub starts: usize,
    pub recalibration_starts: usize,
    /// Simulations one start of a candidate fit may use.
    pub simulations_per_start: usize,
    pub threads: usize,
    pub seed: u64,
    /// Fit every alternative even when the error is within the noise (`none`).
    pub always_fit: bool,
    /// Practical significance, NMSE % (None: the twin's default, see [`crate::twin::run::Tolerance::resolve`]).
    pub tolerance: Option<f64>,
    /// RK4 sub-steps of the shear FMU while candidates are fitted (its `substeps`); each fit is
    /// then scored at the twin's own sub-steps. `None`: the twin's own throughout.
    pub fit_substeps: Option<i32>,
    /// Told what the diagnosis is doing, stage by stage (a terminal's progress line).
    pub progress: Option<Progress>,
    /// The time (s of the record) the structure changed at, when known (a located change):
    /// the twin holds before it, and what came after is diagnosed from the state the twin
    /// reached there ([`change`]).
    pub changed_at: Option<f64>,
}

/// Where a diagnosis says what it is doing.
#[derive(Clone)]
pub struct Progress(pub std::sync::Arc<dyn Fn(&str) + Send + Sync>);

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Progress")
    }
}

impl DiagnoseOptions {
    pub(super) fn tell(&self, what: &str) {
        if let Some(p) = &self.progress {
            (p.0)(what);
        }
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            transient: crate::evaluation::compare::DEFAULT_TRANSIENT,
            block: 1.0,
            gates: Gates::default(),
            candidates: None,
            starts: 3,
            recalibration_starts: 8,
            simulations_per_start: 250,
            threads: crate::parallel::cores(),
            seed: 1,
            always_fit: false,
            tolerance: None,
            fit_substeps: Some(FIT_SUBSTEPS),
            progress: None,
            changed_at: None,
        }
    }
}
