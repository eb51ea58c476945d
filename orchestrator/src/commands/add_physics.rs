//! `twin add-physics`: switch an effect of the shear FMU's library on, estimate its parameters
//! and write the new twin.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::diagnose::options;
use super::write_json;
use crate::twin::data::Measurement;
use crate::twin::Twin;
use crate::workflows::diagnose::{add_physics, effects_from_report, Addition, Candidate};

#[derive(clap::Args)]
pub struct AddPhysicsArgs {
    /// The twin (.ssp) to extend.
    #[arg(long)]
    pub twin: PathBuf,
    /// The effect, KIND@LOCATION[:SIDE]: contact@2-3[:both|positive|negative], cubic@2,
    /// friction@1; repeat it to add several at once.
    #[arg(
        long,
        conflicts_with_all = ["diagnosis", "hybrid"],
        required_unless_present_any = ["diagnosis", "hybrid"]
    )]
    pub effect: Vec<String>,
    /// Take the contact law a `twin hybrid run` report identified from its interface
    /// measurements (its run with the smallest |a_err|): contact between floors 2 and 3, set
    /// as identified, nothing refitted.
    #[arg(long, conflicts_with_all = ["diagnosis", "refine"])]
    pub hybrid: Option<PathBuf>,
    /// Take the effects from a `twin diagnose` report instead (all of them, in order; with the
    /// physics refined too when the diagnosis took a recalibration as one of its moves).
    #[arg(long)]
    pub diagnosis: Option<PathBuf>,
    /// The record its parameters are estimated on.
    #[arg(long, required_unless_present = "hybrid")]
    pub data: Option<PathBuf>,
    /// The new twin (.ssp).
    #[arg(long)]
    pub out: PathBuf,
    /// Refine the nine physics parameters jointly with the effect's.
    #[arg(long)]
    pub refine: bool,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[arg(long, default_value_t = crate::evaluation::compare::DEFAULT_TRANSIENT, value_parser = super::transient_seconds)]
    pub transient: f64,
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn run(args: &AddPhysicsArgs) -> Result<()> {
    if let Some(path) = &args.hybrid {
        let twin = Twin::load(Some(&args.twin))?;
        let (new_twin, law, a_err) =
            crate::workflows::hybrid::experiment::add_identified_contact(&twin, path)?;
        new_twin.write(&args.out)?;
        if let Some(report) = &args.report {
            write_json(report, &law)?;
        }
        println!(
            "effect        contact@2-3:negative from the hybrid test (a_err {a_err:+.3}): gap \
             {:.4e} ± {:.1e} m, stiffness {:.4e} ± {:.1e} N/m",
            law.gap, law.gap_sd, law.contact_stiffness, law.contact_stiffness_sd
        );
        println!("wrote {}", args.out.display());
        return Ok(());
    }
    let o = options(args.transient, args.threads)?;
    let (candidates, refine) = match (args.effect.is_empty(), &args.diagnosis) {
        (false, _) => (
            args.effect
                .iter()
                .map(|e| {
                    Candidate::parse(e)
                        .map(Addition::Library)
                        .map_err(anyhow::Error::msg)
                })
                .collect::<Result<Vec<_>>>()?,
            args.refine,
        ),
        (true, Some(path)) => {
            let (candidates, moved) = effects_from_report(path)?;
            if moved && !args.refine {
                println!(
                    "the diagnosis recalibrated the physics with the effects: refining it too"
                );
            }
            (candidates, args.refine || moved)
        }
        (true, None) => bail!("give --effect KIND@LOCATION or --diagnosis R.json"),
    };
    let Some(data) = &args.data else {
        bail!("give --data D.csv: the record the effects are estimated on");
    };
    let data = Measurement::read(data)?;
    let twin = Twin::load(Some(&args.twin))?;
    let (new_twin, report) = add_physics(&twin, &data, &candidates, refine, &o)?;
    new_twin.write(&args.out)?;
    if let Some(path) = &args.report {
        write_json(path, &report)?;
    }
    let pct = |x: &[f64; 3]| format!("{:.3} / {:.3} / {:.3} %", x[0], x[1], x[2]);
    for effect in &report.effects {
        println!("effect        {}", effect.name.label);
        for t in &effect.terms {
            println!(
                "  {:<14} {:.4e} ± {:.2e}{}",
                t.function,
                t.coefficient,
                t.sd,
                t.scale
                    .map(|s| format!("  (s = {s:.3e})"))
                    .unwrap_or_default()
            );
        }
        for (k, v) in &effect.parameters {
            if k != "side" && effect.terms.is_empty() {
                println!(
                    "  {k:<14} {v:.4e} ± {:.2e}",
                    effect.sd.get(k).copied().unwrap_or(0.0)
                );
            }
        }
    }
    for p in &report.refined_physics {
        println!("  {:<14} {:.4} ± {:.2e}", p.name, p.value, p.sd);
    }
    println!("NMSE before   {}", pct(&report.nmse_before));
    println!("NMSE after    {}", pct(&report.nmse_after));
    println!("wrote {}", args.out.display());
    Ok(())
}
