//! `twin synth`: make a synthetic measurement record and its truth JSON (see
//! [`crate::synth`] for the scenario and how a record is made).

use std::path::PathBuf;

use anyhow::{anyhow, bail, Result};

use super::{write_json, write_text_atomically};
use crate::synth::{
    csv_text, parse_change_flag, parse_effect_flag_for, synth_controlled, BetweenSamples,
    ForceWindow, GroundMotion, InLoopController, NoiseLevel, Scenario, DEFAULT_WINDOW_RAMP,
};
use crate::workflows::control::ControllerSpec;
use structure::channel::{parse_header_field, Channel, Quantity, Unit};
use structure::Excitation;

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
   \"changes\": [{\"at\": 8.0, \"parameter\": \"k2\", \"factor\": 0.85}],
   \"storeys\": 5, \"excitation\": \"force:K\" | \"base\",
   \"ground_motion\": {\"soil_hz\": 2.5, \"soil_damping\": 0.6, \"rise_end\": 2, \"strong_end\": 10, \"decay\": 0.4},
   \"channels\": [\"acc1 (g)\", \"acc3 (g)\", \"vel5 (mm/s)\"]}
Any building: --storeys N (equal floors 5.2 kg, storeys 3 N s/m and 4021 N/m unless
--nominal NOMINAL.json {\"m\": [...], \"c\": [...], \"k\": [...]} or --mass/--damping/--stiffness
give them), --excitation force:K or base (ground motion: Kanai-Tajimi filtered white noise
under a Jennings envelope, --force-rms its stationary RMS in m/s2), --channels acc1,acc3,vel2
and --units acc=g,vel=mm/s. Effects at any site of it: cubic@4, contact@9-10, friction@floor12.
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
    /// Measurement CSV to write: time, the excitation (force or ground_acc), the response
    /// channels (default acc1..accN in m/s2).
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
    /// Storeys of the building (default 3, the paper's rig).
    #[arg(long)]
    pub storeys: Option<usize>,
    /// What shakes it: force:K (a force at floor K) or base (ground motion).
    #[arg(long, value_name = "force:K|base")]
    pub excitation: Option<String>,
    /// The structure's m, c, k as `twin init --nominal` takes them: {"m": [...], "c": [...],
    /// "k": [...]} (kg, N s/m, N/m).
    #[arg(long, value_name = "NOMINAL.json")]
    pub nominal: Option<PathBuf>,
    /// Floor masses, kg (one per floor).
    #[arg(long, value_name = "M1,M2,...")]
    pub mass: Option<String>,
    /// Storey damping, N s/m (one per storey).
    #[arg(long, value_name = "C1,C2,...")]
    pub damping: Option<String>,
    /// Storey stiffness, N/m (one per storey).
    #[arg(long, value_name = "K1,K2,...")]
    pub stiffness: Option<String>,
    /// The response channels written (default acc1..accN): e.g. acc1,acc3,acc5 or vel1,vel2.
    #[arg(long, value_name = "CHANNEL,...")]
    pub channels: Option<String>,
    /// Units of the written channels by quantity: acc=g|m/s2|mm/s2, vel=m/s|mm/s, disp=m|mm.
    #[arg(long, value_name = "QUANTITY=UNIT,...")]
    pub units: Option<String>,
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

/// A flag's number: finite, or an error naming the flag.
fn number(flag: &str, text: &str) -> Result<f64> {
    match text.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(anyhow!(
            "--{flag} {text:?}: {:?} is not a finite number",
            text.trim()
        )),
    }
}

/// A flag's comma-separated numbers.
fn list(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',').map(|part| number(flag, part)).collect()
}

/// `--units`' `QUANTITY=UNIT` parts applied to the scenario's response channels.
fn with_units(t: &str, mut channels: Vec<(Channel, Unit)>) -> Result<Vec<(Channel, Unit)>> {
    for part in t.split(',') {
        let (key, unit) = part.split_once('=').ok_or_else(|| {
            anyhow!("--units {t:?}: {part:?} is not QUANTITY=UNIT (acc=g, vel=mm/s, disp=mm)")
        })?;
        let quantity = match key.trim() {
            "acc" => Quantity::Acceleration,
            "vel" => Quantity::Velocity,
            "disp" => Quantity::Displacement,
            other => bail!("--units {t:?}: {other:?} is not acc, vel or disp"),
        };
        let unit = Unit::parse(unit)
            .filter(|u| u.quantity() == quantity)
            .ok_or_else(|| {
                anyhow!(
                    "--units {t:?}: {:?} is not a unit of {key} ({})",
                    unit.trim(),
                    Unit::ALL
                        .iter()
                        .filter(|u| u.quantity() == quantity)
                        .map(|u| u.symbol())
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
        for (channel, u) in channels.iter_mut() {
            if matches!(channel, Channel::Response { quantity: q, .. } if *q == quantity) {
                *u = unit;
            }
        }
    }
    Ok(channels)
}

/// `--force-window START:END:GAIN[:RAMP]`.
fn force_window(w: &str) -> Result<ForceWindow> {
    let parts: Vec<&str> = w.split(':').collect();
    if !(3..=4).contains(&parts.len()) {
        bail!("--force-window {w:?}: expected START:END:GAIN or START:END:GAIN:RAMP");
    }
    Ok(ForceWindow {
        start: number("force-window", parts[0])?,
        end: number("force-window", parts[1])?,
        gain: number("force-window", parts[2])?,
        ramp: if parts.len() == 4 {
            number("force-window", parts[3])?
        } else {
            DEFAULT_WINDOW_RAMP
        },
    })
}

impl SynthArgs {
    /// The scenario: the file's (or the default), then the flags.
    pub fn scenario(&self) -> Result<Scenario> {
        let (mut s, origin) = match &self.scenario {
            Some(path) => (Scenario::load(path)?, path.display().to_string()),
            None => (Scenario::default(), "scenario".to_string()),
        };
        self.apply_timing(&mut s);
        self.apply_structure(&mut s)?;
        self.apply_channels(&mut s)?;
        self.apply_force(&mut s)?;
        self.apply_noise(&mut s)?;
        for e in &self.effects {
            s.effects.push(parse_effect_flag_for(e, s.storeys())?);
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

    /// `--seed`, `--duration`, `--sample-rate`, `--oversample`.
    fn apply_timing(&self, s: &mut Scenario) {
        if let Some(x) = self.seed {
            s.seed = x;
        }
        if let Some(x) = self.duration {
            // The ground motion's envelope follows the record unless the scenario set it.
            if s.ground == GroundMotion::for_duration(s.duration) {
                s.ground = GroundMotion::for_duration(x);
            }
            s.duration = x;
        }
        if let Some(x) = self.sample_rate {
            s.sample_rate = x;
        }
        if let Some(x) = self.oversample {
            s.oversample = x;
        }
    }

    /// `--storeys`, `--nominal`, `--mass`, `--damping`, `--stiffness`, `--excitation`.
    fn apply_structure(&self, s: &mut Scenario) -> Result<()> {
        if let Some(n) = self.storeys {
            if !(1..=structure::MAX_STOREYS).contains(&n) {
                bail!(
                    "--storeys {n}: a structure has 1 to {} storeys",
                    structure::MAX_STOREYS
                );
            }
            if n != s.storeys() {
                s.set_storeys(n);
            }
        }
        if let Some(path) = &self.nominal {
            let nominal = crate::twin::structure::Nominal::read(path)?;
            if let Some(n) = self.storeys {
                if nominal.m.len() != n {
                    bail!(
                        "{}: \"m\" has {} values but --storeys is {n}",
                        path.display(),
                        nominal.m.len()
                    );
                }
            }
            s.mass = nominal.m;
            s.damping = nominal.c;
            s.stiffness = nominal.k;
        }
        if let Some(t) = &self.mass {
            s.mass = list("mass", t)?;
        }
        if let Some(t) = &self.damping {
            s.damping = list("damping", t)?;
        }
        if let Some(t) = &self.stiffness {
            s.stiffness = list("stiffness", t)?;
        }
        if let Some(t) = &self.excitation {
            s.excitation = Excitation::parse(t)
                .map_err(|e| anyhow!("--excitation {t:?}: {e}; expected force:K or base"))?;
        }
        Ok(())
    }

    /// `--channels`, then `--units`.
    fn apply_channels(&self, s: &mut Scenario) -> Result<()> {
        if let Some(t) = &self.channels {
            s.channels = Some(
                t.split(',')
                    .map(|field| {
                        parse_header_field(field).map_err(|e| anyhow!("--channels {t:?}: {e}"))
                    })
                    .collect::<Result<Vec<_>>>()?,
            );
        }
        if let Some(t) = &self.units {
            s.channels = Some(with_units(t, s.response_channels())?);
        }
        Ok(())
    }

    /// `--force-rms`, `--band-hz`, `--low-hz`, `--force-between-samples`, `--force-window`.
    fn apply_force(&self, s: &mut Scenario) -> Result<()> {
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
            s.force.windows.push(force_window(w)?);
        }
        Ok(())
    }

    /// `--noise-fraction` or `--noise-sd`, `--force-noise-fraction`.
    fn apply_noise(&self, s: &mut Scenario) -> Result<()> {
        match (self.noise_fraction, self.noise_sd) {
            (Some(_), Some(_)) => bail!("give either --noise-fraction or --noise-sd, not both"),
            (Some(f), None) => s.noise.level = NoiseLevel::Fraction(vec![f]),
            (None, Some(sd)) => s.noise.level = NoiseLevel::Sd(vec![sd]),
            (None, None) => {}
        }
        if let Some(x) = self.force_noise_fraction {
            s.noise.force_fraction = x;
        }
        Ok(())
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
        "wrote {} ({} samples at {} Hz, seed {}, {} RMS {:.4} {}, made in {:.0} ms)",
        args.out.display(),
        truth.record.samples,
        scenario.sample_rate,
        scenario.seed,
        scenario.excitation.input_name(),
        truth.force.rms_record,
        if scenario.excitation == Excitation::Base {
            "m/s2"
        } else {
            "N"
        },
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
