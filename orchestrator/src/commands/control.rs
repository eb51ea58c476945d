//! `twin control`: LQR designs on the twin, the structure driven by a record's force passive and
//! under each design, the attenuation, control effort and contact initiations; `--retune` and
//! `--schedule` let the twin inform the control.

use std::path::PathBuf;

use anyhow::{Context, Result};

use super::{progress_bar, write_json, write_text_atomically};
use crate::report::control_plot::plot_control;
use crate::twin::Twin;
use crate::workflows::control::closed_loop::Gap;
use crate::workflows::control::{
    run_control, sensor_noise, twin_for_control, ControlOptions, EstimatorChoice, Retune,
    ScheduleOptions, StateUnit, VarianceTrigger,
};
use crate::workflows::options::check_svg;

#[derive(clap::Args)]
pub struct ControlArgs {
    #[command(flatten)]
    pub columns: super::ColumnsArg,
    /// The twin (.ssp) whose structure is controlled (its calibrated m, c, k; its effects).
    #[arg(long)]
    pub twin: Option<PathBuf>,
    /// The record whose force drives the structure.
    #[arg(long)]
    pub data: PathBuf,
    /// State weight q of Q = q·diag(0, I); repeat for several designs.
    #[arg(long = "q", required = true, num_args = 1.., allow_negative_numbers = true)]
    pub q: Vec<f64>,
    /// Control weight R (N⁻², > 0).
    #[arg(long = "r", default_value_t = ControlOptions::default().r)]
    pub r: f64,
    /// Unit of the designed state: q and R mean something only with it.
    #[arg(long, value_parser = super::choice::<StateUnit>(), default_value_t = ControlOptions::default().unit)]
    pub state_unit: StateUnit,
    /// How the controller estimates the state from the measured accelerations.
    #[arg(long, value_parser = super::choice::<EstimatorChoice>(), default_value_t = ControlOptions::default().estimator)]
    pub estimator: EstimatorChoice,
    /// Corner (Hz) of the integrating estimator's drift removal.
    #[arg(long, default_value_t = ControlOptions::default().highpass_hz)]
    pub highpass: f64,
    /// Controller samples per record sample (default: from the fastest closed-loop pole).
    #[arg(long)]
    pub substeps: Option<usize>,
    /// Accelerometer noise sd (m/s², every floor) the controller reads; default: the twin's
    /// calibrated noise; 0 for none.
    #[arg(long)]
    pub sensor_noise: Option<f64>,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = ControlOptions::default().seed)]
    pub seed: u64,
    /// A gap to watch for contact besides the twin's own: `2-3:5e-4[:negative|positive|both]`
    /// (storey by its floors, gap in m).
    #[arg(long)]
    pub gap: Vec<String>,
    /// Find the smallest q (on a grid from the smallest --q up to 100×) keeping the contact
    /// initiations at or below --target-contacts.
    #[arg(long)]
    pub retune: bool,
    #[arg(long, default_value_t = Retune::default().target)]
    pub target_contacts: usize,
    /// Largest peak control force (N) a retuned design may use.
    #[arg(long)]
    pub max_force: Option<f64>,
    /// Gain scheduling: the lowest q normally, the highest (or the retuned) q while the
    /// estimated drift comes within --margin of the gap.
    #[arg(long)]
    pub schedule: bool,
    /// Fraction of the gap: the high gain comes on when the projected drift passes
    /// (1 − margin)·gap.
    #[arg(long, default_value_t = ScheduleOptions::default().margin)]
    pub margin: f64,
    /// Seconds ahead the drift is projected (drift + lookahead · drift rate).
    #[arg(long, default_value_t = ScheduleOptions::default().lookahead)]
    pub lookahead: f64,
    /// Seconds the high gain stays on after the last trigger (against chattering).
    #[arg(long, default_value_t = ScheduleOptions::default().dwell)]
    pub dwell: f64,
    /// The schedule also switches up when the twin's GP corrector's latent variance exceeds
    /// this, (m/s²)², every floor: `auto` (default: when the twin has a corrector, above its
    /// calibrated noise variance), `off`, or a number.
    #[arg(long, default_value = "auto")]
    pub variance_threshold: String,
    /// Also run the first design with the exact state and with each estimator, to show what
    /// the estimation costs in attenuation.
    #[arg(long)]
    pub estimator_costs: bool,
    /// The floor the control force acts on (1-based; a floor the twin's structure has).
    #[arg(long, default_value_t = ControlOptions::default().actuator_floor)]
    pub actuator_floor: usize,
    /// JSON report.
    #[arg(long)]
    pub report: PathBuf,
    /// Plot (.svg): FRFs per floor and time histories with the contact initiations.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also write the controlled system as an SSP archive: the twin's shear FMU and the
    /// controller as the fmu_lqr FMU, for any SSP tool (`twin run`, fmpy's simulate_ssp).
    #[arg(long)]
    pub ssp: Option<PathBuf>,
    /// The design (its q) the SSP holds; default: the first stable one.
    #[arg(long, requires = "ssp")]
    pub ssp_q: Option<f64>,
}

impl ControlArgs {
    /// The library's options from the flags, checked.
    pub fn options(&self) -> Result<ControlOptions> {
        // q, r and --max-force first (the latter even without --retune), then the texts.
        let mut options = ControlOptions {
            qs: self.q.clone(),
            r: self.r,
            unit: self.state_unit,
            estimator: self.estimator,
            highpass_hz: self.highpass,
            substeps: self.substeps,
            seed: self.seed,
            retune: Some(Retune {
                target: self.target_contacts,
                max_force: self.max_force,
            }),
            estimator_costs: self.estimator_costs,
            actuator_floor: self.actuator_floor,
            ..ControlOptions::default()
        };
        options.validate()?;
        options.retune = options.retune.filter(|_| self.retune);
        options.sensor_noise = sensor_noise(self.sensor_noise)?.0;
        options.gaps = self
            .gap
            .iter()
            .map(|g| Gap::parse(g))
            .collect::<Result<Vec<_>, _>>()?;
        let variance = VarianceTrigger::parse(&self.variance_threshold)?;
        options.schedule = self.schedule.then_some(ScheduleOptions {
            margin: self.margin,
            lookahead: self.lookahead,
            dwell: self.dwell,
            variance,
        });
        Ok(options)
    }
}

pub fn run(args: &ControlArgs) -> Result<()> {
    if let Some(plot) = &args.plot {
        check_svg(plot)?;
    }
    let options = args.options()?;
    let data = args.columns.read_any(&args.data)?;
    let twin = twin_for_control(&Twin::load(args.twin.as_deref())?, args.sensor_noise);
    let mut progress = progress_bar();
    let outcome = run_control(&twin, &data, &options, &mut progress)?;
    let svg = match &args.plot {
        Some(path) => Some((
            path,
            plot_control(
                &outcome,
                &format!("twin control on {}", args.data.display()),
            )
            .map_err(|m| anyhow::anyhow!("cannot draw {}: {m}", path.display()))?,
        )),
        None => None,
    };
    write_json(&args.report, &outcome.report)?;
    if let Some(path) = &args.ssp {
        let span = (data.time[0], *data.time.last().unwrap_or(&data.time[0]));
        crate::workflows::control::ssp::write_controlled_ssp(
            &twin,
            &outcome.report,
            args.ssp_q,
            Some(span),
            path,
        )
        .with_context(|| format!("--ssp {}", path.display()))?;
    }
    if let Some((path, text)) = svg {
        write_text_atomically(path, &text)?;
    }
    print_summary(&outcome.report);
    Ok(())
}

fn print_summary(r: &crate::workflows::control::ControlReport) {
    println!(
        "twin control: {} on {} (state in {}, R = {}, estimator {}, controller at {:.1} Hz)",
        r.twin, r.data, r.state_unit, r.r, r.estimator, r.control_rate_hz
    );
    let gaps: Vec<String> = r
        .gaps
        .iter()
        .map(|g| format!("{} (gap {:.3} mm)", g.storey, g.gap * 1e3))
        .collect();
    if !gaps.is_empty() {
        println!("  contacts watched at {}", gaps.join(", "));
    }
    println!(
        "  {:>12}  {:>8}  {:>14}  {:>14}  {:>14}",
        "design", "contacts", "attenuation dB", "control RMS N", "control peak N"
    );
    println!(
        "  {:>12}  {:>8}  {:>14}  {:>14}  {:>14}",
        "passive", r.passive.contacts, "-", "-", "-"
    );
    for d in &r.designs {
        match &d.unstable {
            Some(m) => println!("  {:>12}  {m}", format!("q = {}", d.design.q)),
            None => println!(
                "  {:>12}  {:>8}  {:>14.2}  {:>14.4}  {:>14.4}",
                format!("q = {}", d.design.q),
                d.contacts,
                d.mean_attenuation_db,
                d.control_rms,
                d.control_peak
            ),
        }
    }
    if let Some(s) = &r.schedule {
        println!(
            "  {:>12}  {:>8}  {:>14.2}  {:>14.4}  {:>14.4}   ({} switches, high gain {:.0} % of the time)",
            "scheduled",
            s.contacts,
            s.mean_attenuation_db,
            s.control_rms,
            s.control_peak,
            s.switches.len(),
            100.0 * s.high_fraction
        );
        println!(
            "  schedule triggers: drift near the gap {:.1} % of the time, latent variance {}",
            100.0 * s.drift_trigger_fraction,
            match s.variance_threshold {
                Some(_) => format!("{:.1} %", 100.0 * s.variance_trigger_fraction),
                None => "not used (no corrector, or off)".into(),
            }
        );
    }
    if let Some(rt) = &r.retune {
        println!("  retune: {}", rt.verdict);
    }
    for c in &r.estimator_costs {
        println!(
            "  state from {:>9}: mean attenuation {:.2} dB, control RMS {:.4} N, {} contacts",
            c.estimator, c.mean_attenuation_db, c.control_rms, c.contacts
        );
    }
}
