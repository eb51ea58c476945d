//! The record's integration: the fine grid, the structure as the record starts, its parameter
//! changes in time, the in-loop controller, and the stepping loop that records the response.

use super::scenario::{Change, ChangeHow, Scenario};
use super::structure::Hysteretic;
use super::truth::ChangeTruth;
use super::truth::Stats;
use super::{
    floor_accelerations, HysteresisTrace, InLoopController, Result, SynthError,
    CONTROL_SENSOR_STREAM,
};
use ::structure::channel::{Channel, Quantity, Unit};
use ::structure::effects::drift;
use fmu_shear::effects::Effects;
use fmu_shear::{ShearModel, ShearParameters};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// The record's grid: `n` samples `dt` apart, each interval `os` fine steps of `hf`.
#[derive(Clone, Copy)]
pub(super) struct FineGrid {
    pub(super) n: usize,
    pub(super) os: usize,
    pub(super) dt: f64,
    pub(super) hf: f64,
}

impl FineGrid {
    pub(super) fn of(s: &Scenario) -> FineGrid {
        let n = s.samples();
        let os = s.oversample as usize;
        let dt = s.dt();
        FineGrid {
            n,
            os,
            dt,
            hf: dt / os as f64,
        }
    }
}

/// The structure as the record starts: the model with the library's effects (its own step
/// is the fine step), and beside it the effects the library lacks (see `Hysteretic`).
pub(super) fn structure_model(s: &Scenario) -> (ShearModel, Hysteretic) {
    let mut effects = Effects::new(s.storeys());
    for e in &s.effects {
        // Hysteresis and quadratic damping are not in the library: integrated here, beside the
        // model (see `Hysteretic`).
        if let Some((_, location, law)) = e.library() {
            effects.switch_on(location, law);
        }
    }
    let hysteretic = Hysteretic::new(&s.effects);
    let params = ShearParameters {
        substeps: 1,
        ..ShearParameters::from_structure(&s.structure())
    };
    (ShearModel::new(params, effects), hysteretic)
}

/// The scenario's parameter changes in time order (stable: equal times keep the scenario's
/// order), the next one to apply, and what each applied did.
pub(super) struct Changes<'a> {
    pub(super) list: Vec<&'a Change>,
    pub(super) next: usize,
    pub(super) truth: Vec<ChangeTruth>,
}

impl<'a> Changes<'a> {
    pub(super) fn of(s: &'a Scenario) -> Changes<'a> {
        let mut list: Vec<&Change> = s.changes.iter().collect();
        list.sort_by(|a, b| a.at.total_cmp(&b.at));
        Changes {
            list,
            next: 0,
            truth: Vec::new(),
        }
    }

    /// The time of the next change, when it is due by `t`.
    pub(super) fn due(&self, t: f64) -> Option<f64> {
        match self.list.get(self.next) {
            Some(c) if c.at <= t => Some(c.at),
            _ => None,
        }
    }

    /// Apply the next change to the model's parameters and keep what it did.
    pub(super) fn apply_next(&mut self, model: &mut ShearModel) {
        let c = self.list[self.next];
        let slot = c.parameter.slot(&mut model.params);
        let before = *slot;
        *slot = match c.how {
            ChangeHow::Factor(f) => before * f,
            ChangeHow::Value(x) => x,
        };
        self.truth.push(ChangeTruth {
            at: c.at,
            parameter: c.parameter.name(),
            factor: match c.how {
                ChangeHow::Factor(f) => Some(f),
                ChangeHow::Value(_) => None,
            },
            before,
            after: *slot,
        });
        self.next += 1;
    }
}

/// The controller in the loop as the integration runs it: it reads every `period` fine steps
/// (its sensors' noise drawn from `rng`), and `at_samples` keeps its force at each sample.
pub(super) struct ControlLoop {
    pub(super) controller: numerics::lqr::Controller,
    pub(super) sensor_sd: Vec<f64>,
    pub(super) period: usize,
    pub(super) rng: ChaCha8Rng,
    pub(super) at_samples: Vec<f64>,
}

impl ControlLoop {
    /// The controller built for its reading interval (a whole number of fine steps); refused
    /// when the interval is not positive or the controller cannot be built.
    pub(super) fn of(
        control: Option<InLoopController>,
        grid: FineGrid,
    ) -> Result<Option<ControlLoop>> {
        let Some(c) = control else {
            return Ok(None);
        };
        if !(c.interval.is_finite() && c.interval > 0.0) {
            return Err(SynthError::Record(format!(
                "the controller's interval must be positive, got {} s",
                c.interval
            )));
        }
        // The controller reads every `period` fine steps.
        let period = ((c.interval / grid.hf).round() as usize).max(1);
        let controller = (c.make)(period as f64 * grid.hf).map_err(SynthError::Record)?;
        let mut rng = ChaCha8Rng::seed_from_u64(c.seed);
        rng.set_stream(CONTROL_SENSOR_STREAM);
        Ok(Some(ControlLoop {
            controller,
            sensor_sd: c.sensor_sd,
            period,
            rng,
            at_samples: vec![0.0; grid.n],
        }))
    }

    /// A reading at `time` under the excitation `force`, with the sensors' noise: the
    /// controller's new force acts until the next reading; a controller that fails or gives a
    /// non-finite force stops the record.
    pub(super) fn read(
        &mut self,
        model: &mut ShearModel,
        hysteretic: &Hysteretic,
        force: f64,
        time: f64,
    ) -> Result<()> {
        // The sensors read the structure as it is, under the force held so far.
        let a = hysteretic.acceleration(model, force);
        let measured: Vec<f64> = a
            .iter()
            .zip(self.sensor_sd.iter())
            .map(|(a, sd)| {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                a + sd * z
            })
            .collect();
        self.controller.step(&measured, force).map_err(|e| {
            SynthError::Record(format!(
                "the controller in the loop at t = {time:.6} s: {e}"
            ))
        })?;
        let u = self.controller.acting();
        if !u.is_finite() {
            return Err(SynthError::Record(format!(
                "the controller in the loop gave a non-finite force at t = {time:.6} s"
            )));
        }
        model.control_force.value = u;
        model.control_force.slope = 0.0;
        Ok(())
    }
}

/// The integration of the structure over the record, sample by sample, each sample interval
/// in fine steps, with the changes at their times and the controller (if any) in the loop.
pub(super) struct Integration<'a> {
    pub(super) s: &'a Scenario,
    pub(super) grid: FineGrid,
    pub(super) fine_force: &'a [f64],
    pub(super) channels: &'a [(Channel, Unit)],
    pub(super) model: ShearModel,
    pub(super) hysteretic: Hysteretic,
    pub(super) changes: Changes<'a>,
    pub(super) control: Option<ControlLoop>,
    /// The library's effects held back until their start (`Scenario::effects_from`).
    pub(super) dormant: Option<Effects>,
    pub(super) stats: Stats,
    pub(super) clean_acc: Vec<Vec<f64>>,
    pub(super) clean_force: Vec<f64>,
    pub(super) traces: Vec<HysteresisTrace>,
}

/// What the integration gave: the noise-free samples and hysteresis traces, the structure as
/// it ended (and the effects beside it), what the fine grid saw, the changes applied, and the
/// control force at each sample (with a controller in the loop).
pub(super) struct Integrated {
    pub(super) clean_acc: Vec<Vec<f64>>,
    pub(super) clean_force: Vec<f64>,
    pub(super) traces: Vec<HysteresisTrace>,
    pub(super) model: ShearModel,
    pub(super) hysteretic: Hysteretic,
    pub(super) stats: Stats,
    pub(super) changes: Vec<ChangeTruth>,
    pub(super) control: Option<Vec<f64>>,
}

impl<'a> Integration<'a> {
    /// The structure at rest at the record's start, the changes and the controller ready.
    pub(super) fn new(
        s: &'a Scenario,
        grid: FineGrid,
        fine_force: &'a [f64],
        channels: &'a [(Channel, Unit)],
        control: Option<InLoopController>,
    ) -> Result<Integration<'a>> {
        let n = grid.n;
        let (mut model, hysteretic) = structure_model(s);
        let dormant = (s.effects_from > 0.0)
            .then(|| std::mem::replace(&mut model.effects, Effects::new(s.storeys())));
        let traces: Vec<HysteresisTrace> = hysteretic
            .laws
            .iter()
            .map(|law| HysteresisTrace {
                effect: law.effect,
                storey: law.storey + 1,
                z: Vec::with_capacity(n),
                drift: Vec::with_capacity(n),
                work: Vec::with_capacity(n),
            })
            .collect();
        let changes = Changes::of(s);
        let stats = Stats::new(&s.effects, s.storeys());
        let control = ControlLoop::of(control, grid)?;
        Ok(Integration {
            s,
            grid,
            fine_force,
            channels,
            model,
            hysteretic,
            changes,
            control,
            dormant,
            stats,
            clean_acc: vec![vec![0.0; n]; channels.len()],
            clean_force: vec![0.0; n],
            traces,
        })
    }

    /// Integrate over the record: at each sample the changes due, then the sample, then (but
    /// after the last) the interval's fine steps.
    pub(super) fn run(mut self) -> Result<Integrated> {
        let FineGrid { n, os, hf, .. } = self.grid;
        for k in 0..n {
            let j0 = k * os;
            if self.dormant.is_some() && j0 as f64 * hf >= self.s.effects_from - 1e-9 {
                // The effects start: the model's caches were for the linear structure.
                self.model.effects = self.dormant.take().expect("dormant effects");
                self.model.contact_maps = None;
            }
            while self.changes.due(j0 as f64 * hf).is_some() {
                self.changes.apply_next(&mut self.model);
            }
            self.sample(k, j0);
            if k + 1 == n {
                break;
            }
            for j in j0..j0 + os {
                self.fine_step(k, j0, j)?;
            }
        }
        Ok(self.finish())
    }

    /// Sample `k` (fine point `j0`): the response channels, the hysteresis traces and the
    /// excitation, noise-free, and the largest floor accelerations so far.
    pub(super) fn sample(&mut self, k: usize, j0: usize) {
        let (model, hysteretic) = (&self.model, &self.hysteretic);
        let a = floor_accelerations(self.s, hysteretic, model, self.fine_force[j0]);
        for (f, a) in a.iter().enumerate() {
            self.stats.max_acc[f] = self.stats.max_acc[f].max(a.abs());
        }
        for (c, (channel, _)) in self.channels.iter().enumerate() {
            if let Channel::Response { quantity, floor } = *channel {
                self.clean_acc[c][k] = match quantity {
                    Quantity::Velocity => model.velocity[floor - 1],
                    Quantity::Displacement => model.displacement[floor - 1],
                    _ => a[floor - 1],
                };
            }
        }
        for (i, trace) in self.traces.iter_mut().enumerate() {
            trace.z.push(hysteretic.z[i]);
            trace
                .drift
                .push(drift(&model.displacement, trace.storey - 1));
            trace.work.push(hysteretic.work[i]);
        }
        self.clean_force[k] = self.fine_force[j0];
    }

    /// Fine step `j` of sample interval `k` (which starts at fine point `j0`): the controller's
    /// reading when one is due, the force linear over the step, the step split at each change
    /// due in it; a non-finite state stops the record.
    pub(super) fn fine_step(&mut self, k: usize, j0: usize, j: usize) -> Result<()> {
        let (fine_force, hf) = (self.fine_force, self.grid.hf);
        let model = &mut self.model;
        let (t0, t1) = (j as f64 * hf, (j + 1) as f64 * hf);
        let next = if j + 1 < fine_force.len() {
            fine_force[j + 1]
        } else {
            fine_force[0]
        };
        if let Some(control) = &mut self.control {
            if j % control.period == 0 {
                control.read(model, &self.hysteretic, fine_force[j], j as f64 * hf)?;
            }
            if j == j0 {
                control.at_samples[k] = model.control_force.value;
            }
        }
        model.force.value = fine_force[j];
        model.force.slope = (next - fine_force[j]) / hf;
        let mut t = t0;
        while let Some(at) = self.changes.due(t1) {
            if at > t {
                self.hysteretic.advance(model, at - t);
                t = at;
            }
            self.changes.apply_next(model);
        }
        if t1 > t {
            self.hysteretic.advance(model, t1 - t);
        }
        let finite = model
            .displacement
            .iter()
            .chain(&model.velocity)
            .chain(&self.hysteretic.z)
            .all(|x| x.is_finite());
        if !finite {
            return Err(SynthError::Record(format!(
                "the synthetic structure diverged at t = {t1:.6} s (non-finite state); check the parameters and effects, or raise oversample (now {})",
                self.s.oversample
            )));
        }
        self.stats.observe(model, t1, hf);
        self.hysteretic.observe(model);
        Ok(())
    }

    /// What the integration gave; the last sample's control force is as the controller left
    /// it.
    pub(super) fn finish(self) -> Integrated {
        let n = self.grid.n;
        let model = self.model;
        let control = self.control.map(|c| {
            let mut cs = c.at_samples;
            if n > 0 {
                cs[n - 1] = model.control_force.value;
            }
            cs
        });
        Integrated {
            clean_acc: self.clean_acc,
            clean_force: self.clean_force,
            traces: self.traces,
            model,
            hysteretic: self.hysteretic,
            stats: self.stats,
            changes: self.changes.truth,
            control,
        }
    }
}
