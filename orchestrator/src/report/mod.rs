//! The plots: a model against a record (`plot`: the time histories of the paper's Figure 4 and
//! the frequency responses of its Figure 3), a diagnosis (`diagnose_plot`), active learning
//! (`learn_plot`) and `twin run`'s outputs (`run_plot`). The JSON reports are written by the
//! commands from the workflows' serialisable results; those of compare and calibrate are built
//! here (`json`), for the CLI and the Python package alike.
//!
//! Only SVG is written: text goes out as `<text>` elements, so nothing here needs system fonts.

use std::path::PathBuf;

pub mod control_plot;
pub mod diagnose_plot;
pub mod frf_plot;
pub mod hybrid_plot;
pub mod json;
pub mod learn_plot;
pub mod modal_plot;
pub mod mode_plot;
pub mod plot;

/// Every plot's colours: the Okabe–Ito set (apart for colour-blind readers too), a red for
/// what fails or is queried, and two greys. Each plot names its roles with these.
pub mod palette {
    use plotters::style::RGBColor;

    pub const BLUE: RGBColor = RGBColor(0x00, 0x72, 0xB2);
    pub const ORANGE: RGBColor = RGBColor(0xE6, 0x9F, 0x00);
    pub const GREEN: RGBColor = RGBColor(0x00, 0x9E, 0x73);
    pub const VERMILION: RGBColor = RGBColor(0xD5, 0x5E, 0x00);
    pub const RED: RGBColor = RGBColor(0xD6, 0x27, 0x28);
    pub const DARK_GREY: RGBColor = RGBColor(0x33, 0x33, 0x33);
    pub const GREY: RGBColor = RGBColor(0x80, 0x80, 0x80);
    /// One colour per floor, in floor order.
    pub const FLOORS: [RGBColor; 3] = [BLUE, ORANGE, GREEN];
}
pub mod run_plot;

pub use plot::{
    plot_calibrated, plot_compared, plot_comparison, plot_latent_variance, FRF_SEGMENT,
};

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
