//! `twin diagnose`: diagnose a failing twin (none, recalibrate, add physics or update the
//! data-based model), with the evidence; a summary, a JSON report and a plot.

use std::path::PathBuf;

use anyhow::{bail, Result};

use super::{write_json, write_text_atomically};
use crate::twin::Twin;
use crate::workflows::diagnose::{
    diagnose, diagnose_ambient, parse_candidates, AmbientDiagnosis, DiagnoseOptions, Diagnosis,
    Progress,
};

#[derive(clap::Args)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// The twin (.ssp) to diagnose, made by `twin calibrate` (its noise variances set the
    /// noise level).
    #[arg(long)]
    pub twin: PathBuf,
    /// Measurement CSV: time,force,acc1,acc2,acc3.
    #[arg(long)]
    pub data: PathBuf,
    /// JSON report (the contract: nmse_before, action, effect, nmse_after, candidates).
    #[arg(long)]
    pub report: PathBuf,
    /// Plot (.svg): before/after per floor, failing windows, the winning effect's evidence.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Candidates to try, KIND@LOCATION[:SIDE] (default: the whole library).
    #[arg(long, num_args = 1..)]
    pub effects: Vec<String>,
    /// Seconds at the start left out of every error measure and fit.
    #[arg(long, default_value_t = DiagnoseOptions::default().transient, value_parser = super::transient_seconds)]
    pub transient: f64,
    /// Length (s) of the alternating fitted / held-out blocks.
    #[arg(long, default_value_t = DiagnoseOptions::default().block)]
    pub block: f64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Fit the alternatives even when the error is within the noise.
    #[arg(long)]
    pub always_fit: bool,
    /// Practical significance, NMSE %: a worst-floor NMSE below it is `none` whatever the
    /// statistics say. Default: 2 × the twin's worst validation NMSE (`twin calibrate
    /// --validate`), else 0.5 %.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// The structure changed at this time (s of the record): the twin holds before it, and
    /// what came after is diagnosed on its own, every fit starting from the state the twin
    /// reached there (no transient left out after it)
    #[arg(long, value_name = "SECONDS")]
    pub changed_at: Option<f64>,
}

pub(super) fn options(transient: f64, threads: Option<usize>) -> Result<DiagnoseOptions> {
    let mut o = DiagnoseOptions {
        transient,
        ..DiagnoseOptions::default()
    };
    if let Some(t) = threads {
        if t == 0 {
            bail!("--threads must be at least 1");
        }
        o.threads = t;
    }
    Ok(o)
}

impl DiagnoseArgs {
    /// The library's options from the flags.
    pub fn options(&self) -> Result<DiagnoseOptions> {
        let mut o = DiagnoseOptions {
            transient: self.transient,
            block: self.block,
            always_fit: self.always_fit,
            tolerance: self.tolerance,
            changed_at: self.changed_at,
            ..DiagnoseOptions::default()
        };
        if let Some(t) = self.threads {
            o.threads = t;
        }
        o.validate()?;
        if !self.effects.is_empty() {
            o.candidates = Some(parse_candidates(&self.effects)?);
        }
        Ok(o)
    }
}

pub fn run(args: &DiagnoseArgs) -> Result<()> {
    let mut o = args.options()?;
    let twin = Twin::load(Some(&args.twin))?;
    let data = match args.columns.read_or_ambient(&args.data)? {
        Ok(data) => data,
        Err(ambient) => return run_ambient(args, &twin, &ambient),
    };
    crate::twin::guard::check_record(&twin, &data)?;
    // A spinner with the stage on a terminal (indicatif draws nothing when stderr is not one).
    let spinner = indicatif::ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    spinner.set_message("comparing the twin with the record");
    let shown = spinner.clone();
    o.progress = Some(Progress(std::sync::Arc::new(move |what: &str| {
        shown.set_message(what.to_string())
    })));
    let d = diagnose(&twin, &data, &o);
    spinner.finish_and_clear();
    let d = d?;
    // Draw before writing anything: a failed plot leaves no half-written output.
    let plot = match &args.plot {
        Some(path) => Some((path, crate::report::diagnose_plot::draw_diagnosis(&d)?)),
        None => None,
    };
    write_json(&args.report, &d)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    print!("{}", summary(&d));
    Ok(())
}

/// `twin diagnose` on a record without the excitation: by its modes alone.
fn run_ambient(
    args: &DiagnoseArgs,
    twin: &Twin,
    record: &crate::record::AmbientRecord,
) -> Result<()> {
    if !args.effects.is_empty() || args.always_fit {
        bail!(
            "{}: no excitation column, so the twin cannot be run on it and --effects / \
             --always-fit have nothing to fit; the diagnosis of an ambient record compares modes",
            record.path.display()
        );
    }
    let spinner = indicatif::ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    spinner.set_message("identifying the record's modes (output-only)");
    let d = diagnose_ambient(twin, record, crate::workflows::modal::ModalBand::default());
    spinner.finish_and_clear();
    let d = d?;
    let plot = match &args.plot {
        Some(path) => Some((
            path,
            crate::report::mode_plot::draw_ambient_diagnosis(&d)
                .map_err(|message| anyhow::anyhow!("cannot draw {}: {message}", path.display()))?,
        )),
        None => None,
    };
    write_json(&args.report, &d)?;
    if let Some((path, svg)) = plot {
        write_text_atomically(path, &svg)?;
    }
    print!("{}", ambient_summary(&d));
    Ok(())
}

/// What `twin diagnose` prints for an ambient record.
pub fn ambient_summary(d: &AmbientDiagnosis) -> String {
    let mut s = String::new();
    s += &format!("record        {} (ambient: no excitation)\n", d.record);
    s += &format!("channels      {}\n", d.channels.join(" / "));
    s += &format!(
        "modes         {} (band {} sd, at least {} %)\n",
        d.modes.method, d.modes.band.sigmas, d.modes.band.tolerance
    );
    for m in &d.modes.modes {
        s += &format!(
            "  mode {}  twin {:>8.4} Hz  record {:>8.4} Hz  {:+6.2} %  MAC {:.3}{}\n",
            m.pair.twin_mode,
            m.pair.twin_frequency,
            m.pair.observed_frequency,
            m.pair.frequency_shift_percent,
            m.pair.mac,
            if m.outside { "  moved" } else { "" }
        );
    }
    if !d.explanations.is_empty() {
        s += &format!(
            "explanations  (one parameter each, best first; misfit {:.1} unchanged)\n",
            d.misfit_unchanged
        );
        for e in d.explanations.iter().take(4) {
            s += &format!(
                "  {:<4} {:+7.1} %  misfit {:.1}\n",
                e.parameter, e.change_percent, e.misfit
            );
        }
    }
    s += &format!("action        {}\n", d.action.name());
    s += &format!("reason        {}\n", d.reason);
    s
}

/// The channels' quantities and what each saw of the verdict, when the record has other
/// sensors than accelerometers (an accelerometer-only record prints nothing more).
fn sensing_lines(d: &Diagnosis) -> String {
    if d.sensing.iter().all(|c| c.quantity == "acceleration") {
        return String::new();
    }
    let mut s = String::from("sensors       ");
    let described: Vec<String> = d
        .sensing
        .iter()
        .map(|c| {
            let seen = match c.visibility {
                Some(v) => format!(", the verdict's change {v:.1}× its noise sd"),
                None => String::new(),
            };
            format!(
                "{} {} (localisation: {}{seen})",
                c.channel, c.quantity, c.localisation
            )
        })
        .collect();
    s += &described.join("; ");
    s += "\n              velocity and displacement sensors weigh a structure's low modes more \
          and its high ones less than accelerometers: an effect of high frequency (a contact's \
          impacts, friction's stick-slip) shows less in them, a slow one more; the ratios above \
          are what each sensor saw of this answer\n";
    s
}

/// What `twin diagnose` prints: the error, the fits, the answer.
pub fn summary(d: &Diagnosis) -> String {
    the_error(d) + &the_fits(d) + &the_answer(d)
}

/// Per-channel NMSEs, `a / b / c %`.
pub(super) fn pct(x: &[f64]) -> String {
    let values: Vec<String> = x.iter().map(|v| format!("{v:.3}")).collect();
    format!("{} %", values.join(" / "))
}

/// The record, the twin's error on it and whether it is significant.
fn the_error(d: &Diagnosis) -> String {
    let mut s = String::new();
    s += &format!("record        {}\n", d.record);
    s += &format!("channels      {}\n", d.channels.join(" / "));
    if let Some(at) = d.changed_at {
        s += &format!(
            "after change  the samples from {at:.3} s on, every fit from the state the twin \
             reached there\n"
        );
    }
    s += &format!("NMSE before   {}\n", pct(&d.nmse_before));
    s += &format!("noise level   {}\n", pct(&d.noise_nmse));
    s += &format!(
        "band explains {} (noise + parameter uncertainty {}); {}statistically significant\n",
        pct(&d.explained_nmse),
        pct(&d.band_nmse),
        if d.statistically_significant {
            ""
        } else {
            "not "
        }
    );
    s += &format!(
        "tolerance     {:.3} % ({}); {}practically significant\n",
        d.tolerance,
        d.tolerance_source,
        if d.practically_significant {
            ""
        } else {
            "not "
        }
    );
    if !d.failing_windows.is_empty() {
        let w: Vec<String> = d
            .failing_windows
            .iter()
            .map(|w| format!("{:.2}–{:.2} s", w.start, w.end))
            .collect();
        s += &format!("failing       {}\n", w.join(", "));
    }
    s
}

/// The recalibration, the candidates and the forward selection's rounds.
fn the_fits(d: &Diagnosis) -> String {
    let mut s = String::new();
    if let Some(r) = &d.recalibration {
        s += &format!(
            "recalibration {} (held out {}), evidence {:.1}\n",
            pct(&r.nmse_after),
            pct(&r.nmse_held_out),
            r.evidence
        );
    }
    if !d.candidates.is_empty() {
        s += "candidates (best evidence first; * passes the gates)\n";
        for c in &d.candidates {
            s += &format!(
                "  {} {:<22} evidence {:>12.1}  held-out NMSE {}\n",
                if c.passes { '*' } else { ' ' },
                c.name.label,
                c.evidence,
                pct(&c.nmse_held_out)
            );
        }
    }
    if let (Some(head), false) = (d.race_head, d.raced_out.is_empty()) {
        let out: Vec<String> = d
            .raced_out
            .iter()
            .map(|(label, w)| format!("{label} {w:.3} %"))
            .collect();
        s += &format!(
            "raced out     on the first {head} samples (worst held-out NMSE): {}\n",
            out.join(", ")
        );
    }
    for (label, error) in &d.failed_candidates {
        s += &format!("  failed {label}: {error}\n");
    }
    for step in &d.selection {
        s += &format!(
            "round {}       + {} (worst held-out NMSE {:.3} % → alone {:.3} %, jointly {:.3} %{})\n",
            step.round,
            step.added,
            step.worst_before,
            step.nmse_held_out_effect
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max),
            step.nmse_held_out_joint
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max),
            match (step.joint_kept, step.settled) {
                (false, _) => ", not kept",
                (true, true) => "; no later round: the joint refit explains the record",
                (true, false) => "",
            }
        );
    }
    s
}

/// The action, what it adds or moves, the NMSE after, the modes and why.
fn the_answer(d: &Diagnosis) -> String {
    let mut s = String::new();
    s += &format!("action        {}\n", d.action.name());
    for e in &d.effects {
        let params: Vec<String> = e
            .parameters
            .iter()
            .filter(|(k, _)| k.as_str() != "side")
            .map(|(k, v)| {
                format!(
                    "{k} = {v:.4e} ± {:.2e}",
                    e.sd.get(k).copied().unwrap_or(0.0)
                )
            })
            .collect();
        s += &format!("effect        {}: {}\n", e.name.label, params.join(", "));
    }
    for p in &d.physics_moved {
        s += &format!(
            "physics       {} {:.4} → {:.4} ({:+.1} %, {:+.1} sd)\n",
            p.name,
            p.before,
            p.after,
            100.0 * p.relative_change,
            p.change_in_sd
        );
    }
    if let Some(x) = &d.sensor {
        let (unit, rate) = match d.sensing.iter().find(|c| c.channel == x.channel) {
            Some(c) if c.quantity == "velocity" => ("m/s", "m/s²"),
            Some(c) if c.quantity == "displacement" => ("m", "m/s"),
            _ => ("m/s²", "m/s³"),
        };
        s += &format!(
            "sensor        {} (floor {}): gain {:.4} ± {:.1e}, offset {:.4e} ± {:.1e} {unit}, \
             drift {:.4e} ± {:.1e} {rate} (a sensor fault is not physics: fix or recalibrate it)\n",
            x.channel, x.floor, x.gain, x.sd.gain, x.offset, x.sd.offset, x.drift, x.sd.drift
        );
    }
    s += &sensing_lines(d);
    s += &format!("NMSE after    {}\n", pct(&d.nmse_after));
    match &d.modes {
        Some(m) => {
            let line: Vec<String> = m
                .modes
                .iter()
                .map(|x| {
                    format!(
                        "{}: {:.3}→{:.3} Hz {:+.2} %{}",
                        x.pair.twin_mode,
                        x.pair.twin_frequency,
                        x.pair.observed_frequency,
                        x.pair.frequency_shift_percent,
                        if x.outside { " OUTSIDE" } else { "" }
                    )
                })
                .collect();
            s += &format!("modes ({})  {}\n", m.method, line.join("; "));
        }
        None => {
            if let Some(e) = &d.modes_error {
                s += &format!("modes         not identified: {e}\n");
            }
        }
    }
    s += &format!("why           {}\n", d.reason);
    s += &format!("time          {:.1} s\n", d.seconds);
    s
}
