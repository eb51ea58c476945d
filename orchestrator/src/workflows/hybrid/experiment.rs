//! `twin hybrid threshold` and `twin hybrid run`: the experiments of the reference paper's
//! section 5 on the substructured test of [`super::run`], with the actuator of
//! [`numerics::actuator`] and the excitation of [`numerics::excitation`] (or a record's force),
//! and the contact law learned from the interface measurements. `twin hybrid run`'s stepped
//! tests run on the master with the substructures as `fmu_substructure` FMUs
//! ([`Setup::simulate_on_master`]); the threshold's bisection, dozens of runs per amplitude
//! error, on the Rust loop ([`super::run`]): the same computation, tested equal to 1e-12.

use std::time::Instant;

use numerics::actuator::{Actuator, ActuatorSpec};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;

use super::identify::{identify, ContactLaw};
use super::spectrum::{harmonics, welch, Harmonics, Spectrum};
use super::{monolithic, run, threshold, Cut, Frame, HybridError, HybridRun, Result, Split};

/// Everything a hybrid experiment is set up with.
#[derive(Clone, Debug)]
pub struct Setup {
    pub structure: Frame,
    /// Where the structure is cut (default: the paper's, the specimen floors 2 and 3).
    pub split: Split,
    /// The excitation scaled to a peak of 1 N, at `dt`.
    pub unit: Vec<f64>,
    pub dt: f64,
    pub substeps: u32,
    /// The actuator (its `amplitude_error` is overridden by each experiment's a_err).
    pub actuator: ActuatorSpec,
    pub energy_factor: f64,
    pub coupling: Coupling,
}

/// How the substructures are coupled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Coupling {
    /// One ODE when the actuator has no dynamics (no delay, lag or compensation: the paper's
    /// simplified simulation), the stepped loop otherwise.
    Auto,
    /// The assembly as one ODE (an actuator without dynamics only).
    Monolithic,
    /// The substructures stepped at the control rate with the actuator between, as a real test.
    Stepped,
}

impl crate::choice::Choice for Coupling {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        (
            "auto",
            "one ODE when the actuator has no dynamics, the stepped loop otherwise",
            Coupling::Auto,
        ),
        (
            "monolithic",
            "the assembly as one ODE (an actuator without dynamics only)",
            Coupling::Monolithic,
        ),
        (
            "stepped",
            "the substructures stepped at the control rate with the actuator between",
            Coupling::Stepped,
        ),
    ];
}

crate::choice::display_by_name!(Coupling);

impl Setup {
    /// What the specimen holds, in words.
    pub fn describe_split(&self) -> String {
        Cut {
            floor: self.structure.floor,
            split: self.split,
            storeys: None,
        }
        .describe(self.structure.storeys())
    }

    fn control_step(&self) -> f64 {
        self.dt / f64::from(self.substeps)
    }

    /// The actuator with amplitude error `a_err`; refuses a delay the control step cannot
    /// represent, and any pure delay when the specimen holds floor 2.
    fn actuator(&self, a_err: f64) -> Result<Actuator> {
        let spec = ActuatorSpec {
            amplitude_error: a_err,
            ..self.actuator
        };
        let actuator = Actuator::new(spec, self.control_step())
            .map_err(|e| HybridError::Setup(e.to_string()))?;
        if self.split.floor_physical() && spec.delay > 0.0 {
            // Measured: one control step of delay (0.49 ms) diverges within 5.1 s, five within
            // 0.7 s even with third-order compensation; the other split runs both.
            let (n, j) = (self.structure.storeys(), self.structure.floor);
            let name = |split| {
                Cut {
                    floor: j,
                    split,
                    storeys: None,
                }
                .name(n)
            };
            return Err(HybridError::Setup(format!(
                "a pure delay ({} s) with the specimen holding floor {j} (--split {}, the paper's) \
                 feeds floor {j}'s inertia of the delayed motion back into the massless interface \
                 equation (14): a neutral delay loop that no stepped test holds; give --split {} \
                 (floor {j} numerical) or no delay (a lag is accepted)",
                spec.delay,
                name(Split::FloorPhysical),
                name(Split::FloorNumerical)
            )));
        }
        Ok(actuator)
    }

    /// Whether the actuator only scales (no delay, lag or compensation).
    fn algebraic(&self) -> bool {
        self.actuator.delay == 0.0
            && self.actuator.lag == 0.0
            && self.actuator.compensation == numerics::actuator::Compensation::None
    }

    /// The coupling `coupling` resolves to; refuses a one-ODE solve of an actuator with
    /// dynamics.
    pub fn resolved(&self) -> Result<Coupling> {
        match (self.coupling, self.algebraic()) {
            (Coupling::Auto, true) => Ok(Coupling::Monolithic),
            (Coupling::Auto, false) => Ok(Coupling::Stepped),
            (Coupling::Monolithic, false) => Err(HybridError::Setup(
                "a delay, lag or compensation makes the actuator dynamic: it needs the stepped \
                 coupling"
                    .into(),
            )),
            (c, _) => Ok(c),
        }
    }

    /// One test of `excitation` with amplitude error `a_err`.
    pub fn simulate(&self, excitation: &[f64], a_err: f64) -> Result<HybridRun> {
        match self.resolved()? {
            Coupling::Monolithic => monolithic::run(
                &self.structure,
                self.split,
                excitation,
                self.dt,
                self.substeps,
                a_err,
            ),
            _ => {
                let mut act = self.actuator(a_err)?;
                run(
                    &self.structure,
                    self.split,
                    excitation,
                    self.dt,
                    self.substeps,
                    |y| act.step(y),
                    self.energy_factor,
                )
            }
        }
    }
}

impl Setup {
    /// [`Setup::simulate`] with the stepped coupling on the master: the substructures as two
    /// `fmu_substructure` instances ([`super::fmus::run_on_master`], the same computation as
    /// [`super::run`], tested equal to it) when the FMU's variables fit the cut (the paper's
    /// rig, [`super::fmus::serves`]); other cuts, and the one-ODE coupling, which has no
    /// substructures to run, as [`Setup::simulate`].
    pub fn simulate_on_master(&self, excitation: &[f64], a_err: f64) -> Result<HybridRun> {
        match self.resolved()? {
            Coupling::Stepped if super::fmus::serves(&self.structure) => {
                let mut act = self.actuator(a_err)?;
                super::fmus::run_on_master(
                    &self.structure,
                    self.split,
                    excitation,
                    self.dt,
                    self.substeps,
                    move |y| act.step(y),
                    self.energy_factor,
                )
            }
            _ => self.simulate(excitation, a_err),
        }
    }
}

/// One point of the threshold curve.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ThresholdPoint {
    pub a_err: f64,
    /// The peak excitation force at which the bumper first closes (bisection on the test).
    pub threshold_peak_force: f64,
    /// The same from the linear assembly: the gap over the largest `y_r` of the unit-peak run.
    pub independent: f64,
    /// Against perfect control's threshold (when a_err = 0 is among the points).
    pub relative_to_perfect: Option<f64>,
}

/// The threshold curve, or why a point could not be had (an unstable test).
#[derive(Clone, Debug, Serialize)]
pub struct ThresholdCurve {
    pub thresholds: Vec<ThresholdPoint>,
    /// a_err and the reason, for each point that failed.
    pub failed: Vec<(f64, String)>,
    pub seconds: f64,
}

/// The threshold for each amplitude error.
pub fn threshold_curve(setup: &Setup, a_errs: &[f64]) -> Result<ThresholdCurve> {
    let started = Instant::now();
    let mut points = Vec::new();
    let mut failed = Vec::new();
    for &a in a_errs {
        // Refuse a bad actuator up front (a delay that is no whole number of steps).
        setup.actuator(a)?;
        let found = threshold(&setup.unit, |f| setup.simulate(f, a));
        let open = Setup {
            structure: Frame {
                gap: f64::MAX / 4.0,
                ..setup.structure.clone()
            },
            ..setup.clone()
        };
        let linear = open.simulate(&setup.unit, a);
        match (found, linear) {
            (Ok(t), Ok(l)) => points.push(ThresholdPoint {
                a_err: a,
                threshold_peak_force: t,
                independent: setup.structure.gap / l.max_relative,
                relative_to_perfect: None,
            }),
            (Err(e), _) | (_, Err(e)) => failed.push((a, e.to_string())),
        }
    }
    if let Some(perfect) = points
        .iter()
        .find(|p| p.a_err == 0.0)
        .map(|p| p.threshold_peak_force)
    {
        for p in &mut points {
            p.relative_to_perfect = Some(p.threshold_peak_force / perfect - 1.0);
        }
    }
    Ok(ThresholdCurve {
        thresholds: points,
        failed,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Sensor noise on the interface measurements (sd).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct InterfaceNoise {
    /// m, on each displacement.
    pub displacement: f64,
    /// N, on the force.
    pub force: f64,
    /// m/s², on floor 2's acceleration (the specimen's accelerometer; used when the specimen
    /// holds floor 2 and the force carries its inertia).
    pub acceleration: f64,
    pub seed: u64,
}

/// One run of `twin hybrid run`.
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub a_err: f64,
    pub contacts: usize,
    pub max_relative: f64,
    /// Floor 2's displacement spectrum: fundamental, peaks, harmonics (the structure's own
    /// modes left out).
    pub spectrum: Option<Harmonics>,
    /// The contact law from the measured (noisy) interface: y₂ₚ, y₃, F_m (and floor 2's
    /// acceleration when the specimen holds floor 2).
    pub identified: Option<ContactLaw>,
    /// The same from the commanded y₂ₙ instead of the measured y₂ₚ: the bias an amplitude
    /// error puts in a law identified from the command.
    pub identified_from_command: Option<ContactLaw>,
    /// Why the run stopped, if it did (an unstable test).
    pub stopped: Option<String>,
}

/// A run with what the plot draws.
pub struct RunOutcome {
    pub summary: RunSummary,
    pub run: Option<HybridRun>,
    pub spectrum: Option<Spectrum>,
}

/// Segment of the displacement spectra: 8 s at the record's rate (0.125 Hz bins).
fn segment(dt: f64) -> usize {
    ((8.0 / dt).round() as usize).max(16)
}

/// The test at `peak` N for each amplitude error (stepped: on the master with the substructure
/// FMUs), with the law identified from each.
pub fn runs(
    setup: &Setup,
    peak: f64,
    a_errs: &[f64],
    noise: InterfaceNoise,
) -> Result<Vec<RunOutcome>> {
    if !(peak.is_finite() && peak > 0.0) {
        return Err(HybridError::Setup(format!(
            "the peak force must be positive and finite, was {peak}"
        )));
    }
    let excitation: Vec<f64> = setup.unit.iter().map(|f| f * peak).collect();
    let st = &setup.structure;
    let modes = structure::Structure {
        mass: st.mass.to_vec(),
        damping: st.damping.to_vec(),
        stiffness: st.stiffness.to_vec(),
        excitation: structure::Excitation::Force { floor: 1 },
    }
    .natural_frequencies();
    let mut out = Vec::new();
    for (i, &a) in a_errs.iter().enumerate() {
        setup.actuator(a)?;
        let result = setup.simulate_on_master(&excitation, a);
        let run = match result {
            Ok(r) => r,
            Err(e @ HybridError::Unstable { .. }) => {
                out.push(RunOutcome {
                    summary: RunSummary {
                        a_err: a,
                        contacts: 0,
                        max_relative: f64::NAN,
                        spectrum: None,
                        identified: None,
                        identified_from_command: None,
                        stopped: Some(e.to_string()),
                    },
                    run: None,
                    spectrum: None,
                });
                continue;
            }
            Err(e) => return Err(e),
        };
        let spectrum = welch(&run.yjp, setup.dt, segment(setup.dt));
        // The measurements, with noise (seeded per run).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(noise.seed.wrapping_add(i as u64));
        let mut noisy = |x: &[f64], sd: f64| -> Vec<f64> {
            match Normal::new(0.0, sd) {
                Ok(d) if sd > 0.0 => x.iter().map(|v| v + d.sample(&mut rng)).collect(),
                _ => x.to_vec(),
            }
        };
        let face = &run.interface;
        let yjp = noisy(&face.yjp, noise.displacement);
        let yjn = noisy(&face.yjn, noise.displacement);
        let y3 = noisy(&face.y_above, noise.displacement);
        let force = noisy(&face.force, noise.force);
        let ajp = setup
            .split
            .floor_physical()
            .then(|| noisy(&face.ajp, noise.acceleration));
        out.push(RunOutcome {
            summary: RunSummary {
                a_err: a,
                contacts: run.contact_times.len(),
                max_relative: run.max_relative,
                spectrum: harmonics(&spectrum, 40.0, &modes),
                identified: identify(&yjp, &y3, ajp.as_deref(), &force, face.step),
                identified_from_command: identify(&yjn, &y3, ajp.as_deref(), &force, face.step),
                stopped: None,
            },
            run: Some(run),
            spectrum: Some(spectrum),
        });
    }
    Ok(out)
}

/// The contact law a `twin hybrid run` report identified (from the measured interface of its
/// run with the smallest |a_err|), and that a_err; Err when no run identified a contact.
pub fn identified_contact(report: &std::path::Path) -> Result<(ContactLaw, f64)> {
    let bad = |what: String| HybridError::Setup(format!("{}: {what}", report.display()));
    let text = std::fs::read_to_string(report).map_err(|e| bad(e.to_string()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not JSON ({e})")))?;
    let runs = value
        .get("runs")
        .and_then(|r| r.as_array())
        .ok_or_else(|| bad("no runs: give the report of `twin hybrid run`".into()))?;
    let (a_err, law) = runs
        .iter()
        .filter_map(|r| {
            let a = r.get("a_err")?.as_f64()?;
            let law: ContactLaw = serde_json::from_value(r.get("identified")?.clone()).ok()?;
            Some((a, law))
        })
        .min_by(|x, y| x.0.abs().total_cmp(&y.0.abs()))
        .ok_or_else(|| bad("no run identified a contact law".into()))?;
    if !(law.gap > 0.0 && law.contact_stiffness > 0.0) {
        return Err(bad(format!(
            "the identified law (gap {}, stiffness {}) is not a contact",
            law.gap, law.contact_stiffness
        )));
    }
    Ok((law, a_err))
}
