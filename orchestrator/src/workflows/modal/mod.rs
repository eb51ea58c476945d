//! `twin modal`: the structure read by its modes. The twin's own modes — natural frequencies,
//! damping ratios and shapes of its linear part, each with its standard deviation from the
//! calibration's posterior ([`twin`]) — and the pairing of those with modes identified from a
//! record ([`pair`]): each mode's frequency shift in % and in units of the combined sd, the
//! damping change, the MAC matrix.

pub mod evidence;
pub mod explain;
pub mod identify;
pub mod pair;
pub mod twin;

pub use evidence::{
    evidence_of, modal_evidence, modal_evidence_with, ModalBand, ModalEvidence, ModeShift,
};
pub use explain::{explain_shifts, Explanation};
pub use identify::{
    identify, identify_ambient, identify_window, IdentifyError, IdentifyOptions, RecordModes,
};
pub use pair::{pair_modes, ModeComparison, ModePair, ObservedMode};
pub use twin::{twin_modes, ModalOptions, TwinMode, TwinModes};
// The methods' verdicts are the identification's last stage (identify/verdicts.rs).
pub use identify::verdicts::{self, verdicts, ModeVerdict};

#[derive(Debug, thiserror::Error)]
pub enum ModalError {
    #[error(transparent)]
    Twin(#[from] crate::twin::TwinError),
    #[error("the twin's structure: {0}")]
    Structure(#[from] ::structure::StructureError),
    #[error("the twin's modes: {0}")]
    Modes(#[from] numerics::modal::ModalError),
    #[error("{0}")]
    Options(String),
}
