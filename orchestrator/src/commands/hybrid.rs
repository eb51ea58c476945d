//! `twin hybrid`: the simulated real-time hybrid test (the reference paper's section 5) —
//! `threshold` finds the excitation at which the bumper between floors 2 and 3 first closes for
//! each actuator amplitude error (Fig. 14), `run` runs the test at a peak force and reports the
//! contacts, the spectra's harmonics and the contact law learned from the interface (Fig. 15).

use std::path::PathBuf;

use anyhow::Result;

use super::{write_json, write_text_atomically};
use crate::report::hybrid_plot;
use crate::twin::Twin;
use crate::workflows::hybrid::experiment::{Coupling, InterfaceNoise};
use crate::workflows::hybrid::options::{check_a_err, HybridOptions, RUN_PEAK};
use crate::workflows::hybrid::Cut;

#[derive(clap::Args)]
pub struct HybridArgs {
    #[command(subcommand)]
    pub command: HybridCommand,
}

#[derive(clap::Subcommand)]
pub enum HybridCommand {
    /// The peak excitation force at which contact starts, for each amplitude error (Fig. 14).
    Threshold(ThresholdArgs),
    /// The test at a peak force: contacts, spectra and harmonics, the identified contact law.
    Run(RunArgs),
}

#[derive(clap::Args)]
pub struct Common {
    /// The twin (.ssp) whose calibrated m, c, k make the substructures (default: the shear
    /// FMU's defaults).
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// A `time,force` CSV as the excitation (default: Clough–Penzien filtered noise under a
    /// build-up / strong / decay envelope).
    #[arg(long)]
    pub excitation: Option<PathBuf>,
    /// Seed of the generated excitation.
    #[arg(long, default_value_t = HybridOptions::default().seed)]
    pub seed: u64,
    /// Length of the generated excitation, s.
    #[arg(long, default_value_t = HybridOptions::default().duration)]
    pub duration: f64,
    /// Sample rate of the generated excitation, Hz.
    #[arg(long, default_value_t = HybridOptions::default().sample_rate)]
    pub sample_rate: f64,
    /// Control steps per excitation sample.
    #[arg(long, default_value_t = HybridOptions::default().substeps)]
    pub substeps: u32,
    /// Gap d of the bumper between floors 2 and 3, m.
    #[arg(long, default_value_t = HybridOptions::default().gap, allow_negative_numbers = true)]
    pub gap: f64,
    /// Stiffness of the closed bumper, N/m (9 N/mm).
    #[arg(long, default_value_t = HybridOptions::default().contact_stiffness, allow_negative_numbers = true)]
    pub contact_stiffness: f64,
    /// The actuator's pure delay, s (a whole number of control steps).
    #[arg(long, default_value_t = HybridOptions::default().delay, allow_negative_numbers = true)]
    pub delay: f64,
    /// The actuator's first-order lag time constant, s (0: none).
    #[arg(long, default_value_t = HybridOptions::default().lag, allow_negative_numbers = true)]
    pub lag: f64,
    /// Compensate the delay (and lag) by polynomial extrapolation of this order (1–4).
    #[arg(long)]
    pub compensate: Option<usize>,
    /// Stop a run when the interface has put more than this × the excitation's energy into
    /// the numerical substructure.
    #[arg(long, default_value_t = HybridOptions::default().energy_factor, allow_negative_numbers = true)]
    pub energy_factor: f64,
    /// The storey count of the building tested without --twin (the paper's floor and storey N
    /// times); with --twin it must be the twin's.
    #[arg(long)]
    pub storeys: Option<usize>,
    /// Where the structure is cut: J, the floor the actuator drives (1 ≤ J < N; the specimen
    /// floors J..N with floor J's mass and the bumper in storey J+1, the paper's eqs 13–14;
    /// default 2), or a name: specimen-floors-J-N (the same), specimen-storeys-A-N (storeys
    /// A..N moved at floor A−1, that floor's mass numerical), specimen-floor-N (A = N). The
    /// paper's rig: specimen-floors-2-3 (the default) or specimen-floor-3.
    #[arg(long)]
    pub split: Option<Cut>,
    /// How the substructures are coupled: auto (one ODE for an actuator without dynamics, as
    /// the paper's simplified simulation; the stepped loop otherwise), monolithic or stepped.
    #[arg(long, value_parser = super::choice::<Coupling>(), default_value_t = HybridOptions::default().coupling)]
    pub coupling: Coupling,
    /// JSON report.
    #[arg(long)]
    pub report: PathBuf,
    /// Plot (.svg).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct ThresholdArgs {
    #[command(flatten)]
    pub common: Common,
    /// Amplitude errors (repeat; default −0.1 to 0.1 by 0.02).
    #[arg(long = "a-err", allow_negative_numbers = true)]
    pub a_err: Vec<f64>,
}

#[derive(clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub common: Common,
    /// Peak excitation force, N.
    #[arg(long, default_value_t = RUN_PEAK, allow_negative_numbers = true)]
    pub peak: f64,
    /// Amplitude errors (repeat; default 0 and 0.05).
    #[arg(long = "a-err", allow_negative_numbers = true)]
    pub a_err: Vec<f64>,
    /// Sensor noise sd on the interface displacements, m.
    #[arg(long, default_value_t = InterfaceNoise::default().displacement)]
    pub displacement_noise: f64,
    /// Sensor noise sd on the interface force, N.
    #[arg(long, default_value_t = InterfaceNoise::default().force)]
    pub force_noise: f64,
    /// Sensor noise sd on the specimen's floor-2 acceleration, m/s² (used when the specimen
    /// holds floor 2: the force carries its inertia).
    #[arg(long, default_value_t = InterfaceNoise::default().acceleration)]
    pub acceleration_noise: f64,
}

impl Common {
    /// The library's options from the flags.
    pub fn options(&self) -> HybridOptions {
        HybridOptions {
            excitation: self.excitation.clone(),
            seed: self.seed,
            duration: self.duration,
            sample_rate: self.sample_rate,
            substeps: self.substeps,
            gap: self.gap,
            contact_stiffness: self.contact_stiffness,
            delay: self.delay,
            lag: self.lag,
            compensate: self.compensate,
            energy_factor: self.energy_factor,
            storeys: self.storeys,
            split: self.split,
            coupling: self.coupling,
        }
    }
}

pub fn run(args: &HybridArgs) -> Result<()> {
    match &args.command {
        HybridCommand::Threshold(a) => threshold_command(a),
        HybridCommand::Run(a) => run_command(a),
    }
}

fn threshold_command(a: &ThresholdArgs) -> Result<()> {
    let a_errs = (!a.a_err.is_empty()).then_some(a.a_err.as_slice());
    check_a_err(a_errs.unwrap_or_default())?;
    let twin = Twin::load(a.common.twin.as_deref())?;
    let (report, curve, setup) =
        crate::workflows::hybrid::options::threshold(&twin, &a.common.options(), a_errs)?;
    println!("split: {}", setup.describe_split());
    let plot = match &a.common.plot {
        Some(path) => Some((
            path,
            hybrid_plot::threshold_svg(&curve).map_err(anyhow::Error::msg)?,
        )),
        None => None,
    };
    write_json(&a.common.report, &report)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    println!("a_err     threshold (N)   independent (N)   against perfect control");
    for p in &report.thresholds {
        println!(
            "{:+.3}    {:>10.4}      {:>10.4}        {}",
            p.a_err,
            p.threshold_peak_force,
            p.independent,
            p.relative_to_perfect
                .map(|r| format!("{:+.1} %", 100.0 * r))
                .unwrap_or_default()
        );
    }
    for (x, why) in &report.failed {
        println!("{x:+.3}    failed: {why}");
    }
    Ok(())
}

fn run_command(a: &RunArgs) -> Result<()> {
    let a_errs = (!a.a_err.is_empty()).then_some(a.a_err.as_slice());
    check_a_err(a_errs.unwrap_or_default())?;
    let noise = InterfaceNoise {
        displacement: a.displacement_noise,
        force: a.force_noise,
        acceleration: a.acceleration_noise,
        seed: a.common.seed,
    };
    noise.validate()?;
    let twin = Twin::load(a.common.twin.as_deref())?;
    let (report, outcomes, setup) =
        crate::workflows::hybrid::options::run(&twin, &a.common.options(), a.peak, a_errs, noise)?;
    let plot = match &a.common.plot {
        Some(path) => Some((
            path,
            hybrid_plot::runs_svg(&outcomes, setup.dt).map_err(anyhow::Error::msg)?,
        )),
        None => None,
    };
    write_json(&a.common.report, &report)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    println!("split: {}", setup.describe_split());
    for r in &report.runs {
        if let Some(why) = &r.stopped {
            println!("a_err {:+.3}: {why}", r.a_err);
            continue;
        }
        let h = r.spectrum.as_ref();
        let j = setup.structure.floor;
        println!(
            "a_err {:+.3}: {} contacts, largest y{j} − y{} {:.3e} m, fundamental {:.2} Hz, harmonics {}",
            r.a_err,
            r.contacts,
            j + 1,
            r.max_relative,
            h.map(|h| h.fundamental_hz).unwrap_or(f64::NAN),
            h.map(|h| {
                h.harmonics
                    .iter()
                    .map(|(n, p)| format!("{n}× ({:.2} Hz, {:.0} dB)", p.frequency, p.relative_db))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| "none".into())
        );
        for (what, law) in [
            (format!("measured y{j}p"), &r.identified),
            (format!("commanded y{j}n"), &r.identified_from_command),
        ] {
            match law {
                Some(l) => println!(
                    "  contact law from the {what}: gap {:.4e} ± {:.1e} m, stiffness {:.4e} ± {:.1e} N/m{}",
                    l.gap,
                    l.gap_sd,
                    l.contact_stiffness,
                    l.contact_stiffness_sd,
                    l.specimen_mass
                        .map(|m| format!(", floor {j}'s mass {m:.4} kg"))
                        .unwrap_or_default()
                ),
                None => println!("  contact law from the {what}: not identifiable (too few contacts)"),
            }
        }
    }
    Ok(())
}
