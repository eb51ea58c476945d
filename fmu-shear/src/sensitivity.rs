//! Forward sensitivities of the linear model: the derivatives of the floor accelerations with
//! respect to the 3N structural parameters (`m1..mN`, `c1..cN`, `k1..kN`), carried along the
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

use nalgebra::{DMatrix, DMatrixView};
use serde::{Deserialize, Serialize};

use crate::effects::Effects;
use crate::kernels::add_rows;
use crate::linear::{AccelerationRows, LinearStepMap, StepInputs, INPUT_COLUMNS};
use crate::model::ShearParameters;
use structure::Excitation;

/// The derivative maps of one communication step, for the current parameters and step size.
#[derive(Clone, Debug)]
pub struct SensitivityMaps {
    step: f64,
    params: ShearParameters,
    /// The derivatives of `[Φ G]` (2N rows of 2N + 4) along the 3N parameters, laid out
    /// `[row][column][parameter]`: a step adds, for each row and column, the column's state or
    /// input times a contiguous run over the parameters (a vectorised axpy, as `Φ S`), where a
    /// map per parameter would be one dot product per row and parameter (a reduction the
    /// compiler cannot vectorise: 60 % of a 20-storey compare with its band).
    derivative: Vec<f64>,
}

/// The sensitivity states `∂[y, ẏ]/∂θ` of the 3N parameters (part of the FMU state).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Sensitivities {
    pub on: bool,
    /// `states[i·3N + j] = ∂x_i/∂θ_j`, 2N × 3N (empty until the first step: zero).
    pub states: Vec<f64>,
    #[serde(skip)]
    maps: Option<Box<SensitivityMaps>>,
    /// The next step's states and the step's `[x, u]` (reused: a step allocates nothing).
    #[serde(skip)]
    scratch: Vec<f64>,
    #[serde(skip)]
    inputs: Vec<f64>,
    /// The N × 3N outputs for the current state, and the inputs they were computed with.
    #[serde(skip)]
    outputs: Option<(StepInputs, Vec<f64>)>,
}

impl Sensitivities {
    /// Step the sensitivities with the linear step `map` from `x0` under `inputs`.
    pub fn advance(
        &mut self,
        params: &ShearParameters,
        map: &LinearStepMap,
        x0: &[f64],
        inputs: &StepInputs,
        h: f64,
    ) {
        if !self
            .maps
            .as_ref()
            .is_some_and(|m| crate::linear::same_step(m.step, h) && m.params == *params)
        {
            self.maps = Some(Box::new(SensitivityMaps::new(params, h)));
        }
        self.outputs = None;
        let Some(maps) = self.maps.as_ref() else {
            return;
        };
        let n = params.storeys();
        let (states, count) = (2 * n, 3 * n);
        if self.states.len() != states * count {
            self.states = vec![0.0; states * count];
        }
        let width = states + INPUT_COLUMNS;
        let u = [
            inputs.excitation,
            inputs.excitation_slope,
            inputs.control,
            inputs.control_slope,
        ];
        // S' = Φ S + Σ_c Φ_θ[·][c] x0[c] + G_θ u, all parameters of a row at a time: row i
        // is the rows of S times Φ's row i, plus the derivative maps' columns for row i
        // (contiguous over the parameters) times the state and the inputs.
        let mut z = std::mem::take(&mut self.inputs);
        z.clear();
        z.extend(x0.iter().chain(&u));
        let mut next = std::mem::take(&mut self.scratch);
        next.clear();
        next.resize(states * count, 0.0);
        let s = &self.states;
        for (i, row) in next.chunks_exact_mut(count).enumerate() {
            add_rows(map.phi_row(i), s, row);
            add_rows(
                &z,
                &maps.derivative[i * width * count..(i + 1) * width * count],
                row,
            );
        }
        self.inputs = z;
        self.scratch = std::mem::replace(&mut self.states, next);
    }

    /// The output [`Sensitivities::output`] computed last, if it was for these inputs (the state
    /// has not moved since: a step clears them).
    pub fn cached(
        &self,
        params: &ShearParameters,
        inputs: &StepInputs,
        floor: usize,
        parameter: usize,
    ) -> Option<f64> {
        match &self.outputs {
            Some((at, values)) if at == inputs => values
                .get(floor * 3 * params.storeys() + parameter)
                .copied(),
            _ => None,
        }
    }

    /// `∂acc_floor/∂θ_parameter` (both 0-based) at the state `x` and inputs (all N × 3N computed
    /// together, once per state and input). An accelerometer's ground acceleration does not
    /// depend on the parameters, so the relative and the absolute acceleration share them.
    pub fn output(
        &mut self,
        params: &ShearParameters,
        effects: &Effects,
        x: &[f64],
        inputs: &StepInputs,
        floor: usize,
        parameter: usize,
    ) -> f64 {
        let count = 3 * params.storeys();
        match &self.outputs {
            Some((at, values)) if at == inputs => values[floor * count + parameter],
            _ => {
                let values = if effects.any_enabled() {
                    vec![f64::NAN; params.storeys() * count]
                } else {
                    self.all_outputs(params, x, inputs)
                };
                let value = values[floor * count + parameter];
                self.outputs = Some((*inputs, values));
                value
            }
        }
    }

    fn all_outputs(&self, params: &ShearParameters, x: &[f64], inputs: &StepInputs) -> Vec<f64> {
        let n = params.storeys();
        let (states, count) = (2 * n, 3 * n);
        let rows = AccelerationRows::new(params);
        let zero = vec![0.0; states * count];
        let s = if self.states.len() == states * count {
            &self.states
        } else {
            &zero
        };
        let mut out = vec![0.0; n * count];
        // A_a S.
        for f in 0..n {
            let row = &mut out[f * count..(f + 1) * count];
            for c in 0..states {
                let a = rows.a[(f, c)];
                if a != 0.0 {
                    for (o, sc) in row.iter_mut().zip(&s[c * count..(c + 1) * count]) {
                        *o += a * sc;
                    }
                }
            }
        }
        // + ∂(A_a x + b_e e + b_c c)/∂θ_j at the fixed state, term by term (each parameter
        // touches one or two floors: [`acceleration_derivative`] written sparsely, O(N) in all).
        let (y, v) = x.split_at(n);
        let force_excited = matches!(params.excitation, Excitation::Force { .. });
        for i in 0..n {
            // m_i divides floor i's row: ∂a_i/∂m_i = −(its row's value)/m_i, the ground
            // acceleration's −1 aside (it does not depend on the mass).
            let mut row = rows.b_control[i] * inputs.control;
            if force_excited {
                row += rows.b_excitation[i] * inputs.excitation;
            }
            for c in 0..states {
                row += rows.a[(i, c)] * x[c];
            }
            out[i * count + i] -= row / params.mass[i];
        }
        for s in 0..n {
            // Storey s pushes floor s back and floor s − 1 forward: c_s by its drift rate, k_s
            // by its drift.
            let below = |q: &[f64]| if s > 0 { q[s - 1] } else { 0.0 };
            let (rate, drift) = (v[s] - below(v), y[s] - below(y));
            for (j, value) in [(n + s, rate), (2 * n + s, drift)] {
                out[s * count + j] -= value / params.mass[s];
                if s > 0 {
                    out[(s - 1) * count + j] += value / params.mass[s - 1];
                }
            }
        }
        out
    }
}

/// `∂ÿ/∂θ_j` at a fixed state `x` and inputs (linear model), θ in `m1..mN, c1..cN, k1..kN`.
pub fn acceleration_derivative(
    params: &ShearParameters,
    x: &[f64],
    inputs: &StepInputs,
    j: usize,
) -> Vec<f64> {
    let d = AccelerationRows::derivative(params, j);
    let n = params.storeys();
    (0..n)
        .map(|f| {
            let mut sum = 0.0;
            for c in 0..2 * n {
                sum += d.a[(f, c)] * x[c];
            }
            sum + d.b_excitation[f] * inputs.excitation + d.b_control[f] * inputs.control
        })
        .collect()
}

/// The values of `R(δF)^n` as RK4's polynomial by Horner and repeated squaring compute it,
/// kept at every stage: they are the same for every parameter, whose derivatives
/// ([`ValueChain::tangent`]) follow the same stages (a stage's derivative is the product rule
/// on its two factors), so each parameter costs two matrix products a stage instead of three.
struct ValueChain {
    hf: DMatrix<f64>,
    /// `r` after each Horner stage, for divisors 4, 3, 2, 1.
    horner: [DMatrix<f64>; 4],
    /// The square's value at each bit of `n`, and whether that bit multiplies the result.
    squares: Vec<(DMatrix<f64>, bool)>,
    /// The result's value before each multiplication by a square (after the first).
    results: Vec<DMatrix<f64>>,
}

const HORNER: [f64; 4] = [4.0, 3.0, 2.0, 1.0];

/// `m / k + I`.
fn identity_plus(mut m: DMatrix<f64>, k: f64) -> DMatrix<f64> {
    m /= k;
    for i in 0..m.nrows() {
        m[(i, i)] += 1.0;
    }
    m
}

impl ValueChain {
    fn new(hf: DMatrix<f64>, mut n: u32) -> Self {
        let mut r = identity_plus(hf.clone(), HORNER[0]);
        let mut horner = vec![r.clone()];
        for k in &HORNER[1..] {
            r = identity_plus(&hf * &r, *k);
            horner.push(r.clone());
        }
        let mut squares = Vec::new();
        let mut results = Vec::new();
        let mut result: Option<DMatrix<f64>> = None;
        let mut square = r;
        while n > 0 {
            let bit = n & 1 == 1;
            squares.push((square.clone(), bit));
            if bit {
                result = Some(match result {
                    None => square.clone(),
                    Some(value) => {
                        let next = &value * &square;
                        results.push(value);
                        next
                    }
                });
            }
            n >>= 1;
            if n > 0 {
                square = &square * &square;
            }
        }
        ValueChain {
            hf,
            horner: horner.try_into().expect("four Horner stages"),
            squares,
            results,
        }
    }

    /// The derivative of `R(δF)^n` along `hf_t`, the derivative of `δF`.
    fn tangent(&self, hf_t: &DMatrix<f64>) -> DMatrix<f64> {
        // Horner: r₀ = hf/4 + I, rₖ = hf rₖ₋₁ / k + I.
        let mut t = hf_t / HORNER[0];
        for (stage, k) in HORNER[1..].iter().enumerate() {
            t = (hf_t * &self.horner[stage] + &self.hf * &t) / *k;
        }
        // Repeated squaring: square' = s' s + s s'; result' = r' s + r s'.
        let mut square_t = t;
        let mut result_t: Option<DMatrix<f64>> = None;
        let mut results = self.results.iter();
        for (level, (square, bit)) in self.squares.iter().enumerate() {
            if *bit {
                result_t = Some(match result_t {
                    None => square_t.clone(),
                    Some(rt) => {
                        let value = results.next().expect("a result value per product");
                        &rt * square + value * &square_t
                    }
                });
            }
            if level + 1 < self.squares.len() {
                square_t = &square_t * square + square * &square_t;
            }
        }
        result_t.unwrap_or_else(|| DMatrix::zeros(self.hf.nrows(), self.hf.ncols()))
    }
}

impl SensitivityMaps {
    pub fn new(params: &ShearParameters, h: f64) -> Self {
        let n = params.storeys();
        let f = AccelerationRows::new(params).augmented(true);
        let substeps = params.substeps.max(1);
        let delta = h / f64::from(substeps);
        let width = 2 * n + INPUT_COLUMNS;
        let count = 3 * n;
        let mut derivative = vec![0.0; 2 * n * width * count];
        let chain = ValueChain::new(&f * delta, substeps);
        for j in 0..count {
            let tangent =
                chain.tangent(&(AccelerationRows::derivative(params, j).augmented(false) * delta));
            for i in 0..2 * n {
                for c in 0..width {
                    derivative[(i * width + c) * count + j] = tangent[(i, c)];
                }
            }
        }
        SensitivityMaps {
            step: h,
            params: params.clone(),
            derivative,
        }
    }

    /// The derivative maps along `directions` (3N × d, each column a direction of the
    /// parameters): row `i·d + a`, column `c` is `Σ_j ∂[Φ G]_ic/∂θ_j · directions[j][a]`
    /// (2N·d rows of 2N + 4), for [`crate::batch`].
    pub fn along(&self, directions: &DMatrix<f64>) -> DMatrix<f64> {
        let n = self.params.storeys();
        let (states, count, d) = (2 * n, 3 * n, directions.ncols());
        let width = states + INPUT_COLUMNS;
        // The maps are, column-major, p × (2N·(2N + 4)): one matrix product gives every entry
        // along every direction, `R[(a, i·width + c)]`.
        let maps = DMatrixView::from_slice(&self.derivative, count, states * width);
        let r = directions.transpose() * maps;
        DMatrix::from_fn(states * d, width, |row, c| {
            let (i, a) = (row / d, row % d);
            r[(a, i * width + c)]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sparse output derivatives are the dense [`acceleration_derivative`]'s plus `A_a S`,
    /// for a force and for ground motion, at a state and sensitivity states away from zero.
    #[test]
    fn sparse_outputs_are_the_dense_derivatives() {
        for excitation in [Excitation::Force { floor: 2 }, Excitation::Base] {
            let n = 4;
            let params = ShearParameters {
                mass: vec![5.2, 4.9, 5.5, 4.4],
                damping: vec![3.0, 2.1, 4.2, 1.3],
                stiffness: vec![4021.0, 3700.0, 4400.0, 3100.0],
                excitation,
                control_floor: 3,
                ..ShearParameters::default()
            };
            let x: Vec<f64> = (0..2 * n).map(|i| 1e-3 * (i as f64 - 3.3)).collect();
            let inputs = StepInputs {
                excitation: 0.7,
                excitation_slope: 0.0,
                control: -0.3,
                control_slope: 0.0,
            };
            let count = 3 * n;
            let mut s = Sensitivities {
                on: true,
                states: (0..2 * n * count)
                    .map(|i| 1e-4 * ((i * 7 % 11) as f64 - 5.0))
                    .collect(),
                ..Sensitivities::default()
            };
            assert_eq!(s.cached(&params, &inputs, 0, 0), None);
            let got = s.output(&params, &Effects::new(n), &x, &inputs, 0, 0);
            let all = s.all_outputs(&params, &x, &inputs);
            assert_eq!(got, all[0]);
            assert_eq!(s.cached(&params, &inputs, 2, 7), Some(all[2 * count + 7]));
            let rows = AccelerationRows::new(&params);
            for j in 0..count {
                let d = acceleration_derivative(&params, &x, &inputs, j);
                for f in 0..n {
                    let a_s: f64 = (0..2 * n)
                        .map(|c| rows.a[(f, c)] * s.states[c * count + j])
                        .sum();
                    let want = d[f] + a_s;
                    let err = (all[f * count + j] - want).abs();
                    assert!(
                        err <= 1e-12 * want.abs().max(1.0),
                        "floor {f} parameter {j}: {} vs {want}",
                        all[f * count + j]
                    );
                }
            }
        }
    }
}
