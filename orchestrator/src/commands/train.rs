//! `twin train`: train the GP bias corrector on a record and put it behind the physics FMU.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::write_json;
use crate::twin::Twin;
use crate::workflows::train::{train_selected, LagSelection, TrainOptions, SELECTION_STRIDE};
use fmu_gp_corrector::TargetForm;

#[derive(clap::Args)]
pub struct TrainArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// The twin (.ssp) whose physics the corrector corrects; the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// Measurement CSV to train on.
    #[arg(long)]
    pub data: PathBuf,
    /// The twin with the corrector (.ssp) to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Lags q: each channel's GP takes the current and q previous physics predictions of the
    /// channel and its nearest measured neighbours (at most two) and of the excitation.
    #[arg(long, default_value_t = TrainOptions::default().lags)]
    pub lags: usize,
    /// What the GP models: the discrepancy measured − physics (default), or the measured
    /// acceleration itself (the reference paper's zero-mean form).
    #[arg(long, value_parser = super::choice::<TargetForm>(), default_value = "discrepancy")]
    pub target: TargetForm,
    /// Seconds at the start of the record not used for training.
    #[arg(long, default_value_t = TrainOptions::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Train on every n-th sample after the transient (a GP fit costs O(N³)).
    #[arg(long, default_value_t = TrainOptions::default().stride)]
    pub stride: usize,
    /// Choose the lags among these (e.g. 1,3,5,7,9,11) by the lowest total negative log
    /// marginal likelihood of the channels' GPs, fitted on every `--selection-stride`-th sample;
    /// overrides --lags.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    pub select_lags: Vec<usize>,
    /// Every n-th sample for the lag selection's fits.
    #[arg(long, default_value_t = SELECTION_STRIDE)]
    pub selection_stride: usize,
    /// JSON report of the training.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

impl TrainArgs {
    /// The library's options from the flags, and the lag selection when asked for.
    pub fn options(&self) -> (TrainOptions, Option<LagSelection>) {
        let options = TrainOptions {
            lags: self.lags,
            target: self.target.into(),
            transient: self.transient,
            stride: self.stride,
        };
        let selection = (!self.select_lags.is_empty()).then(|| LagSelection {
            candidates: self.select_lags.clone(),
            stride: self.selection_stride,
        });
        (options, selection)
    }
}

pub fn run(args: &TrainArgs) -> Result<()> {
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    let data = args.columns.read_any(&args.data)?;
    let twin = Twin::load(args.twin.as_deref())?;
    crate::twin::guard::check_record(&twin, &data)?;
    let (options, selection) = args.options();
    options.validate()?;
    if let Some(s) = &selection {
        s.validate()?;
    }
    let trained = train_selected(&twin, &data, &options, selection.as_ref())?;
    if !trained.selection.is_empty() {
        let rig = ::structure::paper::is_paper_rig(trained.channels.as_slice());
        if rig {
            println!("lags   NLML (floors 1 / 2 / 3)                 total");
        } else {
            println!("lags   NLML ({})   total", trained.channels.join(" / "));
        }
        for s in &trained.selection {
            if rig {
                println!(
                    "{:>4}   {:>11.1} / {:>11.1} / {:>11.1}   {:>11.1}",
                    s.lags, s.nlml[0], s.nlml[1], s.nlml[2], s.total
                );
            } else {
                let each: Vec<String> = s.nlml.iter().map(|v| format!("{v:.1}")).collect();
                println!("{:>4}   {}   {:.1}", s.lags, each.join(" / "), s.total);
            }
        }
        println!(
            "chosen: {} lags (lowest negative log marginal likelihood)",
            trained.summary.lags
        );
    }
    trained.twin.write(&args.out)?;
    if let Some(path) = &args.report {
        let report = crate::report::json::train(&twin, &data, Some(&args.out), &trained);
        write_json(path, &report)?;
    }
    let (summary, nmse) = (&trained.summary, &trained.nmse);
    println!(
        "trained the corrector on {}: {} points, {} inputs ({} lags), target {}, {:.2} s",
        data.path.display(),
        summary.points,
        summary.inputs,
        summary.lags,
        summary.target,
        summary.seconds
    );
    if ::structure::paper::is_paper_rig(trained.channels.as_slice()) {
        println!(
            "NMSE % of the corrected twin on {}: {:.3} / {:.3} / {:.3}",
            data.path.display(),
            nmse[0],
            nmse[1],
            nmse[2]
        );
    } else {
        let each = |v: &[f64]| -> String {
            v.iter()
                .map(|x| format!("{x:.3}"))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        println!(
            "NMSE % on {} ({}): physics alone {}, corrected {}",
            data.path.display(),
            trained.channels.join(" / "),
            each(&trained.nmse_physics),
            each(nmse)
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
