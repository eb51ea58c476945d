//! `twin init`: the default twin (the shear FMU, default parameters) as an SSP archive; with
//! `--storeys`, `--excitation` or `--nominal`, the twin of that shear building.

use std::path::PathBuf;

use anyhow::Result;

use crate::twin::structure::{InitOptions, Nominal};
use crate::workflows::init::InitRequest;

#[derive(clap::Args)]
pub struct InitArgs {
    #[arg(long)]
    pub out: PathBuf,
    /// Storeys of the building (1 to 50); 3 by default, or as many as NOMINAL.json has masses.
    #[arg(long)]
    pub storeys: Option<usize>,
    /// What shakes it: `force:K` (a force at floor K, the input `force`) or `base` (ground
    /// acceleration, the input `ground_acc`); `force:1` by default.
    #[arg(long, value_parser = parse_excitation)]
    pub excitation: Option<structure::Excitation>,
    /// The nominal structure, `{"m": [...], "c": [...], "k": [...]}` in kg, N s/m, N/m: the
    /// FMU's start values. Without it, every floor and storey is the paper's (5.2 kg,
    /// exp(-4.605) N s/m, 4021 N/m).
    #[arg(long, value_name = "NOMINAL.json")]
    pub nominal: Option<PathBuf>,
    /// The calibration's priors, kept in the twin (`resources/priors.json`) for `twin
    /// calibrate`: by family (m, c, k) or parameter (m1..mN, c1..cN, k1..kN), each with space
    /// (linear|log), value or mean, and one of sd, variance, relative_sd, e.g. {"m":
    /// {"relative_sd": 0.05}, "k": {"space": "log", "sd": 0.3}}. Without it: Table 1 on the
    /// paper's rig; otherwise centred on the nominal, mass sd 10 %, stiffness log-sd 0.25,
    /// damping log-sd 1.
    #[arg(long, value_name = "P.json")]
    pub priors: Option<PathBuf>,
}

fn parse_excitation(text: &str) -> Result<structure::Excitation, String> {
    structure::Excitation::parse(text).map_err(|e| e.to_string())
}

pub fn run(args: &InitArgs) -> Result<()> {
    let nominal = match &args.nominal {
        Some(path) => Some((path.clone(), Nominal::read(path)?)),
        None => None,
    };
    let priors = match &args.priors {
        Some(path) => Some((
            path.display().to_string(),
            std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
        )),
        None => None,
    };
    let request = InitRequest {
        structure: InitOptions {
            storeys: args.storeys,
            excitation: args.excitation,
            nominal,
        },
        priors,
    };
    request.twin()?.write(&args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
