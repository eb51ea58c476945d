//! Reports on a model-against-measurement comparison: SVG plots of the time histories (the
//! paper's Figure 4) and, optionally, of the frequency-response estimates (its Figure 3).
//!
//! Only SVG is written: text goes out as `<text>` elements, so nothing here needs system fonts.

use std::path::PathBuf;

pub mod learn_plot;
pub mod plot;
pub mod run_plot;

pub use plot::{plot_comparison, plot_latent_variance, welch_h1, FrequencyResponse, FRF_SEGMENT};

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("only .svg is supported: {}", path.display())]
    UnsupportedFormat { path: PathBuf },
    #[error("cannot plot {}: {message}", path.display())]
    BadInput { path: PathBuf, message: String },
    #[error("cannot draw {}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
    #[error(transparent)]
    Write(#[from] crate::fsutil::WriteError),
}
