//! The set-up and the runs: the record and the options checked, the twin's linear basis, the
//! designs and the loop's plan, the estimator chosen for the record's sensors, and a [`Runner`]
//! that drives the structure passive and under each design.

use super::closed_loop::{simulate, Gains, Gap, LoopLaw, LoopSetup, Response, StateSource};
use super::design::{self, design, plant_measuring, structure_of, with_actuator_at, Design};
use super::options::{ControlOptions, EstimatorChoice, RETUNE_GRID};
use super::report::{Attenuation, DesignRun, EstimatorCost, RetuneReport, ScheduleReport};
use super::response::{acc_rms, attenuation, resonance_peaks};
use super::{closed_loop, ControlError};
use crate::blocks::lqr::SensorNoise;
use crate::evaluation::stats::rms;
use crate::twin::data::Measurement;
use crate::twin::Twin;
use numerics::lqr::{Estimator, StateSpace};
use structure::channel::{Channel, Quantity};
use structure::Structure;

/// Controller samples per record sample: the fastest closed-loop pole moves by at most 0.1 rad
/// per sample; a power of two (so that it divides a synthetic record's fine grid), at least 4,
/// at most 4096.
pub fn substeps_for(designs: &[Design], dt: f64) -> usize {
    let fastest = designs
        .iter()
        .flat_map(|d| d.closed_loop_poles.iter())
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0f64, f64::max);
    ((fastest * dt / 0.1).ceil() as usize)
        .clamp(4, 4096)
        .next_power_of_two()
}

pub(super) struct Runner<'a> {
    pub(super) twin: &'a Twin,
    pub(super) data: &'a Measurement,
    pub(super) setup: LoopSetup,
    pub(super) estimator: Estimator,
    pub(super) resonances: Vec<f64>,
    pub(super) passive_peaks: Vec<Vec<f64>>,
    pub(super) progress: &'a mut dyn FnMut(u64, u64),
    pub(super) runs_done: u64,
    pub(super) runs_total: u64,
}

impl Runner<'_> {
    pub(super) fn run(&mut self, law: Option<&LoopLaw>) -> Result<Response, ControlError> {
        let (done, total) = (self.runs_done, self.runs_total.max(self.runs_done + 1));
        let progress = &mut *self.progress;
        let mut report = |k: u64, n: u64| progress(done * n + k, total * n);
        let out = simulate(self.twin, self.data, &self.setup, law, &mut report);
        self.runs_done += 1;
        out
    }

    /// Run `gains` with the chosen estimator; an unstable loop is a result, not a failure.
    pub(super) fn run_law(
        &mut self,
        gains: Gains,
        state: StateSource,
    ) -> Result<Result<Response, String>, ControlError> {
        match self.run(Some(&LoopLaw { gains, state })) {
            Ok(r) => Ok(Ok(r)),
            Err(ControlError::Unstable(message)) => Ok(Err(message)),
            Err(e) => Err(e),
        }
    }

    /// The attenuation of `r` at each resonance against the passive run, and its mean.
    pub(super) fn attenuation_of(&self, r: &Response) -> (Vec<Attenuation>, f64) {
        let peaks = resonance_peaks(
            &self.data.excitation.values,
            r,
            self.data.dt,
            &self.resonances,
        );
        attenuation(&self.passive_peaks, &peaks, &self.resonances)
    }

    pub(super) fn design_run(
        &mut self,
        design: Design,
        role: &str,
    ) -> Result<(DesignRun, Option<Response>), ControlError> {
        let state = StateSource::Estimated(self.estimator.clone());
        let outcome = self.run_law(Gains::Fixed(design.gain.clone()), state)?;
        Ok(match outcome {
            Ok(r) => {
                let (att, mean) = self.attenuation_of(&r);
                (
                    DesignRun {
                        design,
                        role: role.into(),
                        contacts: r.contacts.len(),
                        contact_times: r.contacts.iter().map(|c| c.time).collect(),
                        contact_events: r.contacts.clone(),
                        attenuation_db: att,
                        mean_attenuation_db: mean,
                        control_rms: r.control_rms,
                        control_peak: r.control_peak,
                        acc_rms: acc_rms(&r),
                        unstable: None,
                    },
                    Some(r),
                )
            }
            Err(message) => (
                DesignRun {
                    design,
                    role: role.into(),
                    contacts: 0,
                    contact_times: Vec::new(),
                    contact_events: Vec::new(),
                    attenuation_db: Vec::new(),
                    mean_attenuation_db: f64::NAN,
                    control_rms: f64::NAN,
                    control_peak: f64::NAN,
                    acc_rms: vec![f64::NAN; self.setup.plant.floors()],
                    unstable: Some(message),
                },
                None,
            ),
        })
    }
}

pub(super) fn estimator_of(
    choice: EstimatorChoice,
    options: &ControlOptions,
    noise_sd: Option<&[f64]>,
    data: &Measurement,
    measured: &[Channel],
) -> Estimator {
    match choice {
        EstimatorChoice::Integrate => Estimator::Integrate {
            highpass_hz: options.highpass_hz,
        },
        EstimatorChoice::Kalman => {
            // The model's error as the excitation's: 5 % of the record's excitation RMS per
            // sample; the sensors' noise as the twin calibrated it (else 1 % of each measured
            // channel's RMS, in its own quantity).
            let excitation_rms = rms(&data.excitation.values).max(1e-6);
            let sensor_sd: Vec<f64> = match noise_sd {
                Some(sd) => sd.to_vec(),
                None => measured
                    .iter()
                    .map(|c| (0.01 * rms(data.channel(*c).unwrap_or(&[]))).max(1e-6))
                    .collect(),
            };
            Estimator::Kalman {
                process_sd: 0.05 * excitation_rms,
                sensor_sd: sensor_sd.iter().map(|s| s.max(1e-9)).collect(),
            }
        }
    }
}

/// The record's response channels in the order the controller reads them: accelerations, then
/// velocities, then displacements, each by floor.
pub fn measured_channels(data: &Measurement) -> Vec<Channel> {
    let rank = |q: Quantity| match q {
        Quantity::Acceleration => 0,
        Quantity::Velocity => 1,
        _ => 2,
    };
    let mut channels: Vec<Channel> = data
        .responses
        .iter()
        .map(|s| s.channel)
        .filter(|c| matches!(c, Channel::Response { .. }))
        .collect();
    channels.sort_by_key(|c| match c {
        Channel::Response { quantity, floor } => (rank(*quantity), *floor),
        _ => (3, 0),
    });
    channels.dedup();
    channels
}

pub(super) fn names(channels: &[Channel]) -> String {
    channels
        .iter()
        .map(Channel::name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether the estimator can run on what the record measures, said before any work: the
/// integrating estimator needs every floor's acceleration; the Kalman observer needs a set of
/// channels from which the state is observable (a mode standing still at every sensor is not).
pub fn check_estimator(
    choice: EstimatorChoice,
    structure: &Structure,
    plant: &numerics::lqr::StateSpace,
    measured: &[Channel],
) -> Result<(), ControlError> {
    match choice {
        EstimatorChoice::Integrate => {
            let every = fmu_lqr::model::every_acceleration(structure.storeys());
            if measured != every.as_slice() {
                return Err(ControlError::Options(format!(
                    "--estimator integrate integrates an accelerometer on every floor ({}); the \
                     record measures {}: use --estimator kalman, which estimates the state from \
                     the channels there are",
                    names(&every),
                    names(measured)
                )));
            }
            Ok(())
        }
        EstimatorChoice::Kalman => {
            let missed = plant.unobservable();
            if missed.is_empty() {
                return Ok(());
            }
            let mut freqs: Vec<f64> = missed
                .iter()
                .map(|e| e[0].hypot(e[1]) / (2.0 * std::f64::consts::PI))
                .collect();
            freqs.sort_by(f64::total_cmp);
            freqs.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs().max(1.0));
            let listed: Vec<String> = freqs.iter().map(|f| format!("{f:.3} Hz")).collect();
            Err(ControlError::Options(format!(
                "the state is not observable from the record's channels {}: the motion at {} \
                 moves none of them (a mode standing still at every sensor); the Kalman \
                 estimator cannot see it, so the controller cannot be designed on it — measure \
                 another floor as well",
                names(measured),
                listed.join(", ")
            )))
        }
    }
}

/// What the control is designed on, all checked before any run: the twin's structure, the
/// channels the record measures, the plant the designs are made on, and the twin with its
/// actuator at the chosen floor.
pub(super) struct ControlBasis {
    pub(super) structure: Structure,
    pub(super) measured: Vec<Channel>,
    pub(super) plant: StateSpace,
    /// The twin with the actuator at `--actuator-floor`: the one every run drives.
    pub(super) twin: Twin,
}

/// The designs to run: the requested weights (sorted, without repeats) and their designs, the
/// retune grid's designs (empty without `--retune`), and the controller samples per record
/// sample they fix.
pub(super) struct DesignSet {
    pub(super) qs: Vec<f64>,
    pub(super) designs: Vec<Design>,
    pub(super) retune: Vec<Design>,
    pub(super) substeps: usize,
}

/// What every run of the loop shares besides the plant: the sensor noise the controller reads
/// (None: none), the gaps watched, the estimator and the structure's resonances.
pub(super) struct LoopPlan {
    pub(super) noise_sd: Option<Vec<f64>>,
    pub(super) gaps: Vec<Gap>,
    pub(super) estimator: Estimator,
    pub(super) resonances: Vec<f64>,
}

/// The design runs so far, in the report's order, each with its response (None when the loop
/// went unstable).
#[derive(Default)]
pub(super) struct DesignRuns {
    pub(super) runs: Vec<DesignRun>,
    pub(super) responses: Vec<Option<Response>>,
}

impl DesignRuns {
    pub(super) fn push(&mut self, run: DesignRun, response: Option<Response>) {
        self.runs.push(run);
        self.responses.push(response);
    }
}

/// The gain schedule's run: its report and its response.
pub(super) struct ScheduledRun {
    pub(super) report: ScheduleReport,
    pub(super) response: Response,
}

/// Everything the runs gave, for the report.
pub(super) struct Runs {
    pub(super) passive: Response,
    pub(super) designs: DesignRuns,
    pub(super) retune: Option<RetuneReport>,
    pub(super) schedule: Option<ScheduledRun>,
    pub(super) estimator_costs: Vec<EstimatorCost>,
}

/// The options that need nothing else to be checked: at least one q, and a positive corner
/// for the drift removal.
pub(super) fn check_options(options: &ControlOptions) -> Result<(), ControlError> {
    if options.qs.is_empty() {
        return Err(ControlError::Options("give at least one --q".into()));
    }
    if !(options.highpass_hz.is_finite() && options.highpass_hz > 0.0) {
        return Err(ControlError::Options(format!(
            "--highpass must be a positive frequency (Hz), got {}",
            options.highpass_hz
        )));
    }
    Ok(())
}

/// The twin's structure with the actuator on one of its floors, the record able to drive it,
/// the plant on the record's channels (the estimator able to run on them), and the twin with
/// its actuator at that floor.
pub(super) fn control_basis(
    twin: &Twin,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<ControlBasis, ControlError> {
    let structure: Structure = structure_of(twin)?;
    design::check_actuator_floor(options.actuator_floor, &structure)?;
    check_record(data, &structure)?;
    let measured = measured_channels(data);
    let plant = plant_measuring(
        &structure,
        options.actuator_floor,
        &measured,
        options.unit.scale(),
    )?;
    check_estimator(options.estimator, &structure, &plant, &measured)?;
    let controlled = with_actuator_at(twin, options.actuator_floor)?;
    Ok(ControlBasis {
        structure,
        measured,
        plant,
        twin: controlled,
    })
}

/// The LQR designs of the requested weights and of the retune grid (multiples of the smallest
/// q), and the controller's rate: `--substeps`, or from the fastest closed-loop pole of them
/// all (all runs share it).
pub(super) fn design_set(
    plant: &StateSpace,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<DesignSet, ControlError> {
    let mut qs = options.qs.clone();
    qs.sort_by(f64::total_cmp);
    qs.dedup();
    let designs = qs
        .iter()
        .map(|&q| design(plant, q, options.r))
        .collect::<Result<Vec<_>, _>>()?;
    // The retune grid's designs fix the controller's rate too (all runs share it).
    let retune = match &options.retune {
        Some(_) => RETUNE_GRID
            .iter()
            .map(|m| design(plant, qs[0] * m, options.r))
            .collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    let all: Vec<Design> = designs.iter().chain(&retune).cloned().collect();
    let substeps = match options.substeps {
        Some(n) if n >= 1 => n,
        Some(n) => {
            return Err(ControlError::Options(format!(
                "--substeps must be at least 1, got {n}"
            )))
        }
        None => substeps_for(&all, data.dt),
    };
    Ok(DesignSet {
        qs,
        designs,
        retune,
        substeps,
    })
}

/// The sensor noise (`--sensor-noise`, one value or one per measured channel, else the
/// controlled twin's calibrated noise when it has one for every channel read), the gaps watched
/// (the twin's contacts, then `--gap`'s on other storeys), the estimator and the resonances.
pub(super) fn loop_plan(
    basis: &ControlBasis,
    data: &Measurement,
    options: &ControlOptions,
) -> Result<LoopPlan, ControlError> {
    let twin = &basis.twin;
    let measured = &basis.measured;
    let channels = measured.len();
    let noise_sd: Option<Vec<f64>> = match &options.sensor_noise {
        Some(sd) if sd.len() == 1 => Some(vec![sd[0]; channels]),
        Some(sd) if sd.len() == channels => Some(sd.clone()),
        Some(sd) => {
            return Err(ControlError::Options(format!(
                "the sensor noise has {} values: give one, or one per measured channel \
                 ({channels}: {})",
                sd.len(),
                names(measured)
            )))
        }
        // The twin's calibrated noise, when it has one for every channel read.
        None => measured
            .iter()
            .map(|c| twin.noise_variance_of(*c).map(|x| x.max(0.0).sqrt()))
            .collect(),
    };
    let mut gaps = closed_loop::twin_gaps(twin);
    for g in &options.gaps {
        if !gaps.iter().any(|h| h.storey == g.storey) {
            gaps.push(g.clone());
        }
    }
    let estimator = estimator_of(
        options.estimator,
        options,
        noise_sd.as_deref(),
        data,
        measured,
    );
    Ok(LoopPlan {
        noise_sd,
        gaps,
        estimator,
        resonances: basis.structure.natural_frequencies(),
    })
}

/// The runner of every run: the loop's settings on the controlled twin, and the number of runs
/// the options ask for (the progress counts them).
pub(super) fn runner<'a>(
    basis: &'a ControlBasis,
    data: &'a Measurement,
    options: &ControlOptions,
    set: &DesignSet,
    plan: &LoopPlan,
    progress: &'a mut dyn FnMut(u64, u64),
) -> Runner<'a> {
    let setup = LoopSetup {
        plant: basis.plant.clone(),
        measured: basis.measured.clone(),
        substeps: set.substeps,
        noise: plan.noise_sd.clone().map(|sd| SensorNoise {
            sd,
            seed: options.seed,
        }),
        gaps: plan.gaps.clone(),
        force_limit: force_limit(&basis.structure, data),
        corrector: false,
    };
    let runs_total = 1
        + set.designs.len()
        + set.retune.len()
        + usize::from(options.schedule.is_some())
        + if options.estimator_costs { 2 } else { 0 };
    Runner {
        twin: &basis.twin,
        data,
        setup,
        estimator: plan.estimator.clone(),
        resonances: plan.resonances.clone(),
        passive_peaks: Vec::new(),
        progress,
        runs_done: 0,
        runs_total: runs_total as u64,
    }
}

/// Run each requested design, in the order of q.
pub(super) fn run_designs(
    runner: &mut Runner,
    designs: Vec<Design>,
) -> Result<DesignRuns, ControlError> {
    let mut runs = DesignRuns::default();
    for d in designs {
        let (run, response) = runner.design_run(d, "requested")?;
        runs.push(run, response);
    }
    Ok(runs)
}

/// The record can drive the structure: its excitation is the structure's (a force, or a ground
/// acceleration), and every response it measures is of a floor the structure has; refused
/// naming the column.
pub fn check_record(data: &Measurement, structure: &Structure) -> Result<(), ControlError> {
    for signal in data.channels() {
        let name = signal.channel.name();
        signal
            .channel
            .check(&name, structure)
            .map_err(|e| ControlError::Options(format!("{}: {e}", data.path.display())))?;
    }
    Ok(())
}

/// A control force beyond this stops a run as unstable: a thousand times the record's peak
/// excitation as a force (a ground acceleration times the structure's mass).
pub(super) fn force_limit(structure: &Structure, data: &Measurement) -> f64 {
    let peak = data
        .excitation
        .values
        .iter()
        .fold(0.0f64, |m, f| m.max(f.abs()));
    let per_unit = match structure.excitation {
        structure::Excitation::Force { .. } => 1.0,
        structure::Excitation::Base => structure.mass.iter().sum(),
    };
    1e3 * (peak * per_unit).max(1e-3)
}
