//! Modal analysis: the exact modes of a linear structure and their sensitivities
//! ([`eigen`]), the indicators that compare and qualify mode shapes ([`indicators`]); modes
//! identified from records: Welch spectra and H1 FRFs ([`spectral`]), output-only SSI-COV
//! ([`ssi`]), input–output LSCF with LSFD shapes ([`lscf`]), the stabilisation diagram and the
//! automatic choice of the physical modes ([`stabilisation`]).

mod bell_fit;
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

/// Scale each column of a least-squares design to unit norm (a zero column is left alone),
/// as the fits do before solving when their columns differ in scale by orders of magnitude;
/// the scales, by which the solution's coefficients are multiplied back.
pub(crate) fn equilibrate_columns(design: &mut nalgebra::DMatrix<f64>) -> Vec<f64> {
    let scales: Vec<f64> = design
        .column_iter()
        .map(|c| {
            let n = c.norm();
            if n > 0.0 {
                1.0 / n
            } else {
                1.0
            }
        })
        .collect();
    for (c, scale) in scales.iter().enumerate() {
        design.column_mut(c).scale_mut(*scale);
    }
    scales
}
