//! Modal analysis: the exact modes of a linear structure and their sensitivities
//! ([`eigen`]), the indicators that compare and qualify mode shapes ([`indicators`]); modes
//! identified from records: Welch spectra and H1 FRFs ([`spectral`]), output-only SSI-COV
//! ([`ssi`]), input–output LSCF with LSFD shapes ([`lscf`]), the stabilisation diagram and the
//! automatic choice of the physical modes ([`stabilisation`]).

pub mod eigen;
pub mod error;
pub mod fdd;
pub mod indicators;
pub mod lscf;
pub mod spectral;
pub mod ssi;
pub mod stabilisation;
pub mod time_fit;

pub use eigen::{modes, ModalError, Mode};
pub use error::IdentificationError;
pub use indicators::{mac, mac_matrix, mpc, mpd};

/// Complex numbers of the modal results (num-complex's, as faer and nalgebra use).
pub type Complex = faer::c64;
