//! `twin diagnose`'s options checked, and its `--effects` read, once for the CLI and the
//! Python package.

use structure::building::PAPER_STOREYS;

use super::{Addition, Candidate, DiagnoseOptions};
use crate::twin::data::Measurement;
use crate::workflows::options::{
    check_threads, check_tolerance, check_transient_leaves, InvalidOption,
};

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

/// `--effects KIND@LOCATION[:SIDE] …` as candidates (of the paper's three-storey rig, the
/// building the diagnosis serves).
pub fn parse_candidates(effects: &[String]) -> Result<Vec<Candidate>, InvalidOption> {
    effects
        .iter()
        .map(|e| Candidate::parse(e, PAPER_STOREYS).map_err(InvalidOption))
        .collect()
}

/// `add-physics --effect KIND@LOCATION[:SIDE] …`: the library's effects to switch on.
pub fn parse_additions(effects: &[String]) -> Result<Vec<Addition>, InvalidOption> {
    Ok(parse_candidates(effects)?
        .into_iter()
        .map(Addition::Library)
        .collect())
}
