//! Forward sensitivities of the linear model: the derivatives of the floor accelerations with
//! respect to the nine structural parameters (`m1..m3`, `c1..c3`, `k1..k3`), carried along the
//! run when the `sensitivities` parameter is on, so that a calibration gets its Jacobian from
//! one run instead of one extra run per parameter.
//!
//! They are the derivatives of the FMU's own discrete map, not of the ODE: the linear model's
//! step is `x' = Φ x + g₀ u + g₁ u̇` with `Φ, g₀, g₁` the RK4 sub-steps composed
//! ([`crate::integrate::LinearStepMap`]), so the sensitivity `s = ∂x/∂θ` steps as
//! `s' = Φ s + Φ_θ x + g₀_θ u + g₁_θ u̇`. The derivative maps come from RK4 on the augmented
//! linear system `z = [x, s, u, u̇]`, `ż = F z`, with
//! `F = [[A, 0, b, 0], [A_θ, A, b_θ, 0], [0, 0, 0, 1], [0, 0, 0, 0]]`: one RK4 sub-step of a
//! linear autonomous system is the polynomial `R(δF) = I + δF + (δF)²/2 + (δF)³/6 + (δF)⁴/24`,
//! and on this block-triangular `F` its lower-left block is the derivative of `R(δA)` (the
//! input held as a state ramps exactly as RK4 evaluates it at its stages). The sub-steps
//! composed, `R(δF)^N` by repeated squaring, give `Φ_θ, g₀_θ, g₁_θ` in its `s` rows.
//!
//! The accelerations `a(x, u)` then give `∂a/∂θ = a_θ(x, u) + A_a s`, `A_a` the acceleration
//! rows of `A`. With any effect on the model is not linear and the outputs are NaN.

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};

use crate::effects::Effects;
use crate::integrate::{LinearStepMap, State};
use crate::model::ShearParameters;

/// The parameters with sensitivities, in output order.
pub const PARAMETERS: [&str; 9] = ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"];

type Augmented = SMatrix<f64, 14, 14>;

/// The derivative maps of one communication step, for the current parameters and step size.
#[derive(Clone, Debug)]
pub struct SensitivityMaps {
    step: f64,
    params: ShearParameters,
    /// `Φ_θ[i][c][j]`: row i, column c of parameter j's `Φ_θ`; `g₀_θ[i][j]`, `g₁_θ[i][j]`
    /// (the parameters innermost, as the states).
    phi: [[Row; 6]; 6],
    g0: [Row; 6],
    g1: [Row; 6],
}

/// One component of the state across the nine parameters.
pub type Row = [f64; 9];

/// The sensitivity states `∂[y, ẏ]/∂θ` of the nine parameters (part of the FMU state).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Sensitivities {
    pub on: bool,
    /// `states[i][j] = ∂x_i/∂θ_j`.
    pub states: [Row; 6],
    #[serde(skip)]
    maps: Option<Box<SensitivityMaps>>,
    /// The 27 outputs for the current state, and the net input they were computed with.
    #[serde(skip)]
    outputs: Option<(f64, [f64; 27])>,
}

impl Sensitivities {
    /// Step the sensitivities with the linear step `map` from `x0`, the net input `u0` with
    /// slope `slope` over the step.
    pub fn advance(
        &mut self,
        params: &ShearParameters,
        map: &LinearStepMap,
        x0: &State,
        u0: f64,
        slope: f64,
        h: f64,
    ) {
        if !self
            .maps
            .as_ref()
            .is_some_and(|m| m.step == h && m.params == *params)
        {
            self.maps = Some(Box::new(SensitivityMaps::new(params, h)));
        }
        self.outputs = None;
        let Some(maps) = self.maps.as_ref() else {
            return;
        };
        // S' = Φ S + Σ_c Φ_θ[·][c] x0[c] + g₀_θ u0 + g₁_θ u̇, nine parameters at a time.
        let phi = map.matrix();
        let s = &self.states;
        let next: [Row; 6] = std::array::from_fn(|i| {
            let mut row: Row = std::array::from_fn(|j| maps.g0[i][j] * u0 + maps.g1[i][j] * slope);
            for c in 0..6 {
                let (a, b) = (phi[i][c], x0[c]);
                for j in 0..9 {
                    row[j] += a * s[c][j] + maps.phi[i][c][j] * b;
                }
            }
            row
        });
        self.states = next;
    }

    /// Output `k`: `∂a_f/∂θ_j` for `k = 9 f + j`, at the state `x` and net input `u` (the 27
    /// computed together, once per state and input).
    pub fn output(
        &mut self,
        params: &ShearParameters,
        effects: &Effects,
        x: &State,
        u: f64,
        k: usize,
    ) -> f64 {
        match &self.outputs {
            Some((at, values)) if at.to_bits() == u.to_bits() => values[k],
            _ => {
                let values = if effects.any_enabled() {
                    [f64::NAN; 27]
                } else {
                    self.all_outputs(params, x, u)
                };
                self.outputs = Some((u, values));
                values[k]
            }
        }
    }

    fn all_outputs(&self, params: &ShearParameters, x: &State, u: f64) -> [f64; 27] {
        let (c, k) = (&params.damping, &params.stiffness);
        let inv_m = params.mass.map(|m| 1.0 / m);
        // Storey drifts and drift rates of the state, and the storey forces.
        let storeys = |q: &State| {
            (
                [q[0], q[1] - q[0], q[2] - q[1]],
                [q[3], q[4] - q[3], q[5] - q[4]],
            )
        };
        let (d, dv) = storeys(x);
        let force = |d: &[f64; 3], dv: &[f64; 3], i: usize| k[i] * d[i] + c[i] * dv[i];
        let push = |s: [f64; 3], u: f64| {
            [
                (u - s[0] + s[1]) * inv_m[0],
                (s[2] - s[1]) * inv_m[1],
                -s[2] * inv_m[2],
            ]
        };
        let a = push([force(&d, &dv, 0), force(&d, &dv, 1), force(&d, &dv, 2)], u);
        let mut out = [0.0; 27];
        for j in 0..9 {
            let state: State = std::array::from_fn(|i| self.states[i][j]);
            let (sd, sdv) = storeys(&state);
            let mut da = push(
                [
                    force(&sd, &sdv, 0),
                    force(&sd, &sdv, 1),
                    force(&sd, &sdv, 2),
                ],
                0.0,
            );
            let (group, i) = (j / 3, j % 3);
            if group == 0 {
                da[i] -= a[i] * inv_m[i];
            } else {
                // Storey i's force grows by its drift rate (damping) or drift (stiffness).
                let ds = if group == 1 { dv[i] } else { d[i] };
                da[i] -= ds * inv_m[i];
                if i > 0 {
                    da[i - 1] += ds * inv_m[i - 1];
                }
            }
            for f in 0..3 {
                out[9 * f + j] = da[f];
            }
        }
        out
    }
}

/// The linear model's floor accelerations for the state `x` and net input `u`.
fn linear_acceleration(p: &ShearParameters, x: &State, u: f64) -> [f64; 3] {
    let (m, c, k) = (&p.mass, &p.damping, &p.stiffness);
    let s = [
        k[0] * x[0] + c[0] * x[3],
        k[1] * (x[1] - x[0]) + c[1] * (x[4] - x[3]),
        k[2] * (x[2] - x[1]) + c[2] * (x[5] - x[4]),
    ];
    [(u - s[0] + s[1]) / m[0], (s[2] - s[1]) / m[1], -s[2] / m[2]]
}

/// `∂a/∂θ_j` at a fixed state and input (linear model).
pub fn acceleration_derivative(params: &ShearParameters, x: &State, u: f64, j: usize) -> [f64; 3] {
    let a = linear_acceleration(params, x, u);
    derivative_at(params, x, &a, j)
}

/// `∂a/∂θ_j` at the state `x` whose accelerations are `a`.
fn derivative_at(p: &ShearParameters, x: &State, a: &[f64; 3], j: usize) -> [f64; 3] {
    let (y, v) = ([x[0], x[1], x[2]], [x[3], x[4], x[5]]);
    let m = &p.mass;
    let (group, i) = (j / 3, j % 3);
    if group == 0 {
        let mut out = [0.0; 3];
        out[i] = -a[i] / m[i];
        return out;
    }
    // Storey i's force grows by its drift (stiffness) or drift rate (damping) per unit of θ.
    let storey = |q: &[f64; 3]| if i == 0 { q[0] } else { q[i] - q[i - 1] };
    let ds = if group == 1 { storey(&v) } else { storey(&y) };
    // Storey i pushes floor i back and floor i − 1 forward.
    let mut rhs = [0.0; 3];
    rhs[i] = -ds;
    if i > 0 {
        rhs[i - 1] = ds;
    }
    [rhs[0] / m[0], rhs[1] / m[1], rhs[2] / m[2]]
}

impl SensitivityMaps {
    pub fn new(params: &ShearParameters, h: f64) -> Self {
        let unit = |c: usize| -> State {
            let mut e = [0.0; 6];
            e[c] = 1.0;
            e
        };
        // The acceleration rows of A and b: the linear accelerations on unit states and input.
        let mut base = Augmented::zeros();
        for i in 0..3 {
            base[(i, 3 + i)] = 1.0;
            base[(6 + i, 9 + i)] = 1.0;
        }
        base[(12, 13)] = 1.0;
        let accel = |x: &State, u: f64| linear_acceleration(params, x, u);
        for c in 0..6 {
            let a = accel(&unit(c), 0.0);
            for r in 0..3 {
                base[(3 + r, c)] = a[r];
                base[(9 + r, 6 + c)] = a[r];
            }
        }
        let b = accel(&[0.0; 6], 1.0);
        for r in 0..3 {
            base[(3 + r, 12)] = b[r];
        }
        let substeps = params.substeps.max(1);
        let delta = h / f64::from(substeps);
        let mut maps = SensitivityMaps {
            step: h,
            params: params.clone(),
            phi: [[[0.0; 9]; 6]; 6],
            g0: [[0.0; 9]; 6],
            g1: [[0.0; 9]; 6],
        };
        for j in 0..9 {
            let mut f = base;
            for c in 0..6 {
                let d = acceleration_derivative(params, &unit(c), 0.0, j);
                for r in 0..3 {
                    f[(9 + r, c)] = d[r];
                }
            }
            let d = acceleration_derivative(params, &[0.0; 6], 1.0, j);
            for r in 0..3 {
                f[(9 + r, 12)] = d[r];
            }
            let p = power(&rk4_substep(&(f * delta)), substeps);
            for r in 0..6 {
                for c in 0..6 {
                    maps.phi[r][c][j] = p[(6 + r, c)];
                }
                maps.g0[r][j] = p[(6 + r, 12)];
                maps.g1[r][j] = p[(6 + r, 13)];
            }
        }
        maps
    }
}

/// RK4's map of one step of `ż = F z` for `hf = δF`: `I + hf (I + hf/2 (I + hf/3 (I + hf/4)))`.
fn rk4_substep(hf: &Augmented) -> Augmented {
    let id = Augmented::identity();
    let mut r = id + hf / 4.0;
    r = id + hf * r / 3.0;
    r = id + hf * r / 2.0;
    id + hf * r
}

/// `m^n` by repeated squaring.
fn power(m: &Augmented, mut n: u32) -> Augmented {
    let mut result = Augmented::identity();
    let mut square = *m;
    while n > 0 {
        if n & 1 == 1 {
            result *= square;
        }
        n >>= 1;
        if n > 0 {
            square = square * square;
        }
    }
    result
}
