//! The LQR controller as a zero-time block of the master: inputs the measured channels (through
//! sampled connections: what the sensors read as the last step left the structure), in the
//! order of the controller's model, and the excitation (a force, or a ground acceleration); outputs the control force `f_c = K ŵ` for the shear FMU's `control_force`,
//! held over the next step (the command computed a sample ago: see `numerics::lqr::Controller`),
//! and which gain is on. The law itself is `numerics::lqr`, shared with
//! the controller FMU.

use numerics::lqr::{Controller, Scheduler};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::cosim::master::{Block, MasterError};

/// Gain scheduling inside the block: the scheduler and the gains it switches between.
pub struct Scheduled {
    pub scheduler: Scheduler,
    pub low: Vec<f64>,
    pub high: Vec<f64>,
}

/// Sensor noise added to what the controller reads (the structure's own outputs are
/// noise-free): an sd per measured channel (in its SI unit) and a seed, so runs repeat.
#[derive(Clone, Debug)]
pub struct SensorNoise {
    pub sd: Vec<f64>,
    pub seed: u64,
}

pub struct LqrBlock {
    controller: Controller,
    /// How many of a corrector's latent variances (for the schedule, one per floor) follow
    /// the excitation among the inputs; None: none.
    latent: Option<usize>,
    scheduled: Option<Scheduled>,
    noise: Option<(ChaCha8Rng, Vec<f64>)>,
    /// A control force beyond this (N) means the loop has gone unstable: the run stops.
    force_limit: f64,
    last: Option<(f64, Vec<f64>)>,
}

/// The schedule's triggers at a point as one output: 1 the drift, 2 the latent variance, 3 both.
pub fn trigger_code(t: numerics::lqr::Triggers) -> f64 {
    f64::from(u8::from(t.drift) + 2 * u8::from(t.variance))
}

impl LqrBlock {
    /// The measured channels, then the excitation; then, with `latent`, `latent_var1..N`:
    /// for a controller reading `measured` channels, the inputs before the latent variances.
    pub fn inputs(measured: usize) -> usize {
        measured + 1
    }
    /// `control_force`, `high_gain` (1 when the scheduler has the high gain on), the schedule's
    /// triggers ([`trigger_code`]).
    pub const OUTPUTS: usize = 3;

    pub fn new(
        controller: Controller,
        scheduled: Option<Scheduled>,
        noise: Option<SensorNoise>,
        force_limit: f64,
        latent: Option<usize>,
    ) -> Self {
        // A negative or non-finite sd reads as no noise on that floor.
        let noise = noise.map(|n| {
            (
                ChaCha8Rng::seed_from_u64(n.seed),
                n.sd.iter()
                    .map(|&sd| if sd.is_finite() { sd.max(0.0) } else { 0.0 })
                    .collect(),
            )
        });
        LqrBlock {
            controller,
            latent,
            scheduled,
            noise,
            force_limit,
            last: None,
        }
    }
}

impl Block for LqrBlock {
    fn evaluate(
        &mut self,
        time: f64,
        inputs: &[f64],
        outputs: &mut [f64],
    ) -> Result<(), MasterError> {
        let measured = self.controller.measurements();
        let now = &inputs[..Self::inputs(measured)];
        if let Some((t, seen)) = &self.last {
            // The law has state: one sample per communication point. Sampled inputs do not
            // move inside a point, so a second call there can only be a wiring mistake.
            if *t == time {
                if seen == now {
                    return Ok(());
                }
                return Err(MasterError::Config(
                    "the LQR block's inputs changed inside a communication point: connect the \
                     accelerations with `connect_sampled`"
                        .into(),
                ));
            }
        }
        self.last = Some((time, now.to_vec()));
        let force = inputs[measured];
        let mut acc = inputs[..measured].to_vec();
        if let Some((rng, sd)) = &mut self.noise {
            for (a, s) in acc.iter_mut().zip(sd.iter()) {
                let z: f64 = StandardNormal.sample(rng);
                *a += s * z;
            }
        }
        if acc.iter().chain([&force]).any(|v| !v.is_finite()) {
            return Err(MasterError::Config(format!(
                "the controller read a non-finite measurement at t = {time} s: {acc:?}, force {force}"
            )));
        }
        self.controller
            .observe(&acc, force)
            .map_err(|e| MasterError::Config(format!("the controller at t = {time} s: {e}")))?;
        let (mut high, mut triggers) = (0.0, 0.0);
        if let Some(s) = &mut self.scheduled {
            let at = Self::inputs(measured);
            let latent = self.latent.map(|n| &inputs[at..at + n]);
            let on = s
                .scheduler
                .decide(time, &self.controller.estimate_si(), latent);
            self.controller
                .set_gain(if on { &s.high } else { &s.low })
                .map_err(|e| MasterError::Config(format!("the gain schedule: {e}")))?;
            high = f64::from(u8::from(on));
            triggers = trigger_code(s.scheduler.triggers());
        }
        self.controller.output();
        let force = self.controller.acting();
        if !force.is_finite() || force.abs() > self.force_limit {
            return Err(MasterError::Config(format!(
                "closed loop unstable: the control force reached {force:.3e} N at t = {time} s \
                 (limit {:.3e} N)",
                self.force_limit
            )));
        }
        outputs[0] = force;
        outputs[1] = high;
        outputs[2] = triggers;
        Ok(())
    }
}
