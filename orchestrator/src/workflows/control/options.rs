//! `twin control`'s options: what they are, their defaults, checks and the texts of `--gap`,
//! `--variance-threshold` and `--sensor-noise`, once for the CLI and the Python package.

use serde::Serialize;
use structure::effects::{Kind, Law, Side};

use super::closed_loop::Gap;
use super::StateUnit;
use crate::twin::Twin;
use crate::workflows::options::InvalidOption;

/// Half-width of the band around a resonance in which the peak is read, relative.
pub const RESONANCE_BAND: f64 = 0.1;
/// The grid `--retune` searches, as multiples of the smallest `--q`.
pub const RETUNE_GRID: [f64; 13] = [
    1.0, 1.5, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 70.0, 100.0,
];

/// `--retune`: the smallest q on the grid that keeps the contacts at or below `target` with the
/// peak control force within `max_force`.
#[derive(Clone, Debug)]
pub struct Retune {
    pub target: usize,
    pub max_force: Option<f64>,
}

/// `--schedule`: switch between the smallest and the largest design (or the retuned one).
#[derive(Clone, Debug)]
pub struct ScheduleOptions {
    pub margin: f64,
    pub lookahead: f64,
    pub dwell: f64,
    pub variance: VarianceTrigger,
}

/// Whether the schedule also switches on the corrector's latent variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VarianceTrigger {
    /// When the twin has a corrector: above the twin's noise variance (the threshold active
    /// learning queries at), else 1e-3 of the record's measured variance.
    Auto,
    /// This threshold on every floor, (m/s²)².
    Value(f64),
    Off,
}

#[derive(Clone, Debug)]
pub struct ControlOptions {
    pub qs: Vec<f64>,
    pub r: f64,
    pub unit: StateUnit,
    pub estimator: EstimatorChoice,
    /// Corner of the integrating estimator's drift removal, Hz.
    pub highpass_hz: f64,
    /// Controller samples per record sample (None: from the fastest closed-loop pole).
    pub substeps: Option<usize>,
    /// Accelerometer noise sd the controller reads, per floor, or one for every floor (None:
    /// the twin's calibrated noise).
    pub sensor_noise: Option<Vec<f64>>,
    pub seed: u64,
    /// Gaps to watch besides the twin's own contacts.
    pub gaps: Vec<Gap>,
    pub retune: Option<Retune>,
    pub schedule: Option<ScheduleOptions>,
    /// Compare the estimators' cost on the first design.
    pub estimator_costs: bool,
    /// The floor the control force acts on (1-based).
    pub actuator_floor: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorChoice {
    /// Integrate the measured accelerations twice with drift removal (the paper's).
    Integrate,
    /// A steady-state Kalman observer on the twin's linear model.
    Kalman,
}

impl crate::choice::Choice for EstimatorChoice {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        (
            "integrate",
            "integrate the measured accelerations twice with drift removal",
            EstimatorChoice::Integrate,
        ),
        (
            "kalman",
            "a steady-state Kalman observer on the twin's linear model",
            EstimatorChoice::Kalman,
        ),
    ];
}

crate::choice::display_by_name!(EstimatorChoice);

impl Default for ControlOptions {
    /// No design (`qs` empty: give at least one q), R = 0.1, the state in m, the integrating
    /// estimator with a 0.5 Hz drift removal, sub-steps from the fastest pole, the twin's
    /// calibrated sensor noise, seed 1, no retune, no schedule, the actuator at floor 1.
    fn default() -> Self {
        ControlOptions {
            qs: Vec::new(),
            r: 0.1,
            unit: StateUnit::M,
            estimator: EstimatorChoice::Integrate,
            highpass_hz: 0.5,
            substeps: None,
            sensor_noise: None,
            seed: 1,
            gaps: Vec::new(),
            retune: None,
            schedule: None,
            estimator_costs: false,
            actuator_floor: 1,
        }
    }
}

impl Default for Retune {
    /// At most 3 contact initiations, no force limit.
    fn default() -> Self {
        Retune {
            target: 3,
            max_force: None,
        }
    }
}

impl Default for ScheduleOptions {
    /// The high gain within 40 % of the gap, projected 20 ms ahead, held 0.5 s; the latent
    /// variance trigger `auto`.
    fn default() -> Self {
        ScheduleOptions {
            margin: 0.4,
            lookahead: 0.02,
            dwell: 0.5,
            variance: VarianceTrigger::Auto,
        }
    }
}

impl ControlOptions {
    pub fn validate(&self) -> Result<(), InvalidOption> {
        for &q in &self.qs {
            if !(q.is_finite() && q >= 0.0) {
                return Err(InvalidOption(format!(
                    "--q {q}: the state weight must be a finite number ≥ 0"
                )));
            }
        }
        if !(self.r.is_finite() && self.r > 0.0) {
            return Err(InvalidOption(format!(
                "--r {}: the control weight must be a finite number > 0",
                self.r
            )));
        }
        if self.actuator_floor == 0 {
            return Err(InvalidOption(
                "--actuator-floor 0: floors are counted from 1 (the first floor above the ground)"
                    .into(),
            ));
        }
        if let Some(Retune {
            max_force: Some(m), ..
        }) = &self.retune
        {
            let m = *m;
            if !(m.is_finite() && m > 0.0) {
                return Err(InvalidOption(format!(
                    "--max-force {m}: must be a positive number of newtons"
                )));
            }
        }
        Ok(())
    }
}

/// `--sensor-noise SD` (m/s², every floor): the options' `sensor_noise` (None: the twin's
/// calibrated noise), and whether the twin's own noise goes too (SD = 0: no noise at all).
pub fn sensor_noise(sd: Option<f64>) -> Result<(Option<Vec<f64>>, bool), InvalidOption> {
    match sd {
        Some(s) if s.is_finite() && s >= 0.0 => Ok(((s > 0.0).then(|| vec![s]), s == 0.0)),
        Some(s) => Err(InvalidOption(format!(
            "--sensor-noise {s}: must be a number ≥ 0 (m/s²)"
        ))),
        None => Ok((None, false)),
    }
}

/// The twin as the controller sees it: without its calibrated noise when `--sensor-noise 0`.
pub fn twin_for_control(twin: &Twin, sensor_noise_sd: Option<f64>) -> Twin {
    let mut twin = twin.duplicate();
    if sensor_noise_sd == Some(0.0) {
        twin.noise_variance = None;
    }
    twin
}

impl VarianceTrigger {
    /// `--variance-threshold`: `auto`, `off` or a positive number.
    pub fn parse(text: &str) -> Result<Self, InvalidOption> {
        match text {
            "auto" => Ok(VarianceTrigger::Auto),
            "off" => Ok(VarianceTrigger::Off),
            text => match text.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(VarianceTrigger::Value(v)),
                _ => Err(InvalidOption(format!(
                    "--variance-threshold {text}: expected auto, off or a positive number"
                ))),
            },
        }
    }
}

impl Gap {
    /// `--gap STOREY:GAP[:SIDE]`, e.g. `2-3:5e-4:negative` (storey by its floors, gap in m).
    pub fn parse(text: &str) -> Result<Gap, InvalidOption> {
        let parts: Vec<&str> = text.split(':').collect();
        let usage = || {
            InvalidOption(format!(
                "--gap {text}: expected STOREY:GAP[:SIDE], e.g. 2-3:5e-4:negative (storey 1-2, 2-3 or 0-1)"
            ))
        };
        // The CLI said why a number or side did not parse after the usage (anyhow's context).
        let because = |why: String| InvalidOption(format!("{}: {why}", usage().0));
        if !(2..=3).contains(&parts.len()) {
            return Err(usage());
        }
        let storey = match parts[0] {
            "0-1" => 1,
            "1-2" => 2,
            "2-3" => 3,
            _ => return Err(usage()),
        };
        let gap: f64 = parts[1].parse().map_err(|e| because(format!("{e}")))?;
        if !(gap.is_finite() && gap > 0.0) {
            return Err(InvalidOption(format!(
                "--gap {text}: the gap must be a positive number of metres"
            )));
        }
        let side = match parts.get(2) {
            None => Side::Both,
            Some(s) => Side::parse(s).ok_or_else(usage)?,
        };
        let mut reals: Vec<f64> = Kind::Contact
            .real_params()
            .iter()
            .map(|p| p.start)
            .collect();
        reals[0] = gap;
        let law = Law::new(Kind::Contact, &reals, side)
            .ok_or_else(|| InvalidOption("contact law".into()))?;
        Ok(Gap { storey, law })
    }
}
