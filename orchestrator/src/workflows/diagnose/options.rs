//! `twin diagnose`'s options checked, and its `--effects` read, once for the CLI and the
//! Python package.

use super::{Candidate, DiagnoseOptions};
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

/// `--effects KIND@LOCATION[:SIDE] …` as candidates.
pub fn parse_candidates(effects: &[String]) -> Result<Vec<Candidate>, InvalidOption> {
    effects
        .iter()
        .map(|e| Candidate::parse(e).map_err(InvalidOption))
        .collect()
}
