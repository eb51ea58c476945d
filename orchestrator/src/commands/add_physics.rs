//! `twin add-physics`: switch an effect of the shear FMU's library on, estimate its parameters
//! jointly with the structure's over the new record and the records the twin was calibrated and
//! validated on, and write the new twin.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::diagnose::{options, pct};
use super::write_json;
use crate::twin::data::Measurement;
use crate::twin::{RecordRef, RecordRole, Twin};
use crate::workflows::diagnose::{
    add_hybrid_contact, add_physics, effects_from_report, parse_additions, with_record,
    AddPhysicsReport, DiagnoseOptions, Progress, RecordNmse,
};

#[derive(clap::Args)]
pub struct AddPhysicsArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
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
    /// measurements (its run with the smallest |a_err|): contact between floors 2 and 3, held
    /// as identified, the structure refitted with it over the records.
    #[arg(long, conflicts_with = "diagnosis")]
    pub hybrid: Option<PathBuf>,
    /// Take the effects from a `twin diagnose` report instead (all of them, in order).
    #[arg(long)]
    pub diagnosis: Option<PathBuf>,
    /// The new record the effects are estimated on (with --hybrid: one more record to refit
    /// over).
    #[arg(long, required_unless_present = "hybrid")]
    pub data: Option<PathBuf>,
    /// The records to refit over beside --data; default: those the twin was calibrated and
    /// validated on (stored in it by `twin calibrate`).
    #[arg(long, num_args = 1..)]
    pub records: Vec<PathBuf>,
    /// The new twin (.ssp).
    #[arg(long)]
    pub out: PathBuf,
    /// Accepted for compatibility and ignored: the physics is always refitted with the effects,
    /// over every record.
    #[arg(long, hide = true)]
    pub refine: bool,
    /// JSON report.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[arg(long, default_value_t = crate::evaluation::compare::DEFAULT_TRANSIENT, value_parser = super::transient_seconds)]
    pub transient: f64,
    #[arg(long)]
    pub threads: Option<usize>,
}

/// The records to refit over: `--records`, else the twin's own (checked against their hashes).
fn other_records(
    args: &AddPhysicsArgs,
    twin: &Twin,
    text: &mut String,
) -> Result<Vec<Measurement>> {
    use std::fmt::Write;
    if !args.records.is_empty() {
        return Ok(args
            .records
            .iter()
            .map(|p| args.columns.read_any(p))
            .collect::<Result<Vec<_>, _>>()?);
    }
    if twin.records.is_empty() {
        writeln!(
            text,
            "the twin remembers no records (calibrated before they were stored?): refitting on \
             --data alone; give --records D1.csv D2.csv to refit over them too"
        )?;
    }
    Ok(twin.load_records()?)
}

/// The new twin's records: every record it was fitted on.
fn fitted_records(paths: &[PathBuf]) -> Result<Vec<RecordRef>> {
    let mut out: Vec<RecordRef> = Vec::new();
    for p in paths {
        let r = RecordRef::of(p, RecordRole::Calibration)?;
        if !out.iter().any(|o| o.sha256 == r.sha256) {
            out.push(r);
        }
    }
    Ok(out)
}

fn print_records(text: &mut String, records: &[RecordNmse]) {
    use std::fmt::Write;
    let _ = writeln!(text, "NMSE per record and channel, before → after:");
    for r in records {
        let _ = writeln!(
            text,
            "  {:<28} {} → {}",
            r.record,
            pct(&r.nmse_before),
            pct(&r.nmse_after)
        );
    }
}

pub fn run(args: &AddPhysicsArgs) -> Result<()> {
    if args.refine {
        println!("--refine is no longer needed: the physics is always refitted with the effects");
    }
    let mut o = options(args.transient, args.threads)?;
    // A spinner with the stage on a terminal (indicatif draws nothing when stderr is not one).
    let spinner = indicatif::ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    spinner.set_message("reading the twin and its records");
    let shown = spinner.clone();
    o.progress = Some(Progress(std::sync::Arc::new(move |what: &str| {
        shown.set_message(what.to_string())
    })));
    let result = fit_and_write(args, &o);
    spinner.finish_and_clear();
    let printout = result?;
    print!("{printout}");
    Ok(())
}

/// Everything but the spinner; what to print, once the spinner is gone.
fn fit_and_write(args: &AddPhysicsArgs, o: &DiagnoseOptions) -> Result<String> {
    let mut text = String::new();
    let inputs = Inputs::read(args, &mut text)?;
    match &args.hybrid {
        Some(path) => hybrid_and_write(args, path, &inputs, o, &mut text)?,
        None => effects_and_write(args, &inputs, o, &mut text)?,
    }
    Ok(text)
}

/// What the refit starts from: the twin, the records it remembers and the new one (each
/// checked against it), and their paths in the refit's order (the twin's, then the new one).
struct Inputs {
    twin: Twin,
    others: Vec<Measurement>,
    data: Option<Measurement>,
    paths: Vec<PathBuf>,
}

impl Inputs {
    fn read(args: &AddPhysicsArgs, text: &mut String) -> Result<Inputs> {
        let twin = Twin::load(Some(&args.twin))?;
        let others = other_records(args, &twin, text)?;
        let data = args
            .data
            .as_deref()
            .map(|p| args.columns.read_any(p))
            .transpose()?;
        for record in others.iter().chain(&data) {
            crate::twin::guard::check_record(&twin, record)?;
        }
        let mut paths: Vec<PathBuf> = others.iter().map(|m| m.path.clone()).collect();
        paths.extend(data.iter().map(|d| d.path.clone()));
        Ok(Inputs {
            twin,
            others,
            data,
            paths,
        })
    }
}

/// `--hybrid`: the contact the hybrid test measured, held, and the structure refitted over
/// every record; the twin and the report written, the printout in `text`.
fn hybrid_and_write(
    args: &AddPhysicsArgs,
    path: &std::path::Path,
    inputs: &Inputs,
    o: &DiagnoseOptions,
    text: &mut String,
) -> Result<()> {
    use std::fmt::Write;
    let all: Vec<&Measurement> = match &inputs.data {
        Some(d) => with_record(d, &inputs.others).0,
        None => inputs.others.iter().collect(),
    };
    if all.is_empty() {
        bail!(
            "no record to refit the structure over: the twin remembers none; give --data \
             D.csv or --records D1.csv ..."
        );
    }
    let (mut new_twin, report) = add_hybrid_contact(&inputs.twin, path, &all, o)?;
    new_twin.records = fitted_records(&inputs.paths)?;
    new_twin.write(&args.out)?;
    if let Some(out) = &args.report {
        write_json(out, &report)?;
    }
    let law = &report.law;
    let _ = writeln!(
        text,
        "effect        contact@2-3:negative from the hybrid test (a_err {:+.3}), held: gap \
         {:.4e} ± {:.1e} m, stiffness {:.4e} ± {:.1e} N/m",
        report.a_err, law.gap, law.gap_sd, law.contact_stiffness, law.contact_stiffness_sd
    );
    let _ = writeln!(
        text,
        "structure refitted over {} records:",
        report.records.len()
    );
    for p in &report.refined_physics {
        let _ = writeln!(text, "  {:<14} {:.4} ± {:.2e}", p.name, p.value, p.sd);
    }
    print_records(text, &report.records);
    print_tolerance(text, &new_twin);
    let _ = writeln!(text, "wrote {}", args.out.display());
    Ok(())
}

/// `--effect` or `--diagnosis`: the effects estimated on the record and the structure refitted
/// with them; the twin and the report written, the printout in `text`.
fn effects_and_write(
    args: &AddPhysicsArgs,
    inputs: &Inputs,
    o: &DiagnoseOptions,
    text: &mut String,
) -> Result<()> {
    use std::fmt::Write;
    let candidates = match (args.effect.is_empty(), &args.diagnosis) {
        (false, _) => parse_additions(&args.effect)?,
        (true, Some(path)) => effects_from_report(path)?.0,
        (true, None) => bail!("give --effect KIND@LOCATION or --diagnosis R.json"),
    };
    let Some(data) = &inputs.data else {
        bail!("give --data D.csv: the record the effects are estimated on");
    };
    let (mut new_twin, report) = add_physics(&inputs.twin, data, &inputs.others, &candidates, o)?;
    new_twin.records = fitted_records(&inputs.paths)?;
    new_twin.write(&args.out)?;
    if let Some(path) = &args.report {
        write_json(path, &report)?;
    }
    print_effects(text, &report);
    let _ = writeln!(
        text,
        "structure refitted with the effects over {} records:",
        report.records.len()
    );
    for p in &report.refined_physics {
        let _ = writeln!(text, "  {:<14} {:.4} ± {:.2e}", p.name, p.value, p.sd);
    }
    let _ = writeln!(
        text,
        "NMSE on {} with the effects alone (physics held): {}",
        report.record,
        pct(&report.nmse_effects_alone)
    );
    print_records(text, &report.records);
    print_tolerance(text, &new_twin);
    writeln!(text, "wrote {}", args.out.display())?;
    Ok(())
}

/// Each effect added: its terms with their sd, or its parameters with theirs.
fn print_effects(text: &mut String, report: &AddPhysicsReport) {
    use std::fmt::Write;
    for effect in &report.effects {
        let _ = writeln!(text, "effect        {}", effect.name.label);
        for t in &effect.terms {
            let _ = writeln!(
                text,
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
                let _ = writeln!(
                    text,
                    "  {k:<14} {v:.4e} ± {:.2e}",
                    effect.sd.get(k).copied().unwrap_or(0.0)
                );
            }
        }
    }
}

fn print_tolerance(text: &mut String, twin: &Twin) {
    use std::fmt::Write;
    let t = crate::twin::run::Tolerance::resolve(twin, None);
    let _ = writeln!(
        text,
        "tolerance of compare and diagnose: {:.3} % NMSE ({})",
        t.value, t.source
    );
}
