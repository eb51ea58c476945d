//! `twin synth`: make a synthetic measurement record and its truth JSON (see
//! [`crate::synth`] for the scenario and how a record is made).

use std::path::PathBuf;

use anyhow::{anyhow, bail, Result};

use super::{write_json, write_text_atomically};
use crate::synth::{
    csv_text, parse_change_flag, parse_effect_flag, synth_controlled, BetweenSamples, ForceWindow,
    InLoopController, NoiseLevel, Scenario, DEFAULT_WINDOW_RAMP,
};
use crate::workflows::control::ControllerSpec;

const AFTER_HELP: &str = "\
Scenario JSON (every field optional; see the orchestrator::synth documentation):
  {\"seed\": 7, \"duration\": 20.0, \"sample_rate\": 51.2, \"oversample\": 64,
   \"parameters\": {\"m\": [3], \"c\": [3], \"k\": [3]},
   \"force\": {\"rms\": 0.25, \"band_hz\": 25.6, \"low_hz\": 0, \"between_samples\": \"band-limited\" | \"linear\",
              \"windows\": [{\"start\": 13, \"end\": 17, \"gain\": 3, \"ramp\": 0.5}]},
   \"noise\": {\"fraction\": 0.03 | \"sd\": [3], \"force_fraction\": 0},
   \"effects\": [{\"kind\": \"contact\", \"location\": [2, 3], \"gap\": 5e-4, \"stiffness\": 9000, \"side\": \"both\"},
               {\"kind\": \"cubic\", \"location\": [2], \"stiffness\": 5e9},
               {\"kind\": \"friction\", \"location\": [1], \"force\": 0.2, \"velocity_scale\": 1e-3},
               {\"kind\": \"hysteresis\", \"location\": [2], \"stiffness\": 1000, \"yield\": 5e-4,
                \"beta\": 0.5, \"gamma\": 0.5, \"exponent\": 2},
               {\"kind\": \"quadratic_damping\", \"location\": [2], \"coefficient\": 400},
               {\"kind\": \"quadratic_damping\", \"floor\": 1, \"coefficient\": 400}],
   \"changes\": [{\"at\": 8.0, \"parameter\": \"k2\", \"factor\": 0.85}]}
Locations: contact [lower, upper] floors (0 = ground); cubic, hysteresis and quadratic_damping
[storey] (1 = ground-floor 1); friction [floor]; quadratic_damping \"floor\": N instead damps
floor N's velocity to the ground. Hysteresis (Bouc-Wen) and quadratic_damping (force
coefficient * v|v|, N s^2/m^2, default 400) are NOT in the shear FMU's library. Flags override
the scenario and extend its lists.";

#[derive(clap::Args, Debug, Default, Clone)]
#[command(after_help = AFTER_HELP)]
pub struct SynthArgs {
    /// Scenario JSON; flags override and extend it.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Measurement CSV to write: time,force,acc1,acc2,acc3.
    #[arg(long)]
    pub out: PathBuf,
    /// Truth JSON to write: everything about how the record was made.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Random seed (default 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Record length, s.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Hz.
    #[arg(long)]
    pub sample_rate: Option<f64>,
    /// Fine RK4 steps per sample interval.
    #[arg(long)]
    pub oversample: Option<u32>,
    /// Floor masses, kg.
    #[arg(long, value_name = "M1,M2,M3")]
    pub mass: Option<String>,
    /// Storey damping, N s/m.
    #[arg(long, value_name = "C1,C2,C3")]
    pub damping: Option<String>,
    /// Storey stiffness, N/m.
    #[arg(long, value_name = "K1,K2,K3")]
    pub stiffness: Option<String>,
    /// Force RMS at envelope 1, N.
    #[arg(long)]
    pub force_rms: Option<f64>,
    /// Upper band edge of the force, Hz.
    #[arg(long)]
    pub band_hz: Option<f64>,
    /// Lower band edge of the force, Hz.
    #[arg(long)]
    pub low_hz: Option<f64>,
    /// The force the structure sees between samples: band-limited (default) or linear.
    #[arg(long, value_name = "band-limited|linear")]
    pub force_between_samples: Option<String>,
    /// Amplitude window: ×GAIN between START and END s (repeatable).
    #[arg(long = "force-window", value_name = "START:END:GAIN[:RAMP]")]
    pub force_windows: Vec<String>,
    /// Sensor noise sd as a fraction of each floor's response RMS.
    #[arg(long)]
    pub noise_fraction: Option<f64>,
    /// Sensor noise sd, m/s², every floor.
    #[arg(long)]
    pub noise_sd: Option<f64>,
    /// Noise on the force, fraction of its RMS.
    #[arg(long)]
    pub force_noise_fraction: Option<f64>,
    /// Effect (repeatable): contact@2-3[:gap=5e-4,stiffness=9000,side=both], cubic@2[:stiffness=5e9],
    /// friction@1[:force=0.2,velocity_scale=1e-3],
    /// hysteresis@2[:stiffness=1000,yield=5e-4,beta=0.5,gamma=0.5,exponent=2] (not in the FMU),
    /// quadratic-damping@2[:coefficient=400] (storey) or quadratic-damping@floor1[:coefficient=400]
    /// (floor to the ground; not in the FMU).
    #[arg(long = "effect", value_name = "KIND@LOCATION[:KEY=VALUE,...]")]
    pub effects: Vec<String>,
    /// Parameter change (repeatable): k2@8:0.85 (factor) or k2@8=3500 (value).
    #[arg(long = "change", value_name = "PARAM@TIME:FACTOR|PARAM@TIME=VALUE")]
    pub changes: Vec<String>,
    /// A `twin control` report: its controller runs in the structure's loop (fed the noisy
    /// measured accelerations) and the record gets a `control` column.
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// Which of the report's designs (its q); default the first stable one.
    #[arg(long, requires = "controller")]
    pub controller_q: Option<f64>,
}

impl SynthArgs {
    /// The scenario: the file's (or the default), then the flags.
    pub fn scenario(&self) -> Result<Scenario> {
        let (mut s, origin) = match &self.scenario {
            Some(path) => (Scenario::load(path)?, path.display().to_string()),
            None => (Scenario::default(), "scenario".to_string()),
        };
        let number = |flag: &str, text: &str| -> Result<f64> {
            match text.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(anyhow!(
                    "--{flag} {text:?}: {:?} is not a finite number",
                    text.trim()
                )),
            }
        };
        let three = |flag: &str, text: &str| -> Result<[f64; 3]> {
            let parts: Vec<&str> = text.split(',').collect();
            if parts.len() != 3 {
                bail!("--{flag} {text:?}: expected three comma-separated numbers");
            }
            Ok([
                number(flag, parts[0])?,
                number(flag, parts[1])?,
                number(flag, parts[2])?,
            ])
        };
        if let Some(x) = self.seed {
            s.seed = x;
        }
        if let Some(x) = self.duration {
            s.duration = x;
        }
        if let Some(x) = self.sample_rate {
            s.sample_rate = x;
        }
        if let Some(x) = self.oversample {
            s.oversample = x;
        }
        if let Some(t) = &self.mass {
            s.mass = three("mass", t)?;
        }
        if let Some(t) = &self.damping {
            s.damping = three("damping", t)?;
        }
        if let Some(t) = &self.stiffness {
            s.stiffness = three("stiffness", t)?;
        }
        if let Some(x) = self.force_rms {
            s.force.rms = x;
        }
        if let Some(x) = self.band_hz {
            s.force.band_hz = Some(x);
        }
        if let Some(x) = self.low_hz {
            s.force.low_hz = x;
        }
        if let Some(x) = &self.force_between_samples {
            s.force.between_samples = BetweenSamples::parse(x).ok_or_else(|| {
                anyhow!("--force-between-samples {x:?}: expected band-limited or linear")
            })?;
        }
        for w in &self.force_windows {
            let parts: Vec<&str> = w.split(':').collect();
            if !(3..=4).contains(&parts.len()) {
                bail!("--force-window {w:?}: expected START:END:GAIN or START:END:GAIN:RAMP");
            }
            s.force.windows.push(ForceWindow {
                start: number("force-window", parts[0])?,
                end: number("force-window", parts[1])?,
                gain: number("force-window", parts[2])?,
                ramp: if parts.len() == 4 {
                    number("force-window", parts[3])?
                } else {
                    DEFAULT_WINDOW_RAMP
                },
            });
        }
        match (self.noise_fraction, self.noise_sd) {
            (Some(_), Some(_)) => bail!("give either --noise-fraction or --noise-sd, not both"),
            (Some(f), None) => s.noise.level = NoiseLevel::Fraction([f; 3]),
            (None, Some(sd)) => s.noise.level = NoiseLevel::Sd([sd; 3]),
            (None, None) => {}
        }
        if let Some(x) = self.force_noise_fraction {
            s.noise.force_fraction = x;
        }
        for e in &self.effects {
            s.effects.push(parse_effect_flag(e)?);
        }
        for c in &self.changes {
            s.changes.push(parse_change_flag(c)?);
        }
        let origin = if self.scenario.is_some() {
            format!("{origin} (with the command-line flags)")
        } else {
            "the command-line flags".into()
        };
        s.validate(&origin)?;
        Ok(s)
    }
}

pub fn run(args: &SynthArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let scenario = args.scenario()?;
    let control = match &args.controller {
        None => None,
        Some(path) => Some(InLoopController::from_report(
            ControllerSpec::load(path)?,
            args.controller_q,
            scenario.seed,
        )?),
    };
    let (record, truth) = synth_controlled(&scenario, control)?;
    let elapsed = started.elapsed();
    // Everything is computed before anything is written.
    let text = csv_text(&record.measurement);
    write_text_atomically(&args.out, &text)?;
    if let Some(path) = &args.truth {
        write_json(path, &truth)?;
    }
    println!(
        "wrote {} ({} samples at {} Hz, seed {}, force RMS {:.4} N, made in {:.0} ms)",
        args.out.display(),
        truth.record.samples,
        scenario.sample_rate,
        scenario.seed,
        truth.force.rms_record,
        elapsed.as_secs_f64() * 1e3
    );
    for e in &truth.effects {
        match e.contact_events {
            Some(events) => println!(
                "  {} (gap {} m): {events} contact events, {:.3} s in contact",
                e.description,
                e.parameters["gap"],
                e.time_in_contact.unwrap_or(0.0)
            ),
            None => match (e.max_abs_z, e.z_saturation) {
                (Some(z), Some(bound)) => println!(
                    "  {} (not in the FMU's library): max |z| {z:.3e} m of {bound:.3e} m, work ∫k·z dδ {:.3e} J",
                    e.description,
                    e.hysteretic_work.unwrap_or(0.0)
                ),
                _ => match e.dissipated_energy {
                    Some(energy) => println!(
                        "  {} (not in the FMU's library): max |v| {:.3e} m/s, dissipated {energy:.3e} J",
                        e.description, e.max_drift_or_velocity
                    ),
                    None => println!("  {}", e.description),
                },
            },
        }
    }
    for c in &truth.changes {
        println!("  {} {} → {} at {} s", c.parameter, c.before, c.after, c.at);
    }
    if let Some(path) = &args.truth {
        println!("wrote {}", path.display());
    }
    Ok(())
}
