//! The synthetic structure's equations beside the shear model: the Bouc–Wen hysteresis and
//! the quadratic (velocity-squared) damping, effects the FMU's library lacks.

use ::structure::effects::{add_storey_force, drift};
use fmu_shear::ShearModel;
use numerics::ode::rk4_with_events;

use super::scenario::{DampingSite, EffectSpec};

/// Displacements or velocities of the paper rig's three floors.
type Floors = [f64; 3];

// ---------------------------------------------------------------------------------------------
// Quadratic damping: not in the FMU's library, integrated here beside the model
// ---------------------------------------------------------------------------------------------

/// One quadratic damper: the force `c₂ · v |v|` of a storey's relative velocity (a storey
/// force, positive resisting) or of a floor's velocity (to the ground).
#[derive(Clone, Copy, Debug)]
pub(super) struct QuadraticDamper {
    /// Index in the scenario's effects.
    pub(super) effect: usize,
    pub(super) site: DampingSite,
    /// c₂, N s²/m².
    pub(super) coefficient: f64,
}

impl QuadraticDamper {
    /// The velocity the damper sees: the storey's `v_s − v_{s−1}` or the floor's `v_f`.
    #[inline]
    fn velocity(&self, v: &Floors) -> f64 {
        match self.site {
            DampingSite::Storey(s) => drift(v, s - 1),
            DampingSite::Floor(f) => v[f - 1],
        }
    }
    /// Add its force `c₂ v |v|` (resisting) to the floors' restoring forces `g`; the power it
    /// dissipates, `c₂ |v|³`.
    #[inline]
    fn add_to(&self, v: &Floors, g: &mut Floors) -> f64 {
        let u = self.velocity(v);
        let f = self.coefficient * u * u.abs();
        match self.site {
            DampingSite::Storey(s) => add_storey_force(s - 1, f, g),
            DampingSite::Floor(fl) => g[fl - 1] += f,
        }
        f * u
    }
}

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
/// At most one quadratic damper per storey and per floor (validation refuses two at one site).
const MAX_DAMPERS: usize = 6;
/// The state beside the model: `[y1..y3, ẏ1..ẏ3, z per law, ∫ k_h z dδ per law, ∫ c₂ |v|³ dt
/// per damper]`. Entries of absent laws and dampers stay 0 (their rates are 0), so the other
/// entries are stepped exactly as without them.
type HState = [f64; 6 + 2 * MAX_LAWS + MAX_DAMPERS];
const Z0: usize = 6;
const W0: usize = 6 + MAX_LAWS;
const E0: usize = 6 + 2 * MAX_LAWS;

/// The hysteresis effects' and quadratic dampers' states, and the structure's steps with them.
/// Without either it steps the model by [`ShearModel::advance`], exactly as before they
/// existed.
pub(super) struct Hysteretic {
    pub(super) laws: Vec<BoucWen>,
    pub(super) z: [f64; MAX_LAWS],
    pub(super) work: [f64; MAX_LAWS],
    pub(super) max_abs_z: [f64; MAX_LAWS],
    pub(super) dampers: Vec<QuadraticDamper>,
    /// Per damper, the energy it dissipated so far, `∫ c₂ |v|³ dt`, J.
    pub(super) dissipated: [f64; MAX_DAMPERS],
    /// Per damper, the largest |v| it saw on the fine grid, m/s.
    pub(super) max_abs_velocity: [f64; MAX_DAMPERS],
}

impl Hysteretic {
    pub(super) fn new(effects: &[EffectSpec]) -> Self {
        let dampers = effects
            .iter()
            .enumerate()
            .filter_map(|(effect, e)| match *e {
                EffectSpec::QuadraticDamping { site, coefficient } => Some(QuadraticDamper {
                    effect,
                    site,
                    coefficient,
                }),
                _ => None,
            })
            .take(MAX_DAMPERS)
            .collect();
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
            dampers,
            dissipated: [0.0; MAX_DAMPERS],
            max_abs_velocity: [0.0; MAX_DAMPERS],
        }
    }

    /// Whether anything is integrated beside the model.
    fn is_empty(&self) -> bool {
        self.laws.is_empty() && self.dampers.is_empty()
    }

    /// Subtract the hysteretic storey forces `k_h z` and the dampers' forces at the velocities
    /// `v` from the accelerations `a`; the power each damper dissipates, in `power`.
    #[inline]
    fn add_to(&self, model: &ShearModel, z: &[f64], v: &Floors, a: &mut Floors, power: &mut [f64]) {
        let mut g = [0.0; 3];
        for (law, &z) in self.laws.iter().zip(z) {
            add_storey_force(law.storey, law.stiffness * z, &mut g);
        }
        for (damper, p) in self.dampers.iter().zip(power) {
            *p = damper.add_to(v, &mut g);
        }
        for f in 0..3 {
            a[f] -= g[f] / model.params.mass[f];
        }
    }

    /// The floor accelerations of the model's state, these z and the dampers.
    pub(super) fn acceleration(&self, model: &ShearModel, input: f64) -> Floors {
        let mut a = [0.0; 3];
        model.accelerations_into(&model.displacement, &model.velocity, input, 0.0, &mut a);
        if !self.is_empty() {
            let mut power = [0.0; MAX_DAMPERS];
            let v = std::array::from_fn(|i| model.velocity[i]);
            self.add_to(model, &self.z, &v, &mut a, &mut power);
        }
        a
    }

    #[inline]
    fn rhs(&self, model: &ShearModel, x: &HState, input: f64) -> HState {
        let y = [x[0], x[1], x[2]];
        let v = [x[3], x[4], x[5]];
        let mut a = [0.0; 3];
        model.accelerations_into(&y, &v, input, 0.0, &mut a);
        let mut dx = [0.0; 6 + 2 * MAX_LAWS + MAX_DAMPERS];
        self.add_to(
            model,
            &x[Z0..Z0 + self.laws.len()],
            &v,
            &mut a,
            &mut dx[E0..E0 + self.dampers.len()],
        );
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
        let mut len = contact.values.len();
        out[..len].copy_from_slice(&contact.values);
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

    /// [`ShearModel::advance`] with the hysteresis and the dampers: the same inputs, the same
    /// end-of-step bookkeeping (the input ends at its ramp's end value, slope 0). The dampers'
    /// force is smooth (C¹: `v |v|`), so they add no switch.
    pub(super) fn advance(&mut self, model: &mut ShearModel, h: f64) {
        if self.is_empty() {
            model.advance(h);
            return;
        }
        let u0 = model.force.value - model.control_force.value;
        let slope = model.force.slope - model.control_force.slope;
        let mut x = [0.0; 6 + 2 * MAX_LAWS + MAX_DAMPERS];
        x[..3].copy_from_slice(&model.displacement);
        x[3..6].copy_from_slice(&model.velocity);
        x[Z0..W0].copy_from_slice(&self.z);
        x[W0..E0].copy_from_slice(&self.work);
        x[E0..].copy_from_slice(&self.dissipated);
        let x = self.step(model, &x, u0, slope, h);
        model.displacement.copy_from_slice(&x[..3]);
        model.velocity.copy_from_slice(&x[3..6]);
        self.z.copy_from_slice(&x[Z0..W0]);
        self.work.copy_from_slice(&x[W0..E0]);
        self.dissipated.copy_from_slice(&x[E0..]);
        for input in [&mut model.force, &mut model.control_force] {
            input.value += input.slope * h;
            input.slope = 0.0;
        }
    }

    pub(super) fn observe(&mut self, model: &ShearModel) {
        for i in 0..self.laws.len() {
            self.max_abs_z[i] = self.max_abs_z[i].max(self.z[i].abs());
        }
        for (i, damper) in self.dampers.iter().enumerate() {
            let v = damper
                .velocity(&std::array::from_fn(|i| model.velocity[i]))
                .abs();
            self.max_abs_velocity[i] = self.max_abs_velocity[i].max(v);
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
