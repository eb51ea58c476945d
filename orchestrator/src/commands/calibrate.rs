//! `twin calibrate`: MAP calibration of the physics parameters and noise variances.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::write_json;
use crate::twin::data::Measurement;
use crate::twin::run::Tolerance;
use crate::twin::{RecordRef, RecordRole, Twin};
use crate::workflows::calibrate::{calibrate_validated, read_priors, CalibrationSetup, Validated};
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// Measurement CSV to calibrate on.
    #[arg(long)]
    pub data: PathBuf,
    /// The twin to start from (.ssp); the default twin when absent. It is not modified.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// The calibrated twin (.ssp) to write.
    #[arg(long)]
    pub out: PathBuf,
    /// A real parameter of the physics FMU to calibrate (repeat); default m1..3, c1..3, k1..3.
    #[arg(long = "param")]
    pub params: Vec<String>,
    /// JSON file of priors overriding the defaults: {"k1": {"space": "linear", "mean": 4021, "variance": 10000}}.
    #[arg(long)]
    pub priors: Option<PathBuf>,
    /// Seconds at the start of the record left out of the likelihood.
    #[arg(long, default_value_t = CalibrationSetup::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Optimiser starts (the prior mean plus draws from the widened prior).
    #[arg(long, default_value_t = CalibrationSetup::default().starts)]
    pub starts: usize,
    #[arg(long, default_value_t = CalibrationSetup::default().seed)]
    pub seed: u64,
    /// Other records to report the calibrated twin's NMSE on.
    #[arg(long, num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Plot (.svg) of the calibrated twin on the calibration record.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(args: &CalibrateArgs) -> Result<()> {
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    let data = args.columns.read_record(&args.data)?;
    let validation = args
        .validate
        .iter()
        .map(|p| args.columns.read_record(p))
        .collect::<Result<Vec<_>, _>>()?;
    let twin = Twin::load(args.twin.as_deref())?;
    for record in std::iter::once(&data).chain(&validation) {
        crate::twin::guard::check_paper_rig(&twin, record, "calibrate")?;
    }
    let mut setup = CalibrationSetup {
        transient: args.transient,
        starts: args.starts,
        seed: args.seed,
        ..CalibrationSetup::default()
    };
    if !args.params.is_empty() {
        setup.parameters = args.params.clone();
    }
    if let Some(path) = &args.priors {
        setup.priors = read_priors(path).map_err(anyhow::Error::msg)?;
    }
    let validation: Vec<&Measurement> = validation.iter().collect();
    let Validated {
        twin: mut new_twin,
        calibration,
        validated,
    } = calibrate_validated(&twin, &data, &validation, &setup)?;
    // The records, for `twin add-physics` to refit over.
    new_twin.records = std::iter::once(RecordRef::of(&args.data, RecordRole::Calibration))
        .chain(
            args.validate
                .iter()
                .map(|p| RecordRef::of(p, RecordRole::Validation)),
        )
        .collect::<Result<_, _>>()?;

    // All computed: now write, each file atomically.
    new_twin.write(&args.out)?;
    if let Some(path) = &args.report {
        let report = crate::report::json::calibrate(
            &twin,
            &new_twin,
            Some(&args.out),
            &data,
            args.transient,
            &calibration,
            &validated,
        );
        write_json(path, &report)?;
    }
    if let Some(path) = &args.plot {
        crate::workflows::calibrate::validated::plot(&new_twin, &data, args.transient, path)?;
    }

    println!(
        "calibrated on {} ({} starts, {} simulations, {:.2} s)",
        data.path.display(),
        calibration.starts.len(),
        calibration.simulations,
        calibration.seconds
    );
    println!(
        "{:<10} {:>12} {:>12} {:>14}",
        "parameter", "MAP", "sd", "prior mean"
    );
    for p in &calibration.parameters {
        println!(
            "{:<10} {:>12.4} {:>12.4} {:>14.4}",
            p.name,
            p.value,
            p.sd,
            p.prior.value(p.prior.mean)
        );
    }
    for f in 0..3 {
        println!(
            "noise{}     {:>12.4e} (σ² in (m/s²)²; sd of log σ² {:.3})",
            f + 1,
            calibration.noise_variance[f],
            calibration.noise_log_sd[f]
        );
    }
    let names: Vec<&str> = calibration
        .parameters
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    let mut strongest = Vec::new();
    for a in 0..names.len() {
        for b in a + 1..names.len() {
            strongest.push((calibration.correlation[a][b], names[a], names[b]));
        }
    }
    strongest.sort_by(|x, y| y.0.abs().total_cmp(&x.0.abs()));
    let shown: Vec<String> = strongest
        .iter()
        .take(3)
        .map(|(r, a, b)| format!("{a}–{b} {r:+.2}"))
        .collect();
    println!("strongest correlations: {}", shown.join(", "));
    println!(
        "NMSE % on {}: {:.3} / {:.3} / {:.3}",
        data.path.display(),
        calibration.nmse[0],
        calibration.nmse[1],
        calibration.nmse[2]
    );
    for (p, n) in &validated {
        println!(
            "NMSE % on {p}: {:.3} / {:.3} / {:.3}{}",
            n[0],
            n[1],
            n[2],
            if crate::report::json::accepted_for_validation(n) {
                ""
            } else {
                " (above the cap: not taken as the twin's validation level)"
            }
        );
    }
    let tolerance = Tolerance::resolve(&new_twin, None);
    println!(
        "tolerance of compare and diagnose: {:.3} % NMSE ({})",
        tolerance.value, tolerance.source
    );
    println!("wrote {}", args.out.display());
    Ok(())
}
