//! `twin hybrid`: the simulated real-time hybrid test (the reference paper's section 5) —
//! `threshold` finds the excitation at which the bumper between floors 2 and 3 first closes for
//! each actuator amplitude error (Fig. 14), `run` runs the test at a peak force and reports the
//! contacts, the spectra's harmonics and the contact law learned from the interface (Fig. 15).

use std::path::PathBuf;

use anyhow::{bail, Result};
use serde::Serialize;

use super::{write_json, write_text_atomically};
use crate::report::hybrid_plot;
use crate::twin::Twin;
use crate::workflows::control::design::structure_of;
use crate::workflows::hybrid::experiment::{
    read_excitation, runs, threshold_curve, Coupling, InterfaceNoise, RunSummary, Setup,
    ThresholdPoint,
};
use crate::workflows::hybrid::{unit_peak, Split, Structure};
use numerics::actuator::{ActuatorSpec, Compensation};
use numerics::excitation::ExcitationSpec;

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
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Length of the generated excitation, s.
    #[arg(long, default_value_t = 20.0)]
    pub duration: f64,
    /// Sample rate of the generated excitation, Hz.
    #[arg(long, default_value_t = 512.0)]
    pub sample_rate: f64,
    /// Control steps per excitation sample.
    #[arg(long, default_value_t = 4)]
    pub substeps: u32,
    /// Gap d of the bumper between floors 2 and 3, m.
    #[arg(long, default_value_t = 5e-4, allow_negative_numbers = true)]
    pub gap: f64,
    /// Stiffness of the closed bumper, N/m (9 N/mm).
    #[arg(long, default_value_t = 9000.0, allow_negative_numbers = true)]
    pub contact_stiffness: f64,
    /// The actuator's pure delay, s (a whole number of control steps).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub delay: f64,
    /// The actuator's first-order lag time constant, s (0: none).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub lag: f64,
    /// Compensate the delay (and lag) by polynomial extrapolation of this order (1–4).
    #[arg(long)]
    pub compensate: Option<usize>,
    /// Stop a run when the interface has put more than this × the excitation's energy into
    /// the numerical substructure.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub energy_factor: f64,
    /// Where the structure is cut, by what the specimen (the physical substructure) holds:
    /// specimen-floors-2-3 (the paper's eqs 13–14: the actuator drives floor 2, whose mass is
    /// in the measured force) or specimen-floor-3 (storey 3 moved at floor 2; floor 2's mass
    /// numerical).
    #[arg(long, default_value_t = Split::SpecimenFloors23)]
    pub split: Split,
    /// How the substructures are coupled: auto (one ODE for an actuator without dynamics, as
    /// the paper's simplified simulation; the stepped loop otherwise), monolithic or stepped.
    #[arg(long, value_enum, default_value_t = Coupling::Auto)]
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
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub peak: f64,
    /// Amplitude errors (repeat; default 0 and 0.05).
    #[arg(long = "a-err", allow_negative_numbers = true)]
    pub a_err: Vec<f64>,
    /// Sensor noise sd on the interface displacements, m.
    #[arg(long, default_value_t = 1e-6)]
    pub displacement_noise: f64,
    /// Sensor noise sd on the interface force, N.
    #[arg(long, default_value_t = 1e-3)]
    pub force_noise: f64,
    /// Sensor noise sd on the specimen's floor-2 acceleration, m/s² (used when the specimen
    /// holds floor 2: the force carries its inertia).
    #[arg(long, default_value_t = 1e-3)]
    pub acceleration_noise: f64,
}

/// What the reports share: the substructures' parameters and how the test was set up.
#[derive(Serialize)]
struct Header {
    parameters: std::collections::BTreeMap<String, f64>,
    gap: f64,
    contact_stiffness: f64,
    control_step: f64,
    excitation: String,
    actuator: ActuatorSpec,
    /// What the specimen held: specimen-floors-2-3 (the paper's) or specimen-floor-3.
    split: Split,
    coupling: Coupling,
}

fn setup(c: &Common) -> Result<(Setup, Header)> {
    let twin = Twin::load(c.twin.as_deref())?;
    let s = structure_of(&twin)?;
    let structure = Structure {
        mass: s.mass,
        damping: s.damping,
        stiffness: s.stiffness,
        gap: c.gap,
        contact_stiffness: c.contact_stiffness,
    };
    structure.check()?;
    if c.substeps == 0 {
        bail!("--substeps must be at least 1");
    }
    let (signal, dt, source) = match &c.excitation {
        Some(path) => {
            let (force, dt) = read_excitation(path)?;
            (force, dt, path.display().to_string())
        }
        None => {
            let spec = ExcitationSpec {
                duration: c.duration,
                sample_rate: c.sample_rate,
                seed: c.seed,
                peak_force: 1.0,
                ..ExcitationSpec::default()
            };
            let force = spec.generate()?;
            (
                force,
                1.0 / c.sample_rate,
                format!(
                    "Clough–Penzien filtered noise, {} s at {} Hz, seed {}",
                    c.duration, c.sample_rate, c.seed
                ),
            )
        }
    };
    let actuator = ActuatorSpec {
        amplitude_error: 0.0,
        delay: c.delay,
        lag: c.lag,
        compensation: match c.compensate {
            Some(order) => Compensation::Polynomial { order },
            None => Compensation::None,
        },
    };
    let mut parameters = std::collections::BTreeMap::new();
    for i in 0..3 {
        parameters.insert(format!("m{}", i + 1), s.mass[i]);
        parameters.insert(format!("c{}", i + 1), s.damping[i]);
        parameters.insert(format!("k{}", i + 1), s.stiffness[i]);
    }
    let header = Header {
        parameters,
        gap: c.gap,
        contact_stiffness: c.contact_stiffness,
        control_step: dt / f64::from(c.substeps),
        excitation: source,
        actuator,
        split: c.split,
        coupling: Coupling::Auto,
    };
    let setup = Setup {
        structure,
        split: c.split,
        unit: unit_peak(&signal)?,
        dt,
        substeps: c.substeps,
        actuator,
        energy_factor: c.energy_factor,
        coupling: c.coupling,
    };
    let header = Header {
        coupling: setup.resolved()?,
        ..header
    };
    Ok((setup, header))
}

#[derive(Serialize)]
struct ThresholdReport {
    #[serde(flatten)]
    header: Header,
    thresholds: Vec<ThresholdPoint>,
    failed: Vec<(f64, String)>,
    seconds: f64,
}

#[derive(Serialize)]
struct RunReport {
    #[serde(flatten)]
    header: Header,
    peak: f64,
    noise: InterfaceNoise,
    runs: Vec<RunSummary>,
}

pub fn run(args: &HybridArgs) -> Result<()> {
    match &args.command {
        HybridCommand::Threshold(a) => threshold_command(a),
        HybridCommand::Run(a) => run_command(a),
    }
}

fn check_a_err(a: &[f64]) -> Result<()> {
    if let Some(x) = a.iter().find(|x| !(x.is_finite() && **x > -1.0)) {
        bail!("--a-err must be a finite number above −1, was {x}");
    }
    Ok(())
}

fn threshold_command(a: &ThresholdArgs) -> Result<()> {
    let a_errs = if a.a_err.is_empty() {
        (0..=10).map(|i| -0.1 + 0.02 * f64::from(i)).collect()
    } else {
        a.a_err.clone()
    };
    check_a_err(&a_errs)?;
    let (setup, header) = setup(&a.common)?;
    let curve = threshold_curve(&setup, &a_errs)?;
    println!("split: {}", setup.split.describe());
    let plot = match &a.common.plot {
        Some(path) => Some((
            path,
            hybrid_plot::threshold_svg(&curve).map_err(anyhow::Error::msg)?,
        )),
        None => None,
    };
    let report = ThresholdReport {
        header,
        thresholds: curve.thresholds.clone(),
        failed: curve.failed.clone(),
        seconds: curve.seconds,
    };
    write_json(&a.common.report, &report)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    println!("a_err     threshold (N)   independent (N)   against perfect control");
    for p in &curve.thresholds {
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
    for (x, why) in &curve.failed {
        println!("{x:+.3}    failed: {why}");
    }
    Ok(())
}

fn run_command(a: &RunArgs) -> Result<()> {
    let a_errs = if a.a_err.is_empty() {
        vec![0.0, 0.05]
    } else {
        a.a_err.clone()
    };
    check_a_err(&a_errs)?;
    for (name, x) in [
        ("--displacement-noise", a.displacement_noise),
        ("--force-noise", a.force_noise),
        ("--acceleration-noise", a.acceleration_noise),
    ] {
        if !(x.is_finite() && x >= 0.0) {
            bail!("{name} must be a non-negative number, was {x}");
        }
    }
    let (setup, header) = setup(&a.common)?;
    let noise = InterfaceNoise {
        displacement: a.displacement_noise,
        force: a.force_noise,
        acceleration: a.acceleration_noise,
        seed: a.common.seed,
    };
    let outcomes = runs(&setup, a.peak, &a_errs, noise)?;
    let plot = match &a.common.plot {
        Some(path) => Some((
            path,
            hybrid_plot::runs_svg(&outcomes, setup.dt).map_err(anyhow::Error::msg)?,
        )),
        None => None,
    };
    let report = RunReport {
        header,
        peak: a.peak,
        noise,
        runs: outcomes.iter().map(|o| o.summary.clone()).collect(),
    };
    write_json(&a.common.report, &report)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    println!("split: {}", setup.split.describe());
    for r in &report.runs {
        if let Some(why) = &r.stopped {
            println!("a_err {:+.3}: {why}", r.a_err);
            continue;
        }
        let h = r.spectrum.as_ref();
        println!(
            "a_err {:+.3}: {} contacts, largest y2 − y3 {:.3e} m, fundamental {:.2} Hz, harmonics {}",
            r.a_err,
            r.contacts,
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
            ("measured y2p", &r.identified),
            ("commanded y2n", &r.identified_from_command),
        ] {
            match law {
                Some(l) => println!(
                    "  contact law from the {what}: gap {:.4e} ± {:.1e} m, stiffness {:.4e} ± {:.1e} N/m{}",
                    l.gap,
                    l.gap_sd,
                    l.contact_stiffness,
                    l.contact_stiffness_sd,
                    l.specimen_mass
                        .map(|m| format!(", floor 2's mass {m:.4} kg"))
                        .unwrap_or_default()
                ),
                None => println!("  contact law from the {what}: not identifiable (too few contacts)"),
            }
        }
    }
    Ok(())
}
