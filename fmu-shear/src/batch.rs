//! The linear model over a whole record at once: the floor accelerations and their derivatives
//! along chosen directions of the 3N parameters, from the FMU's own step maps
//! ([`LinearStepMap`], [`SensitivityMaps`]) — the same discretisation a run through FMI steps,
//! computed in blocks of samples instead of one step at a time.
//!
//! Through FMI a step of the sensitivities is a matrix–vector product with the derivative maps
//! (2N × (2N + 4) per parameter, 0.85 MB at 20 storeys: read from memory every step) and the
//! host reads N × 3N values one reference at a time. Over a record, the state's trajectory does
//! not depend on the sensitivities, so a block's states are stepped first and the maps' part of
//! every step in the block is one matrix product (`F = D Z`, the maps read once a block); what
//! stays sequential, `Tₖ₊₁ = Tₖ Φᵀ + Fₖ`, is a small matrix product a step. Along `d` directions
//! (the band's: the rows of the covariance's root) instead of the 3N parameters, the band is
//! `|∂a/∂θ · rᵢ|²` summed, with no p × p product per sample.
//!
//! Sample `k` is the state after `k` steps with the input's value at `t_k` (as a host reads the
//! outputs before stepping); step `k` takes the input as the ramp from `e_k` to `e_{k+1}`
//! (first-order hold, as a master that interpolates its inputs gives it), the control force 0.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;
use structure::Excitation;

use crate::kernels::axpy;
use crate::linear::{sparse_row, AccelerationRows, LinearStepMap, StepInputs, INPUT_COLUMNS};
use crate::model::ShearParameters;
use crate::sensitivity::SensitivityMaps;

/// A column-major slice as faer's matrix (its products: nano-gemm's small kernels, where
/// nalgebra's `gemm` packs every 60 × 40 by 40 × 40 product of a 20-storey recursion).
fn faer_ref(slice: &[f64], rows: usize, cols: usize) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(slice, rows, cols)
}

fn faer_mut(slice: &mut [f64], rows: usize, cols: usize) -> MatMut<'_, f64> {
    MatMut::from_column_major_slice_mut(slice, rows, cols)
}

/// Samples stepped ahead of their sensitivities: the maps' product is one matrix product over
/// this many columns.
const BLOCK: usize = 256;

/// A record for [`accelerations_along`]: the step, the excitation at each sample (N, or m/s²
/// of ground acceleration) and the measured floors (0-based, any order, repeats allowed).
pub struct LinearRecord<'a> {
    pub dt: f64,
    pub excitation: &'a [f64],
    pub floors: &'a [usize],
}

/// Run the linear model with `params` over `record` and call `each(k, values, derivatives)` at
/// every sample: `values[i]` what an accelerometer on `floors[i]` reads (absolute under ground
/// motion), `derivatives[i · d + a]` its derivative along direction `a` (column `a` of
/// `directions`, 3N × d, in `m1..mN, c1..cN, k1..kN`).
pub fn accelerations_along(
    params: &ShearParameters,
    record: &LinearRecord,
    directions: &DMatrix<f64>,
    mut each: impl FnMut(usize, &[f64], &[f64]),
) {
    let states = 2 * params.storeys();
    let d = directions.ncols();
    assert_eq!(
        directions.nrows(),
        3 * params.storeys(),
        "a direction has one entry per parameter"
    );
    let map = LinearStepMap::new(params, record.dt);
    let along = SensitivityMaps::new(params, record.dt).along(directions);
    let phi_t = DMatrix::from_fn(states, states, |c, i| map.phi(i, c));
    let mut outputs = Outputs::new(params, record.floors, directions);
    let samples = record.excitation.len();
    // T = Sᵀ (d × 2N, column-major: the derivatives of state c along every direction are
    // contiguous), at the start of a block; within it, column b of `forcing` becomes Tₖ₊₁.
    let size = states * d;
    let mut x = vec![0.0; states];
    let mut t = vec![0.0; size];
    let mut z = DMatrix::<f64>::zeros(states + INPUT_COLUMNS, BLOCK);
    let mut forcing = DMatrix::<f64>::zeros(size, BLOCK);
    let mut start = 0;
    while start < samples {
        let len = BLOCK.min(samples - start);
        x = step_block(&map, record, start, len, x, &mut z);
        // The maps' part of every step of the block at once: column b is Fₖ.
        matmul(
            faer_mut(&mut forcing.as_mut_slice()[..size * len], size, len),
            Accum::Replace,
            faer_ref(along.as_slice(), size, states + INPUT_COLUMNS),
            faer_ref(
                &z.as_slice()[..(states + INPUT_COLUMNS) * len],
                states + INPUT_COLUMNS,
                len,
            ),
            1.0,
            Par::Seq,
        );
        for b in 0..len {
            let (head, tail) = forcing.as_mut_slice().split_at_mut(b * size);
            let tk: &[f64] = if b == 0 { &t } else { &head[(b - 1) * size..] };
            let (values, derivatives) = outputs.at(z.column(b).as_slice(), tk);
            each(start + b, values, derivatives);
            // Tₖ₊₁ = Tₖ Φᵀ + Fₖ, in place of Fₖ.
            matmul(
                faer_mut(&mut tail[..size], d, states),
                Accum::Add,
                faer_ref(&tk[..size], d, states),
                faer_ref(phi_t.as_slice(), states, states),
                1.0,
                Par::Seq,
            );
        }
        t.copy_from_slice(forcing.column(len - 1).as_slice());
        start += len;
    }
}

/// Step the state `x` (at sample `start`) through `len` samples, writing column b of `z` as
/// `[x_k, e_k, ė_k, 0, 0]` (k = start + b: the state and the step's input ramp); the state
/// after the block.
fn step_block(
    map: &LinearStepMap,
    record: &LinearRecord,
    start: usize,
    len: usize,
    mut x: Vec<f64>,
    z: &mut DMatrix<f64>,
) -> Vec<f64> {
    let e = record.excitation;
    let states = x.len();
    let mut next = vec![0.0; states];
    for b in 0..len {
        let k = start + b;
        let slope = match e.get(k + 1) {
            Some(after) => (after - e[k]) / record.dt,
            None => 0.0,
        };
        let mut column = z.column_mut(b);
        column.rows_mut(0, states).copy_from_slice(&x);
        column[states] = e[k];
        column[states + 1] = slope;
        column[states + 2] = 0.0;
        column[states + 3] = 0.0;
        let inputs = StepInputs {
            excitation: e[k],
            excitation_slope: slope,
            control: 0.0,
            control_slope: 0.0,
        };
        map.apply_into(&x, &inputs, &mut next);
        std::mem::swap(&mut x, &mut next);
    }
    x
}

/// The measured accelerations and their derivatives at one sample, from the state, the input
/// and the sensitivities `T` there.
struct Outputs {
    rows: AccelerationRows,
    mass: Vec<f64>,
    base: bool,
    d: usize,
    /// A_a's nonzero entries per floor (a floor's row touches its own and its neighbours').
    sparse: Vec<Vec<(usize, f64)>>,
    /// Each parameter's direction row: its part of `∂a/∂θ` at a fixed state touches one or two
    /// floors, each adding `value · row`.
    direction_rows: Vec<Vec<f64>>,
    /// Where each floor's outputs go (a floor measured twice gets both).
    slots: Vec<Vec<usize>>,
    values: Vec<f64>,
    derivatives: Vec<f64>,
}

impl Outputs {
    fn new(params: &ShearParameters, floors: &[usize], directions: &DMatrix<f64>) -> Self {
        let n = params.storeys();
        let d = directions.ncols();
        let rows = AccelerationRows::new(params);
        let sparse = (0..n)
            .map(|f| {
                (0..2 * n)
                    .filter_map(|c| Some((c, rows.a[(f, c)])).filter(|(_, a)| *a != 0.0))
                    .collect()
            })
            .collect();
        let mut slots: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (slot, &f) in floors.iter().enumerate() {
            slots[f].push(slot);
        }
        Outputs {
            rows,
            mass: params.mass.clone(),
            base: matches!(params.excitation, Excitation::Base),
            d,
            sparse,
            direction_rows: (0..3 * n)
                .map(|j| directions.row(j).iter().copied().collect())
                .collect(),
            slots,
            values: vec![0.0; floors.len()],
            derivatives: vec![0.0; floors.len() * d],
        }
    }

    /// At the sample whose `[x, e, …]` is `zk` and sensitivities `tk`: `A_a x + b_e e` (+ e
    /// under ground motion) per measured floor, and along each direction `A_a Tᵀ` plus the
    /// direct derivative at the fixed state.
    fn at(&mut self, zk: &[f64], tk: &[f64]) -> (&[f64], &[f64]) {
        let (n, d) = (self.mass.len(), self.d);
        let (x, ek) = (&zk[..2 * n], zk[2 * n]);
        self.derivatives.iter_mut().for_each(|v| *v = 0.0);
        for (f, slots) in self.slots.iter().enumerate() {
            let Some(&first) = slots.first() else {
                continue;
            };
            let mut value = self.rows.b_excitation[f] * ek;
            let along_f = &mut self.derivatives[first * d..(first + 1) * d];
            for &(c, a) in &self.sparse[f] {
                value += a * x[c];
                axpy(a, &tk[c * d..(c + 1) * d], along_f);
            }
            for &slot in slots {
                self.values[slot] = if self.base { value + ek } else { value };
                if slot != first {
                    self.derivatives
                        .copy_within(first * d..(first + 1) * d, slot * d);
                }
            }
        }
        let (y, v) = x.split_at(n);
        for i in 0..n {
            // ∂a_i/∂m_i = −(row i's value)/m_i, the ground acceleration's −1 aside.
            let first = if self.base {
                0.0
            } else {
                self.rows.b_excitation[i] * ek
            };
            let row = sparse_row(first, &self.sparse[i], x);
            self.add(i, i, -row / self.mass[i]);
        }
        for s in 0..n {
            // Storey s pushes floor s back and floor s − 1 forward: c_s by its drift rate,
            // k_s by its drift.
            let below = |q: &[f64]| if s > 0 { q[s - 1] } else { 0.0 };
            let (rate, drift) = (v[s] - below(v), y[s] - below(y));
            for (j, value) in [(n + s, rate), (2 * n + s, drift)] {
                self.add(s, j, -value / self.mass[s]);
                if s > 0 {
                    self.add(s - 1, j, value / self.mass[s - 1]);
                }
            }
        }
        (&self.values, &self.derivatives)
    }

    /// Add `value` times parameter j's direction row to every output of `floor`.
    fn add(&mut self, floor: usize, j: usize, value: f64) {
        let d = self.d;
        for &slot in &self.slots[floor] {
            axpy(
                value,
                &self.direction_rows[j],
                &mut self.derivatives[slot * d..(slot + 1) * d],
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effects;
    use crate::model::ShearModel;
    use crate::variables::{sensitivity_vr, table, SENSITIVITIES};
    use fmi2::CoSimModel;
    use structure::Structure;

    /// Four storeys under a force at floor 2 and under ground motion, floors 3, 1 and 3 again
    /// measured, three directions: the record at once gives the accelerations and the
    /// sensitivities' projections that the model stepped one sample at a time gives (inputs
    /// set, outputs read, the slope set, a step — a host's order), to rounding. Measured worst
    /// 2.6e-15 of the largest value, 2.4e-14 for the derivatives; the bar is 1e-12.
    #[test]
    fn a_record_at_once_is_the_model_stepped_sample_by_sample() {
        for excitation in [Excitation::Force { floor: 2 }, Excitation::Base] {
            let structure = Structure {
                mass: vec![5.1, 4.8, 5.4, 4.5],
                damping: vec![3.2, 2.4, 1.9, 2.8],
                stiffness: vec![4021.0, 3700.0, 4400.0, 3100.0],
                excitation,
            };
            let params = ShearParameters::from_structure(&structure);
            let n = params.storeys();
            let dt = 1.0 / 51.2;
            let samples = 700; // more than two blocks, the last one short
            let e: Vec<f64> = (0..samples)
                .map(|k| (0.37 * k as f64).sin() + 0.5 * (1.3 * k as f64).cos())
                .collect();
            let floors = [2, 0, 2];
            let directions =
                DMatrix::from_fn(3 * n, 3, |j, a| ((j * 7 + a * 5) % 11) as f64 / 11.0 - 0.4);
            let mut got = Vec::new();
            accelerations_along(
                &params,
                &LinearRecord {
                    dt,
                    excitation: &e,
                    floors: &floors,
                },
                &directions,
                |_, v, dv| got.push((v.to_vec(), dv.to_vec())),
            );
            assert_eq!(got.len(), samples);

            let mut model = ShearModel::new(params.clone(), Effects::new(n));
            let info = table(&params);
            let input = info
                .by_name(if matches!(excitation, Excitation::Base) {
                    "ground_acc"
                } else {
                    "force"
                })
                .expect("the excitation's input")
                .vr;
            let acc: Vec<u32> = (1..=n)
                .map(|f| info.by_name(&format!("acc{f}")).expect("acc").vr)
                .collect();
            model.set_boolean(SENSITIVITIES, true).expect("switch");
            let (mut peak, mut worst, mut peak_d, mut worst_d) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for (k, (values, derivatives)) in got.iter().enumerate() {
                model.set_real(input, e[k]).expect("input");
                for (slot, &f) in floors.iter().enumerate() {
                    let want = model.get_real(acc[f]).expect("acc");
                    peak = peak.max(want.abs());
                    worst = worst.max((values[slot] - want).abs());
                    for a in 0..directions.ncols() {
                        let want: f64 = (0..3 * n)
                            .map(|j| {
                                model.get_real(sensitivity_vr(f, j, n)).expect("d")
                                    * directions[(j, a)]
                            })
                            .sum();
                        peak_d = peak_d.max(want.abs());
                        worst_d = worst_d.max((derivatives[slot * 3 + a] - want).abs());
                    }
                }
                if k + 1 < samples {
                    model
                        .set_real_input_derivative(input, (e[k + 1] - e[k]) / dt)
                        .expect("slope");
                    model.do_step(k as f64 * dt, dt).expect("step");
                }
            }
            println!("{excitation:?}: values {worst:e} of {peak:e}, derivatives {worst_d:e} of {peak_d:e}");
            assert!(peak > 1e-3 && peak_d > 1e-6, "the run moves");
            assert!(worst <= 1e-12 * peak, "values: {worst:e} of {peak:e}");
            assert!(
                worst_d <= 1e-12 * peak_d,
                "derivatives: {worst_d:e} of {peak_d:e}"
            );
        }
    }
}
