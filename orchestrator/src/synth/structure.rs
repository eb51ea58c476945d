//! The synthetic structure's equations beside the shear model: the Bouc–Wen hysteresis and
//! the quadratic (velocity-squared) damping, effects the FMU's library lacks.

use ::structure::effects::{add_storey_force, drift};
use ::structure::Excitation;
use fmu_shear::ShearModel;
use numerics::ode::rk4_with_events;

use super::scenario::{DampingSite, EffectSpec};

/// Displacements or velocities of the building's floors 1..N.
type Floors = [f64];

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

/// The state beside the model: `[y1..yN, ẏ1..ẏN, z per law, ∫ k_h z dδ per law, ∫ c₂ |v|³ dt
/// per damper]` (at most one law per storey and one damper per storey and per floor: validation
/// refuses two at one site).
type HState = Vec<f64>;

/// Where each part of [`HState`] starts: the velocities, the laws' z, their work and the
/// dampers' energies.
#[derive(Clone, Copy)]
struct Offsets {
    v: usize,
    z: usize,
    w: usize,
    e: usize,
    len: usize,
}

/// The excitation and the control force over a step, each a ramp `value + slope·τ`; when the
/// control force acts at the floor the force excites, their difference is one ramp (the net
/// force on that floor) and the control none, as [`ShearModel::advance`] steps such a building.
#[derive(Clone, Copy)]
struct Inputs {
    excitation: (f64, f64),
    control: (f64, f64),
}

impl Inputs {
    fn of(model: &ShearModel) -> Inputs {
        let (f, c) = (&model.force, &model.control_force);
        match model.params.excitation {
            Excitation::Force { floor } if floor == model.params.control_floor => Inputs {
                excitation: (f.value - c.value, f.slope - c.slope),
                control: (0.0, 0.0),
            },
            _ => Inputs {
                excitation: (f.value, f.slope),
                control: (c.value, c.slope),
            },
        }
    }

    /// The excitation and the control force at `τ` into the step.
    #[inline]
    fn at(&self, tau: f64) -> (f64, f64) {
        (
            self.excitation.0 + self.excitation.1 * tau,
            self.control.0 + self.control.1 * tau,
        )
    }
}

/// The hysteresis effects' and quadratic dampers' states, and the structure's steps with them.
/// Without either it steps the model by [`ShearModel::advance`], exactly as before they
/// existed.
pub(super) struct Hysteretic {
    pub(super) laws: Vec<BoucWen>,
    /// Per law.
    pub(super) z: Vec<f64>,
    pub(super) work: Vec<f64>,
    pub(super) max_abs_z: Vec<f64>,
    pub(super) dampers: Vec<QuadraticDamper>,
    /// Per damper, the energy it dissipated so far, `∫ c₂ |v|³ dt`, J.
    pub(super) dissipated: Vec<f64>,
    /// Per damper, the largest |v| it saw on the fine grid, m/s.
    pub(super) max_abs_velocity: Vec<f64>,
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
            .collect::<Vec<_>>();
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
            .collect::<Vec<_>>();
        Hysteretic {
            z: vec![0.0; laws.len()],
            work: vec![0.0; laws.len()],
            max_abs_z: vec![0.0; laws.len()],
            laws,
            dissipated: vec![0.0; dampers.len()],
            max_abs_velocity: vec![0.0; dampers.len()],
            dampers,
        }
    }

    /// Whether anything is integrated beside the model.
    fn is_empty(&self) -> bool {
        self.laws.is_empty() && self.dampers.is_empty()
    }

    /// Where each part of the state beside a model of `n` storeys starts.
    fn offsets(&self, n: usize) -> Offsets {
        let (v, z) = (n, 2 * n);
        let w = z + self.laws.len();
        let e = w + self.laws.len();
        Offsets {
            v,
            z,
            w,
            e,
            len: e + self.dampers.len(),
        }
    }

    /// Subtract the hysteretic storey forces `k_h z` and the dampers' forces at the velocities
    /// `v` from the accelerations `a`; the power each damper dissipates, in `power`.
    #[inline]
    fn add_to(&self, model: &ShearModel, z: &[f64], v: &Floors, a: &mut Floors, power: &mut [f64]) {
        let mut g = vec![0.0; a.len()];
        for (law, &z) in self.laws.iter().zip(z) {
            add_storey_force(law.storey, law.stiffness * z, &mut g);
        }
        for (damper, p) in self.dampers.iter().zip(power) {
            *p = damper.add_to(v, &mut g);
        }
        for (f, a) in a.iter_mut().enumerate() {
            *a -= g[f] / model.params.mass[f];
        }
    }

    /// The floor accelerations (relative to the ground) of the model's state and control
    /// force under the excitation `excitation`, with these z and the dampers.
    pub(super) fn acceleration(&self, model: &ShearModel, excitation: f64) -> Vec<f64> {
        let mut a = vec![0.0; model.storeys()];
        let control = model.control_force.value;
        model.accelerations_into(
            &model.displacement,
            &model.velocity,
            excitation,
            control,
            &mut a,
        );
        if !self.is_empty() {
            let mut power = vec![0.0; self.dampers.len()];
            self.add_to(model, &self.z, &model.velocity, &mut a, &mut power);
        }
        a
    }

    #[inline]
    fn rhs(&self, model: &ShearModel, x: &HState, inputs: (f64, f64)) -> HState {
        let at = self.offsets(model.storeys());
        let (y, v) = (&x[..at.v], &x[at.v..at.z]);
        let mut dx = vec![0.0; at.len];
        let (dy, rest) = dx.split_at_mut(at.v);
        let (a, rest) = rest.split_at_mut(at.z - at.v);
        model.accelerations_into(y, v, inputs.0, inputs.1, a);
        let power = &mut rest[at.e - at.z..];
        self.add_to(model, &x[at.z..at.w], v, a, power);
        dy.copy_from_slice(v);
        for (i, law) in self.laws.iter().enumerate() {
            let z = x[at.z + i];
            let rate = drift(v, law.storey);
            dx[at.z + i] = law.z_rate(rate, z);
            dx[at.w + i] = law.stiffness * z * rate;
        }
        dx
    }

    /// Where the vector field has kinks: the contacts' gaps and each law's `δ̇ z`.
    fn switches(&self, model: &ShearModel, x: &HState) -> Vec<f64> {
        let at = self.offsets(model.storeys());
        let mut out = model.effects.switches(&x[..at.v]).values.to_vec();
        for (i, law) in self.laws.iter().enumerate() {
            out.push(drift(&x[at.v..at.z], law.storey) * x[at.z + i]);
        }
        out
    }

    /// RK4 over `[0, h]` with the inputs as ramps, `substeps` sub-steps, each split just past
    /// every sign change of a switch (numerics' stepper, as the shear FMU's contact steps).
    fn step(&self, model: &ShearModel, x: &HState, inputs: Inputs, h: f64) -> HState {
        rk4_with_events(
            |tau: f64, x: &HState| self.rhs(model, x, inputs.at(tau)),
            |x: &HState| self.switches(model, x),
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
        let at = self.offsets(model.storeys());
        let mut x = Vec::with_capacity(at.len);
        x.extend_from_slice(&model.displacement);
        x.extend_from_slice(&model.velocity);
        x.extend_from_slice(&self.z);
        x.extend_from_slice(&self.work);
        x.extend_from_slice(&self.dissipated);
        let x = self.step(model, &x, Inputs::of(model), h);
        model.displacement.copy_from_slice(&x[..at.v]);
        model.velocity.copy_from_slice(&x[at.v..at.z]);
        self.z.copy_from_slice(&x[at.z..at.w]);
        self.work.copy_from_slice(&x[at.w..at.e]);
        self.dissipated.copy_from_slice(&x[at.e..]);
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
            let v = damper.velocity(&model.velocity).abs();
            self.max_abs_velocity[i] = self.max_abs_velocity[i].max(v);
        }
    }
}
