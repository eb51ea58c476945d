//! `twin train`: train the GP bias corrector on a record and put it behind the physics FMU.

use std::path::PathBuf;

use anyhow::{bail, Result};
use serde_json::json;

use super::{nmse_on, write_json};
use crate::twin::data::Measurement;
use crate::twin::Twin;

#[derive(clap::Args)]
pub struct TrainArgs {
    /// The twin (.ssp) whose physics the corrector corrects; the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// Measurement CSV to train on.
    #[arg(long)]
    pub data: PathBuf,
    /// The twin with the corrector (.ssp) to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Lags q: the GP's inputs are the current and q previous physics accelerations and forces.
    #[arg(long, default_value_t = fmu_gp_corrector::DEFAULT_LAGS)]
    pub lags: usize,
    /// What the GP models: the discrepancy measured − physics (default), or the measured
    /// acceleration itself (the reference paper's zero-mean form).
    #[arg(long, value_enum, default_value_t = super::Target::Discrepancy)]
    pub target: super::Target,
    /// Seconds at the start of the record not used for training.
    #[arg(long, default_value_t = crate::evaluation::compare::DEFAULT_TRANSIENT, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Train on every n-th sample after the transient (a GP fit costs O(N³)).
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Choose the lags among these (e.g. 1,3,5,7,9,11) by the lowest total negative log
    /// marginal likelihood of the three GPs, fitted on every `--selection-stride`-th sample;
    /// overrides --lags.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    pub select_lags: Vec<usize>,
    /// Every n-th sample for the lag selection's fits.
    #[arg(long, default_value_t = 4)]
    pub selection_stride: usize,
    /// JSON report of the training.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

pub fn run(args: &TrainArgs) -> Result<()> {
    use crate::workflows::train::{train, TrainOptions};
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    let data = Measurement::read(&args.data)?;
    let twin = Twin::load(args.twin.as_deref())?;
    if args.stride == 0 {
        bail!("--stride must be at least 1");
    }
    let mut options = TrainOptions {
        lags: args.lags,
        target: args.target.into(),
        transient: args.transient,
        stride: args.stride,
    };
    let mut selection = Vec::new();
    if !args.select_lags.is_empty() {
        if args
            .select_lags
            .iter()
            .any(|&q| q == 0 || q > fmu_gp_corrector::training::MAX_LAGS)
        {
            bail!(
                "--select-lags: each count must be in 1..={}, got {:?}",
                fmu_gp_corrector::training::MAX_LAGS,
                args.select_lags
            );
        }
        if args.selection_stride == 0 {
            bail!("--selection-stride must be at least 1");
        }
        selection = crate::workflows::train::select_lags(
            &twin,
            &data,
            &args.select_lags,
            &TrainOptions {
                stride: args.selection_stride,
                ..options.clone()
            },
        )?;
        println!("lags   NLML (floors 1 / 2 / 3)                 total");
        for s in &selection {
            println!(
                "{:>4}   {:>11.1} / {:>11.1} / {:>11.1}   {:>11.1}",
                s.lags, s.nlml[0], s.nlml[1], s.nlml[2], s.total
            );
        }
        options.lags = selection[0].lags;
        println!(
            "chosen: {} lags (lowest negative log marginal likelihood)",
            options.lags
        );
    }
    let (trained, summary) = train(&twin, &data, &options)?;
    let nmse = nmse_on(&trained, &data, args.transient)?;
    trained.write(&args.out)?;
    if let Some(path) = &args.report {
        let report = json!({
            "twin": twin.describe(),
            "data": data.path.display().to_string(),
            "out": args.out.display().to_string(),
            "training": summary,
            "lag_selection": selection,
            "nmse": nmse,
        });
        write_json(path, &report)?;
    }
    println!(
        "trained the corrector on {}: {} points, {} inputs ({} lags), target {}, {:.2} s",
        data.path.display(),
        summary.points,
        summary.inputs,
        summary.lags,
        summary.target,
        summary.seconds
    );
    println!(
        "NMSE % of the corrected twin on {}: {:.3} / {:.3} / {:.3}",
        data.path.display(),
        nmse[0],
        nmse[1],
        nmse[2]
    );
    println!("wrote {}", args.out.display());
    Ok(())
}
