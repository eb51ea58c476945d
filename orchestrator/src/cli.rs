//! The `twin` commands: arguments → validated configuration → work → files written atomically.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use serde_json::json;

use crate::compare::{compare, CompareOptions, Comparison};
use crate::data::Measurement;
use crate::run::{run_twin, Prediction, Progress};
use crate::twin::Twin;

#[derive(Parser)]
#[command(
    name = "twin",
    version,
    about = "shear-twin: an operational digital twin of a shear frame, on FMI 2.0"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run the twin on a measurement's force and compare its accelerations with the measured ones.
    Compare(CompareArgs),
    /// MAP calibration of the physics parameters and noise variances on a measurement.
    Calibrate(CalibrateArgs),
    /// Train the Gaussian-process bias corrector on a record and put it behind the physics FMU.
    Train(TrainArgs),
    /// Package a built FMU library and its modelDescription.xml into a .fmu archive.
    PackFmu(PackArgs),
    /// Write the default twin (the shear FMU, default parameters) as an SSP archive.
    Init {
        #[arg(long)]
        out: PathBuf,
    },
    /// Make a synthetic measurement record (the synthetic physical twin) and its truth JSON.
    Synth(crate::synth::SynthArgs),
    /// Stream-based active learning of the GP corrector over records (paper Algorithm 1).
    Learn(crate::learn::LearnArgs),
    /// Diagnose a failing twin: none, recalibrate, add physics (which effect, where, how
    /// strong) or update the data-based model, with the evidence.
    Diagnose(crate::diagnose::command::DiagnoseArgs),
    /// Switch an effect of the shear FMU's library on, estimate its parameters, write the twin.
    AddPhysics(crate::diagnose::command::AddPhysicsArgs),
    /// Run any FMI 2.0 co-simulation FMU or SSP system and record its outputs as CSV.
    Run(crate::cli_run::RunArgs),
}

#[derive(clap::Args)]
pub struct CompareArgs {
    /// The twin (.ssp); the default twin when absent.
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// Measurement CSV: time,force,acc1,acc2,acc3.
    #[arg(long)]
    pub data: PathBuf,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Predicted accelerations as CSV (time,acc1,acc2,acc3).
    #[arg(long)]
    pub predictions: Option<PathBuf>,
    /// Plot (.svg): measured, predicted, ±3σ band, residual, failing windows.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also draw the frequency-response view.
    #[arg(long)]
    pub frf: bool,
    /// Threshold line of the latent-variance view (`<plot>-latent.svg`, drawn when the twin has
    /// a corrector), (m/s²)², every floor. Default: each floor's sensor-noise variance from the
    /// twin's calibration — above it the GP is less sure of the bias than a single measurement
    /// is, so the point would be worth learning; for an uncalibrated twin, 1e-3 × each floor's
    /// measured variance on this record.
    #[arg(long)]
    pub latent_threshold: Option<f64>,
    /// Seconds at the start left out of the error measures.
    #[arg(long, default_value_t = crate::compare::DEFAULT_TRANSIENT)]
    pub transient: f64,
}

#[derive(clap::Args)]
pub struct CalibrateArgs {
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
    #[arg(long, default_value_t = crate::compare::DEFAULT_TRANSIENT)]
    pub transient: f64,
    /// Optimiser starts (the prior mean plus draws from the widened prior).
    #[arg(long, default_value_t = 12)]
    pub starts: usize,
    #[arg(long, default_value_t = 1)]
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
    #[arg(long, default_value = "discrepancy", value_parser = ["discrepancy", "measured"])]
    pub target: String,
    /// Seconds at the start of the record not used for training.
    #[arg(long, default_value_t = crate::compare::DEFAULT_TRANSIENT)]
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

#[derive(clap::Args)]
pub struct PackArgs {
    #[arg(long)]
    pub model_description: PathBuf,
    #[arg(long)]
    pub library: PathBuf,
    #[arg(long)]
    pub documentation: Option<PathBuf>,
    #[arg(long)]
    pub resources: Option<PathBuf>,
    #[arg(long)]
    pub out: PathBuf,
}

/// Noise variance when the twin has none (not calibrated): 2 % of each floor's measured
/// variance, the centre the calibration's noise prior uses.
pub const PRIOR_NOISE_FRACTION: f64 = 0.02;

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Compare(args) => compare_command(&args),
        Command::Calibrate(args) => calibrate_command(&args),
        Command::Train(args) => train_command(&args),
        Command::PackFmu(a) => {
            let contents = crate::fmu_archive::FmuContents {
                model_description: a.model_description,
                library: a.library,
                documentation: a.documentation,
                resources: a.resources,
            };
            let id = crate::fmu_archive::pack_fmu(&contents, &a.out)?;
            println!("wrote {} (modelIdentifier {id})", a.out.display());
            Ok(())
        }
        Command::Init { out } => {
            Twin::default_twin()?.write(&out)?;
            println!("wrote {}", out.display());
            Ok(())
        }
        Command::Synth(args) => crate::synth::synth_command(&args),
        Command::Learn(args) => crate::learn::learn_command(&args),
        Command::Diagnose(args) => crate::diagnose::command::diagnose_command(&args),
        Command::AddPhysics(args) => crate::diagnose::command::add_physics_command(&args),
        Command::Run(args) => crate::cli_run::run_command(&args),
    }
}

/// Write through a temporary file in the same directory, then rename: a failure leaves no
/// partial file.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> Result<()>,
) -> Result<()> {
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(parent)
        .with_context(|| format!("{}: cannot create a temporary file", parent.display()))?;
    write(tmp.as_file_mut()).with_context(|| format!("writing {}", path.display()))?;
    crate::fmu_archive::persist_readable(tmp, path)
        .with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(())
}

fn variance(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n
}

pub fn progress_bar() -> impl FnMut(u64, u64) {
    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut progress = Progress::new(move |done, total| {
        let b = bar.get_or_insert_with(|| indicatif::ProgressBar::new(total));
        b.set_position(done);
        if done == total {
            b.finish_and_clear();
        }
    });
    move |done, total| progress.tick(done, total)
}

pub fn compare_command(args: &CompareArgs) -> Result<()> {
    if !(args.transient >= 0.0 && args.transient.is_finite()) {
        bail!(
            "--transient must be a non-negative number of seconds, was {}",
            args.transient
        );
    }
    if let Some(plot) = &args.plot {
        if plot.extension().and_then(|e| e.to_str()) != Some("svg") {
            bail!("{}: only .svg plots are supported", plot.display());
        }
    }
    if let Some(t) = args.latent_threshold {
        if !(t > 0.0 && t.is_finite()) {
            bail!("--latent-threshold must be a positive number, was {t}");
        }
    }
    let data = Measurement::read(&args.data)?;
    if args.transient >= data.duration() {
        bail!(
            "--transient {} s leaves nothing of {} ({} s long)",
            args.transient,
            data.path.display(),
            data.duration()
        );
    }
    let twin = Twin::load(args.twin.as_deref())?;
    let prediction = run_twin(&twin, &data, progress_bar())?;
    let (noise_variance, noise_source) = match twin.noise_variance {
        Some(v) => (v, "twin (calibrated)"),
        None => (
            [0, 1, 2].map(|f| PRIOR_NOISE_FRACTION * variance(&data.acc[f])),
            "prior: 2 % of the measured variance",
        ),
    };
    let options = CompareOptions {
        transient: args.transient,
        ..CompareOptions::default()
    };
    let comparison = compare(
        &data.time,
        &data.acc,
        &prediction.acc,
        noise_variance,
        prediction.sd.as_ref(),
        options,
    );

    // Everything is computed before anything is written: a failure leaves no partial output.
    if let Some(path) = &args.predictions {
        write_atomically(path, |f| write_predictions(f, &prediction))?;
    }
    if let Some(path) = &args.report {
        let report = json!({
            "twin": twin.describe(),
            "data": data.path.display().to_string(),
            "nmse": comparison.nmse,
            "failing_windows": comparison.failing_windows,
            "noise_variance": noise_variance,
            "noise_variance_source": noise_source,
            "transient": args.transient,
            "samples": data.len(),
            "sample_interval": data.dt,
        });
        write_atomically(path, |f| {
            serde_json::to_writer_pretty(&mut *f, &report)?;
            f.write_all(b"\n")?;
            Ok(())
        })?;
    }
    if let Some(path) = &args.plot {
        let title = format!("{} on {}", twin.describe(), data.path.display());
        crate::report::plot_comparison(&comparison, &data.force, &title, path, args.frf)?;
        if let Some(latent) = &prediction.latent_var {
            let threshold = match (args.latent_threshold, twin.noise_variance) {
                (Some(t), _) => [t; 3],
                (None, Some(v)) => v,
                (None, None) => [0, 1, 2].map(|f| {
                    crate::learn::PAPER_THRESHOLD * variance(&data.acc[f][comparison.first..])
                }),
            };
            crate::report::plot_latent_variance(&comparison, latent, threshold, &title, path)?;
        }
    }
    print_summary(&twin, &data, &comparison);
    Ok(())
}

/// `time,acc1,acc2,acc3`, then the corrector's `latent_var1..3,sd1..3` when the twin has one.
fn write_predictions(f: &mut std::fs::File, p: &Prediction) -> Result<()> {
    let mut w = csv::Writer::from_writer(f);
    let mut header: Vec<String> = ["time", "acc1", "acc2", "acc3"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let mut columns: Vec<&Vec<f64>> = p.acc.iter().collect();
    for (prefix, triple) in [("latent_var", &p.latent_var), ("sd", &p.sd)] {
        if let Some(values) = triple {
            for (f, column) in values.iter().enumerate() {
                header.push(format!("{prefix}{}", f + 1));
                columns.push(column);
            }
        }
    }
    w.write_record(&header)?;
    for k in 0..p.time.len() {
        let mut row = vec![format!("{}", p.time[k])];
        row.extend(columns.iter().map(|c| format!("{:e}", c[k])));
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}

fn print_summary(twin: &Twin, data: &Measurement, c: &Comparison) {
    println!("twin: {}", twin.describe());
    println!(
        "data: {} ({} samples, {} Hz)",
        data.path.display(),
        data.len(),
        1.0 / data.dt
    );
    println!("{:<8} {:>10} {:>12}", "floor", "NMSE %", "noise sd");
    for f in 0..3 {
        println!("{:<8} {:>10.3} {:>12.4e}", f + 1, c.nmse[f], c.noise_sd[f]);
    }
    if c.failing_windows.is_empty() {
        println!("failing windows: none (the residual stays inside ±3σ)");
    } else {
        println!("failing windows ({}):", c.failing_windows.len());
        for w in &c.failing_windows {
            let floors: Vec<String> = w.floors.iter().map(|f| f.to_string()).collect();
            println!(
                "  {:>7.2}–{:<7.2} s  floors {:<6} NMSE {:.1} / {:.1} / {:.1} %",
                w.start,
                w.end,
                floors.join(","),
                w.nmse[0],
                w.nmse[1],
                w.nmse[2]
            );
        }
    }
}

/// NMSE per floor of `twin` on `data` after the transient.
pub fn nmse_on(twin: &Twin, data: &Measurement, transient: f64) -> Result<[f64; 3]> {
    let prediction = run_twin(twin, data, |_, _| {})?;
    let first = data
        .time
        .iter()
        .position(|&t| t - data.time[0] >= transient)
        .unwrap_or(data.len());
    Ok([0, 1, 2].map(|f| crate::compare::nmse(&data.acc[f][first..], &prediction.acc[f][first..])))
}

pub fn calibrate_command(args: &CalibrateArgs) -> Result<()> {
    use crate::calibrate::{calibrate, calibrated_twin, read_priors, CalibrationSetup};
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    if !(args.transient >= 0.0 && args.transient.is_finite()) {
        bail!(
            "--transient must be a non-negative number of seconds, was {}",
            args.transient
        );
    }
    if let Some(plot) = &args.plot {
        if plot.extension().and_then(|e| e.to_str()) != Some("svg") {
            bail!("{}: only .svg plots are supported", plot.display());
        }
    }
    let data = Measurement::read(&args.data)?;
    let validation = args
        .validate
        .iter()
        .map(|p| Measurement::read(p))
        .collect::<Result<Vec<_>, _>>()?;
    let twin = Twin::load(args.twin.as_deref())?;
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
    let calibration = calibrate(&twin, &data, &setup)?;
    let new_twin = calibrated_twin(&twin, &calibration)?;
    let mut validated = Vec::new();
    for v in &validation {
        validated.push((
            v.path.display().to_string(),
            nmse_on(&new_twin, v, args.transient)?,
        ));
    }

    // All computed: now write, each file atomically.
    new_twin.write(&args.out)?;
    if let Some(path) = &args.report {
        let report = json!({
            "twin": twin.describe(),
            "out": args.out.display().to_string(),
            "data": data.path.display().to_string(),
            "transient": args.transient,
            "parameters": calibration.parameters,
            "correlation": calibration.correlation,
            "noise_variance": calibration.noise_variance,
            "noise_log_sd": calibration.noise_log_sd,
            "neg_log_posterior": calibration.neg_log_posterior,
            "nmse": calibration.nmse,
            "validation": validated.iter().map(|(p, n)| json!({"data": p, "nmse": n})).collect::<Vec<_>>(),
            "starts": calibration.starts,
            "simulations": calibration.simulations,
            "seconds": calibration.seconds,
        });
        write_atomically(path, |f| {
            serde_json::to_writer_pretty(&mut *f, &report)?;
            f.write_all(b"\n")?;
            Ok(())
        })?;
    }
    if let Some(path) = &args.plot {
        let prediction = run_twin(&new_twin, &data, |_, _| {})?;
        let options = CompareOptions {
            transient: args.transient,
            ..CompareOptions::default()
        };
        let comparison = compare(
            &data.time,
            &data.acc,
            &prediction.acc,
            calibration.noise_variance,
            prediction.sd.as_ref(),
            options,
        );
        let title = format!("calibrated on {}", data.path.display());
        crate::report::plot_comparison(&comparison, &data.force, &title, path, false)?;
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
        println!("NMSE % on {p}: {:.3} / {:.3} / {:.3}", n[0], n[1], n[2]);
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

pub fn train_command(args: &TrainArgs) -> Result<()> {
    use crate::train::{train, TrainOptions};
    use fmu_gp_corrector::TargetForm;
    if args.twin.as_deref() == Some(args.out.as_path()) {
        bail!(
            "--out {} is the input twin; the old twin is kept, so write the new one elsewhere",
            args.out.display()
        );
    }
    if !(args.transient >= 0.0 && args.transient.is_finite()) {
        bail!(
            "--transient must be a non-negative number of seconds, was {}",
            args.transient
        );
    }
    let data = Measurement::read(&args.data)?;
    let twin = Twin::load(args.twin.as_deref())?;
    let target = if args.target == "measured" {
        TargetForm::Measured
    } else {
        TargetForm::Discrepancy
    };
    if args.stride == 0 {
        bail!("--stride must be at least 1");
    }
    let mut options = TrainOptions {
        lags: args.lags,
        target,
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
        selection = crate::train::select_lags(
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
        write_atomically(path, |f| {
            serde_json::to_writer_pretty(&mut *f, &report)?;
            f.write_all(b"\n")?;
            Ok(())
        })?;
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
