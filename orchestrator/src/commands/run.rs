//! `twin run`: the command over `cosim::run`.

use std::path::PathBuf;

use anyhow::Result;

use crate::cosim::master::Algorithm;
use crate::cosim::run::RunOptions;

#[derive(clap::Args)]
pub struct RunArgs {
    /// The FMI 2.0 co-simulation FMU (.fmu) or SSP system (.ssp) to run.
    pub model: PathBuf,
    /// Start time (s); default: the model's DefaultExperiment, else 0.
    #[arg(long, allow_negative_numbers = true)]
    pub start: Option<f64>,
    /// Stop time (s); default: the model's DefaultExperiment, else start + 1.
    #[arg(long, allow_negative_numbers = true)]
    pub stop: Option<f64>,
    /// Communication step (s); default: the DefaultExperiment's stepSize (a system: the
    /// smallest of its FMUs'), else a round step giving 500 to 1000 points.
    #[arg(long, allow_negative_numbers = true)]
    pub step: Option<f64>,
    /// Input CSV: a `time` column, then columns named like the model's inputs (a system: its
    /// input connectors or `component.variable`).
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// A start value, NAME=VALUE (repeat); in a system NAME is `component.variable`.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub sets: Vec<String>,
    /// The recorded values as CSV: time, then every output in modelDescription order.
    #[arg(long)]
    pub output: PathBuf,
    /// Also record the local variables.
    #[arg(long)]
    pub output_all: bool,
    /// Hold every input over each step even for FMUs that can interpolate inputs (by default
    /// they get the input's slope over the step; fmpy's simulate_fmu holds them).
    #[arg(long)]
    pub hold_inputs: bool,
    /// How a system's connections are resolved at each communication point: gauss-seidel
    /// (each component sees what the ones before it produced at this point, until nothing
    /// changes) or jacobi (every component reads the outputs as the last step left them, as
    /// fmpy's simulate_ssp does).
    #[arg(long, value_parser = super::choice::<Algorithm>(), default_value_t = RunOptions::default().algorithm)]
    pub algorithm: Algorithm,
    /// Plot (.svg) of every recorded numeric column against time.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(args: &RunArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        if plot.extension().and_then(|e| e.to_str()) != Some("svg") {
            anyhow::bail!("--plot {}: only .svg is supported", plot.display());
        }
    }
    let options = RunOptions {
        start: args.start,
        stop: args.stop,
        step: args.step,
        input: args.input.clone(),
        sets: args.sets.clone(),
        output_all: args.output_all,
        hold_inputs: args.hold_inputs,
        algorithm: args.algorithm,
    };
    let result = crate::cosim::run::run(&args.model, &options, super::progress_bar())?;
    super::write_atomically(&args.output, |f| Ok(result.write_csv(f)?))?;
    println!(
        "{}: {} points from {} to {} s (step {} s), {} columns → {}",
        args.model.display(),
        result.time.len(),
        result.start,
        result.time.last().copied().unwrap_or(result.start),
        result.step,
        result.columns.len(),
        args.output.display()
    );
    if let Some((component, at)) = &result.terminated {
        println!("{component} ended the simulation itself at t = {at} s");
    }
    if let Some(plot) = &args.plot {
        let title = args
            .model
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let svg = crate::report::run_plot::plot_run(&result, &title)
            .map_err(|m| anyhow::anyhow!("cannot draw {}: {m}", plot.display()))?;
        super::write_text_atomically(plot, &svg)?;
        println!("wrote {}", plot.display());
    }
    Ok(())
}
