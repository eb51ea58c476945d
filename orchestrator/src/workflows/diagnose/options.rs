//! `twin diagnose`'s options checked, and its `--effects` read, once for the CLI and the
//! Python package.

use structure::building::MAX_STOREYS;

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
