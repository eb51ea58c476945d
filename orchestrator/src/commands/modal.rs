//! `twin modal`: the twin's natural frequencies, damping ratios and mode shapes, each with its
//! sd from the calibration's posterior (checked against sampling it).

use std::path::PathBuf;

use anyhow::Result;

use super::write_json;
use crate::twin::Twin;
use crate::workflows::modal::{twin_modes, ModalOptions, TwinModes};
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct ModalArgs {
    /// The twin (.ssp); the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Plot (.svg): the mode shapes along the height with their ±2 sd.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Draws from the posterior that check the linearised sds (0: no check).
    #[arg(long, default_value_t = ModalOptions::default().samples)]
    pub samples: usize,
}

pub fn run(args: &ModalArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    let twin = Twin::load(args.twin.as_deref())?;
    let options = ModalOptions {
        samples: args.samples,
        ..ModalOptions::default()
    };
    let modes = twin_modes(&twin, &options)?;
    print_twin_modes(&modes);
    if let Some(path) = &args.report {
        write_json(path, &serde_json::json!({ "twin": &modes }))?;
    }
    if let Some(path) = &args.plot {
        crate::report::mode_plot::plot_mode_shapes(&modes, None, path)?;
    }
    Ok(())
}

pub(crate) fn print_twin_modes(modes: &TwinModes) {
    println!(
        "{}: {} storeys, excitation {}",
        modes.twin, modes.storeys, modes.excitation
    );
    if modes.uncertain_parameters.is_empty() {
        println!("  uncalibrated twin: no posterior, no sds");
    } else {
        println!(
            "  sds from the posterior of {} (sampled sd beside the linearised one)",
            modes.uncertain_parameters.join(", ")
        );
    }
    for m in &modes.modes {
        let shape: Vec<String> = m.shape.iter().map(|x| format!("{x:+.3}")).collect();
        let sampled = m
            .sampled
            .as_ref()
            .map(|s| {
                format!(
                    " [sampled {:.4} Hz, {:.4} %]",
                    s.frequency_sd,
                    100.0 * s.damping_sd
                )
            })
            .unwrap_or_default();
        println!(
            "  mode {}: {:.4}{} Hz  ζ {:.4}{} %{}  shape [{}]",
            m.number,
            m.frequency,
            m.frequency_sd
                .map(|s| format!(" ± {s:.4}"))
                .unwrap_or_default(),
            100.0 * m.damping,
            m.damping_sd
                .map(|s| format!(" ± {:.4}", 100.0 * s))
                .unwrap_or_default(),
            sampled,
            shape.join(" ")
        );
    }
}
