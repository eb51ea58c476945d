//! `twin init`: the twin of a shear building — the default twin (the paper's rig), or the
//! built-in shear FMU written for the structure asked for — with the calibration's priors kept
//! in it. The options are checked whole before anything is written; the CLI and the Python
//! package only map their arguments onto [`InitRequest`].

use crate::twin::structure::InitOptions;
use crate::twin::{Twin, TwinError};
use crate::workflows::calibrate::{priors_from_json, structure_prior};

/// What `twin init` is asked for: the structure (none of its options: the paper's rig) and a
/// priors file's text with where it came from (a path, or "priors=" in Python).
#[derive(Debug, Clone, Default)]
pub struct InitRequest {
    pub structure: InitOptions,
    pub priors: Option<(String, String)>,
}

impl InitRequest {
    /// The twin, not yet written anywhere.
    pub fn twin(&self) -> Result<Twin, TwinError> {
        let s = &self.structure;
        let structure = if s.storeys.is_none() && s.excitation.is_none() && s.nominal.is_none() {
            None
        } else {
            Some(s.structure()?)
        };
        // The priors checked against the structure before anything is built.
        let priors = match &self.priors {
            Some((origin, text)) => {
                let spec = priors_from_json(text, origin).map_err(TwinError::Message)?;
                let s = structure.clone().unwrap_or_default();
                spec.check(&s, true).map_err(TwinError::Message)?;
                for name in s.parameter_names() {
                    if let Some(fallback) = structure_prior(&s, &name) {
                        if let Some(prior) = spec.prior_for(&name, fallback) {
                            prior.map_err(TwinError::Message)?;
                        }
                    }
                }
                Some(text.clone())
            }
            None => None,
        };
        let mut twin = match &structure {
            None => Twin::default_twin()?,
            Some(s) => Twin::for_structure(s)?,
        };
        twin.priors = priors;
        Ok(twin)
    }
}
