//! Modal analysis: the exact modes of a linear structure and their sensitivities
//! ([`eigen`]), the indicators that compare and qualify mode shapes ([`indicators`]).

pub mod eigen;
pub mod indicators;

pub use eigen::{modes, ModalError, Mode};
pub use indicators::{mac, mac_matrix};

/// Complex numbers of the modal results (num-complex's, as faer and nalgebra use).
pub type Complex = faer::c64;
