//! The synthetic structure's equations beside the shear model: the Bouc–Wen hysteresis.

use fmu_shear::effects::{add_storey_force, drift, Floors};
use fmu_shear::ShearModel;
use numerics::ode::rk4_with_events;

use super::scenario::EffectSpec;

// ---------------------------------------------------------------------------------------------
// Hysteresis (Bouc–Wen): not in the FMU's library, integrated here beside the model
// ---------------------------------------------------------------------------------------------

/// One storey's Bouc–Wen law (see the module documentation).
#[derive(Clone, Copy, Debug)]
pub(super) struct BoucWen {
    /// Index in the scenario's effects.
    pub(super) effect: usize,
    /// 0-based storey (0 = ground–floor 1).
    pub(super) storey: usize,
    pub(super) stiffness: f64,
    pub(super) yield_drift: f64,
    pub(super) beta: f64,
    pub(super) gamma: f64,
    pub(super) exponent: f64,
}

impl BoucWen {
    /// `ż = δ̇ (1 − (β sign(δ̇ z) + γ) |z / z_y|ⁿ)`.
    #[inline]
    fn z_rate(&self, drift_rate: f64, z: f64) -> f64 {
        let product = drift_rate * z;
        let sign = if product > 0.0 {
            1.0
        } else if product < 0.0 {
            -1.0
        } else {
            0.0
        };
        let ratio = (z / self.yield_drift).abs();
        let power = if self.exponent == 2.0 {
            ratio * ratio
        } else {
            ratio.powf(self.exponent)
        };
        drift_rate * (1.0 - (self.beta * sign + self.gamma) * power)
    }
    /// The bound of |z|: `z_y (1 / (β + γ))^(1/n)`.
    pub(super) fn saturation(&self) -> f64 {
        self.yield_drift * (1.0 / (self.beta + self.gamma)).powf(1.0 / self.exponent)
    }
}

/// At most one hysteresis effect per storey (validation refuses two at one storey).
const MAX_LAWS: usize = 3;
/// The state with hysteresis: `[y1..y3, ẏ1..ẏ3, z per law, ∫ k_h z dδ per law]`.
type HState = [f64; 6 + 2 * MAX_LAWS];
const Z0: usize = 6;
const W0: usize = 6 + MAX_LAWS;

/// The hysteresis effects' states, and the structure's steps with them. Without hysteresis it
/// steps the model by [`ShearModel::advance`], exactly as before it existed.
pub(super) struct Hysteretic {
    pub(super) laws: Vec<BoucWen>,
    pub(super) z: [f64; MAX_LAWS],
    pub(super) work: [f64; MAX_LAWS],
    pub(super) max_abs_z: [f64; MAX_LAWS],
}

impl Hysteretic {
    pub(super) fn new(effects: &[EffectSpec]) -> Self {
        let laws = effects
            .iter()
            .enumerate()
            .filter_map(|(effect, e)| match *e {
                EffectSpec::Hysteresis {
                    storey,
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                } => Some(BoucWen {
                    effect,
                    storey: storey - 1,
                    stiffness,
                    yield_drift,
                    beta,
                    gamma,
                    exponent,
                }),
                _ => None,
            })
            .take(MAX_LAWS)
            .collect();
        Hysteretic {
            laws,
            z: [0.0; MAX_LAWS],
            work: [0.0; MAX_LAWS],
            max_abs_z: [0.0; MAX_LAWS],
        }
    }

    /// Subtract the hysteretic storey forces `k_h z` from the accelerations `a`.
    #[inline]
    fn add_to(&self, model: &ShearModel, z: &[f64], a: &mut Floors) {
        let mut g = [0.0; 3];
        for (law, &z) in self.laws.iter().zip(z) {
            add_storey_force(law.storey, law.stiffness * z, &mut g);
        }
        for f in 0..3 {
            a[f] -= g[f] / model.params.mass[f];
        }
    }

    /// The floor accelerations of the model's state and these z.
    pub(super) fn acceleration(&self, model: &ShearModel, input: f64) -> Floors {
        let mut a = model.acceleration(&model.displacement, &model.velocity, input);
        if !self.laws.is_empty() {
            self.add_to(model, &self.z, &mut a);
        }
        a
    }

    #[inline]
    fn rhs(&self, model: &ShearModel, x: &HState, input: f64) -> HState {
        let y = [x[0], x[1], x[2]];
        let v = [x[3], x[4], x[5]];
        let mut a = model.acceleration(&y, &v, input);
        self.add_to(model, &x[Z0..Z0 + self.laws.len()], &mut a);
        let mut dx = [0.0; 6 + 2 * MAX_LAWS];
        dx[..3].copy_from_slice(&v);
        dx[3..6].copy_from_slice(&a);
        for (i, law) in self.laws.iter().enumerate() {
            let z = x[Z0 + i];
            let rate = drift(&v, law.storey);
            dx[Z0 + i] = law.z_rate(rate, z);
            dx[W0 + i] = law.stiffness * z * rate;
        }
        dx
    }

    /// Where the vector field has kinks: the contacts' gaps and each law's `δ̇ z`.
    fn switches(&self, model: &ShearModel, x: &HState) -> ([f64; 6 + MAX_LAWS], usize) {
        let contact = model.effects.switches(&[x[0], x[1], x[2]]);
        let mut out = [0.0; 6 + MAX_LAWS];
        out[..contact.len].copy_from_slice(&contact.values[..contact.len]);
        let mut len = contact.len;
        for (i, law) in self.laws.iter().enumerate() {
            out[len] = drift(&[x[3], x[4], x[5]], law.storey) * x[Z0 + i];
            len += 1;
        }
        (out, len)
    }

    /// RK4 over `[0, h]` with the input `u0 + slope·τ`, `substeps` sub-steps, each split just
    /// past every sign change of a switch (numerics' stepper, as the shear FMU's contact steps).
    fn step(&self, model: &ShearModel, x: &HState, u0: f64, slope: f64, h: f64) -> HState {
        rk4_with_events(
            |tau: f64, x: &HState| self.rhs(model, x, u0 + slope * tau),
            |x: &HState| {
                let (values, len) = self.switches(model, x);
                SwitchList { values, len }
            },
            x,
            h,
            model.params.substeps,
        )
    }

    /// [`ShearModel::advance`] with the hysteresis: the same inputs, the same end-of-step
    /// bookkeeping (the input ends at its ramp's end value, slope 0).
    pub(super) fn advance(&mut self, model: &mut ShearModel, h: f64) {
        if self.laws.is_empty() {
            model.advance(h);
            return;
        }
        let u0 = model.force.value - model.control_force.value;
        let slope = model.force.slope - model.control_force.slope;
        let mut x = [0.0; 6 + 2 * MAX_LAWS];
        x[..3].copy_from_slice(&model.displacement);
        x[3..6].copy_from_slice(&model.velocity);
        x[Z0..W0].copy_from_slice(&self.z);
        x[W0..].copy_from_slice(&self.work);
        let x = self.step(model, &x, u0, slope, h);
        model.displacement = [x[0], x[1], x[2]];
        model.velocity = [x[3], x[4], x[5]];
        self.z.copy_from_slice(&x[Z0..W0]);
        self.work.copy_from_slice(&x[W0..]);
        for input in [&mut model.force, &mut model.control_force] {
            input.value += input.slope * h;
            input.slope = 0.0;
        }
    }

    pub(super) fn observe(&mut self) {
        for i in 0..self.laws.len() {
            self.max_abs_z[i] = self.max_abs_z[i].max(self.z[i].abs());
        }
    }
}

/// The switch values of [`Hysteretic::switches`], as numerics' stepper reads them.
struct SwitchList {
    values: [f64; 6 + MAX_LAWS],
    len: usize,
}

impl AsRef<[f64]> for SwitchList {
    fn as_ref(&self) -> &[f64] {
        &self.values[..self.len]
    }
}
