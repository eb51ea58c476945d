//! `twin learn`: stream-based active learning of the GP corrector over records (the paper's
//! Algorithm 1), its table, plots and report.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::write_json;
use crate::twin::Twin;
use crate::workflows::learn::{
    chosen_modes, learned_twin, prepare, run_modes, table, FixedThreshold, LearnOptions, Mode,
    ModeResult, Stretch, FORGETTING,
};
use fmu_gp_corrector::TargetForm;

/// `--mode`: the query decision (the adaptive mode's forgetting factor is `--forgetting`).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ModeArg {
    Uniform,
    Fixed,
    Adaptive,
}

/// `--modes all`, the only value.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum AllModes {
    All,
}

#[derive(clap::Args)]
pub struct LearnArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// The twin (.ssp) whose physics the GPs correct (e.g. from `twin calibrate`); the default
    /// twin when absent. Only its physics is used.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// Measurement CSVs, streamed in this order; the training set carries over.
    #[arg(long, num_args = 1.., required = true)]
    pub data: Vec<PathBuf>,
    /// Query decision: uniform (every 25th point), fixed threshold, adaptive threshold.
    #[arg(long, value_enum, default_value_t = ModeArg::Adaptive)]
    pub mode: ModeArg,
    /// Forgetting factor f_f of the adaptive mode, in (0, 1]; 1 = plain adaptive.
    #[arg(long, default_value_t = FORGETTING)]
    pub forgetting: f64,
    /// `all`: uniform, fixed, adaptive f_f = 1, 0.999, 0.99, 0.9 (overrides --mode).
    #[arg(long, value_enum)]
    pub modes: Option<AllModes>,
    /// Directory for the plots (one SVG per mode) and the JSON report when --report is absent.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write the twin with the corrector as learned (its final training set and
    /// hyperparameters) behind the physics; one mode only.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Fixed threshold on the latent variance, (m/s²)², every floor. Default, per floor: with
    /// --target measured, the largest latent variance that GPs trained on the whole first record
    /// show on the first 100 samples of the second (how the reference paper set its 1e-3,
    /// Fig. 8); with the discrepancy target, 1e-3 × the floor's measured variance on the first
    /// record.
    #[arg(long)]
    pub threshold: Option<f64>,
    #[arg(long, default_value_t = LearnOptions::default().lags)]
    pub lags: usize,
    #[arg(long, value_parser = super::choice::<TargetForm>(), default_value = "discrepancy")]
    pub target: TargetForm,
    /// Seconds at the start of each record neither streamed nor scored.
    #[arg(long, default_value_t = LearnOptions::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// N_initial: points of the first record in the initial training set.
    #[arg(long, default_value_t = LearnOptions::default().initial)]
    pub initial: usize,
    /// At least this many queries between hyperparameter refits (warm-started); 0: never.
    #[arg(long, default_value_t = LearnOptions::default().refit_every)]
    pub refit_every: u32,
    /// Refit once the queries since the last fit reach this fraction of the training set at
    /// that fit (0: every --refit-every queries).
    #[arg(long, default_value_t = LearnOptions::default().refit_growth)]
    pub refit_growth: f64,
    /// L-BFGS iterations of a warm-started refit up to 512 training points; beyond, the same
    /// work (an iteration costs O(n³)), but at least 10.
    #[arg(long, default_value_t = LearnOptions::default().refit_iterations)]
    pub refit_iterations: u64,
    /// Recompute the NMSE over the record after every this many queries.
    #[arg(long, default_value_t = LearnOptions::default().nmse_every)]
    pub nmse_every: usize,
    /// Consecutive queried samples that flag a possible change of the structure.
    #[arg(long, default_value_t = LearnOptions::default().change_run)]
    pub change_run: usize,
}

impl ModeArg {
    fn name(self) -> &'static str {
        match self {
            ModeArg::Uniform => "uniform",
            ModeArg::Fixed => "fixed",
            ModeArg::Adaptive => "adaptive",
        }
    }
}

impl LearnArgs {
    /// The library's options and modes from the flags, checked.
    pub fn options(&self) -> Result<(LearnOptions, Vec<Mode>)> {
        let modes = chosen_modes(self.mode.name(), self.forgetting, self.modes.is_some())?;
        let options = LearnOptions {
            lags: self.lags,
            target: self.target.into(),
            transient: self.transient,
            initial: self.initial,
            threshold: self.threshold,
            refit_every: self.refit_every,
            refit_growth: self.refit_growth,
            refit_iterations: self.refit_iterations,
            nmse_every: self.nmse_every.max(1),
            change_run: self.change_run,
            ..LearnOptions::default()
        };
        options.validate()?;
        Ok((options, modes))
    }
}

pub fn run(args: &LearnArgs) -> Result<()> {
    let (options, modes) = args.options()?;
    if let Some(out) = &args.out {
        if args.modes.is_some() {
            bail!("--out keeps the corrector of one mode: give --mode, not --modes all");
        }
        if args.twin.as_deref() == Some(out.as_path()) {
            bail!(
                "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
                out.display()
            );
        }
    }
    let records = args
        .data
        .iter()
        .map(|p| args.columns.read_any(p))
        .collect::<Result<Vec<_>, _>>()?;
    let twin = Twin::load(args.twin.as_deref())?;
    for record in &records {
        crate::twin::guard::check_record(&twin, record)?;
    }
    let started = std::time::Instant::now();
    let streams = prepare(&twin, &records, &options)?;
    let results = run_modes(&streams, &modes, &options)?;
    let seconds = started.elapsed().as_secs_f64();

    print!("{}", table(&results));
    if let Some(fixed) = results.iter().find_map(|r| r.fixed_threshold.as_ref()) {
        print_fixed_threshold(fixed, &streams[0].layout.names());
    }
    print_change_flags(&results);
    println!(
        "{:.2} s ({} modes in parallel threads)",
        seconds,
        results.len()
    );

    if let (Some(path), [result]) = (&args.out, results.as_slice()) {
        learned_twin(&twin, result, &options)?.write(path)?;
        println!(
            "wrote {} (the corrector as learned: {} points)",
            path.display(),
            result.final_gps.len()
        );
    }
    let report_path = args
        .report
        .clone()
        .or_else(|| args.out_dir.as_ref().map(|d| d.join("learn.json")));
    if let Some(dir) = &args.out_dir {
        for path in crate::report::learn_plot::write_plots(&results, dir)? {
            println!("wrote {}", path.display());
        }
    }
    if let Some(path) = report_path {
        let records: Vec<String> = args.data.iter().map(|p| p.display().to_string()).collect();
        let report = crate::report::json::learn(&twin, &records, &options, seconds, &results);
        write_json(&path, &report)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The fixed threshold's rule and values (per channel, in its unit squared), and the stretches
/// it was trained and tested on.
fn print_fixed_threshold(fixed: &FixedThreshold, channels: &[String]) {
    let stretch = |s: &Option<Stretch>| {
        s.as_ref().map_or(String::new(), |s| {
            format!(
                "{} {:.1}–{:.1} s ({} points)",
                s.record, s.from, s.to, s.points
            )
        })
    };
    let how = match (&fixed.trained_on, &fixed.tested_on) {
        (Some(_), Some(_)) => format!(
            ": trained on {}, largest V(f) on {}",
            stretch(&fixed.trained_on),
            stretch(&fixed.tested_on)
        ),
        _ => String::new(),
    };
    if ::structure::paper::is_paper_rig(channels) {
        println!(
            "fixed threshold ({}{how}): {:.3e} / {:.3e} / {:.3e} (m/s²)²",
            fixed.rule, fixed.values[0], fixed.values[1], fixed.values[2]
        );
    } else {
        let each: Vec<String> = fixed.values.iter().map(|v| format!("{v:.3e}")).collect();
        println!(
            "fixed threshold ({}{how}): {} ({}; each in its unit squared)",
            fixed.rule,
            each.join(" / "),
            channels.join(" / ")
        );
    }
}

/// Each mode's runs of consecutive queries that say the structure may have changed.
fn print_change_flags(results: &[ModeResult]) {
    for r in results {
        for (k, rec) in r.records.iter().enumerate() {
            for flag in &rec.structure_may_have_changed {
                println!(
                    "{}: record {}: {} consecutive queries {:.2}–{:.2} s: the structure may have changed",
                    r.mode,
                    k + 1,
                    flag.samples,
                    flag.start,
                    flag.end
                );
            }
        }
    }
}
