//! The linear model for any number of storeys: its system matrices, the exact RK4 step map of
//! one communication step, and (in `sensitivity`) the derivative maps.
//!
//! The state is `x = [y, ẏ]` (2N, relative to the ground); two inputs, each a ramp over the step:
//! the excitation `e` (a force at floor K, or the ground acceleration) and the control force `c`
//! (at the control floor, acting against the excitation). `ẏ' = A_a x + b_e e + b_c c` with
//! `A_a = −M⁻¹ [K C]`, `b_e = M⁻¹ e_K` (force) or `−1` (ground acceleration: the relative
//! coordinates' load `−M 1 a_g` divided by `M`), `b_c = −M⁻¹ e_cf`.
//!
//! RK4 with `n` sub-steps on a linear system whose inputs are ramps is an affine map of the
//! state and of the inputs' values and slopes. The inputs are held as states of an augmented
//! autonomous system `z = [x, e, ė, c, ċ]`, `ż = F z` (each ramp integrates exactly as RK4
//! evaluates it at its stages), and one sub-step of RK4 on `ż = F z` is the matrix polynomial
//! `R(δF) = I + δF + (δF)²/2 + (δF)³/6 + (δF)⁴/24`; `n` sub-steps are `R(δF)ⁿ`, by repeated
//! squaring. Its first 2N rows are `[Φ g₀ₑ g₁ₑ g₀c g₁c]`. Building it costs O(N³ log n) once per
//! (parameters, step size); a step is then one (2N)² matrix–vector product.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use structure::Excitation;

use crate::model::ShearParameters;

/// Columns of the augmented system after the 2N states.
pub const INPUT_COLUMNS: usize = 4;

/// `A_a` (N × 2N, row-major in a DMatrix), `b_e` and `b_c` (N each) for the parameters.
pub struct AccelerationRows {
    pub a: DMatrix<f64>,
    pub b_excitation: Vec<f64>,
    pub b_control: Vec<f64>,
}

/// Storey `s` (0-based) joins floor `s − 1` (the ground for `s = 0`) and floor `s`: its force
/// `k d + c ḋ`, `d = y_s − y_{s−1}`, pushes floor `s` back and floor `s − 1` forward. Adds the
/// coefficients of that force (for the given `k` and `c`) to the acceleration rows, row `f`
/// divided by `m_f`.
pub(crate) fn add_storey(
    rows: &mut DMatrix<f64>,
    n: usize,
    s: usize,
    k: f64,
    c: f64,
    mass: &[f64],
) {
    let mut push = |floor: usize, sign: f64| {
        let inv_m = 1.0 / mass[floor];
        rows[(floor, s)] -= sign * k * inv_m;
        rows[(floor, n + s)] -= sign * c * inv_m;
        if s > 0 {
            rows[(floor, s - 1)] += sign * k * inv_m;
            rows[(floor, n + s - 1)] += sign * c * inv_m;
        }
    };
    push(s, 1.0);
    if s > 0 {
        push(s - 1, -1.0);
    }
}

impl AccelerationRows {
    pub fn new(p: &ShearParameters) -> Self {
        let n = p.storeys();
        let mut a = DMatrix::zeros(n, 2 * n);
        for s in 0..n {
            add_storey(&mut a, n, s, p.stiffness[s], p.damping[s], &p.mass);
        }
        let mut b_excitation = vec![0.0; n];
        match p.excitation {
            Excitation::Force { floor } => b_excitation[floor - 1] = 1.0 / p.mass[floor - 1],
            Excitation::Base => b_excitation.iter_mut().for_each(|b| *b = -1.0),
        }
        let mut b_control = vec![0.0; n];
        b_control[p.control_floor - 1] = -1.0 / p.mass[p.control_floor - 1];
        AccelerationRows {
            a,
            b_excitation,
            b_control,
        }
    }

    /// The derivative of the rows with respect to parameter `j` of `m1..mN, c1..cN, k1..kN`.
    pub fn derivative(p: &ShearParameters, j: usize) -> Self {
        let n = p.storeys();
        let (group, i) = (j / n, j % n);
        let mut d = AccelerationRows {
            a: DMatrix::zeros(n, 2 * n),
            b_excitation: vec![0.0; n],
            b_control: vec![0.0; n],
        };
        match group {
            0 => {
                // Row i is divided by m_i: its derivative is the row times −1/m_i. The ground
                // acceleration's −1 does not depend on the mass.
                let rows = AccelerationRows::new(p);
                let scale = -1.0 / p.mass[i];
                for c in 0..2 * n {
                    d.a[(i, c)] = rows.a[(i, c)] * scale;
                }
                if matches!(p.excitation, Excitation::Force { .. }) {
                    d.b_excitation[i] = rows.b_excitation[i] * scale;
                }
                d.b_control[i] = rows.b_control[i] * scale;
            }
            1 => add_storey(&mut d.a, n, i, 0.0, 1.0, &p.mass),
            _ => add_storey(&mut d.a, n, i, 1.0, 0.0, &p.mass),
        }
        d
    }

    /// The augmented system matrix `F` (2N + 4 square) with these rows in its acceleration block.
    pub fn augmented(&self, with_kinematics: bool) -> DMatrix<f64> {
        let n = self.b_control.len();
        let size = 2 * n + INPUT_COLUMNS;
        let mut f = DMatrix::zeros(size, size);
        if with_kinematics {
            for i in 0..n {
                f[(i, n + i)] = 1.0;
            }
            f[(2 * n, 2 * n + 1)] = 1.0;
            f[(2 * n + 2, 2 * n + 3)] = 1.0;
        }
        for r in 0..n {
            for c in 0..2 * n {
                f[(n + r, c)] = self.a[(r, c)];
            }
            f[(n + r, 2 * n)] = self.b_excitation[r];
            f[(n + r, 2 * n + 2)] = self.b_control[r];
        }
        f
    }
}

/// RK4's map of one step of `ż = F z` for `hf = δF`: `I + hf (I + hf/2 (I + hf/3 (I + hf/4)))`.
pub fn rk4_substep(hf: &DMatrix<f64>) -> DMatrix<f64> {
    let id = DMatrix::identity(hf.nrows(), hf.ncols());
    let mut r = &id + hf / 4.0;
    r = &id + hf * r / 3.0;
    r = &id + hf * r / 2.0;
    id + hf * r
}

/// `m^n` by repeated squaring.
pub fn power(m: &DMatrix<f64>, mut n: u32) -> DMatrix<f64> {
    let mut result = DMatrix::identity(m.nrows(), m.ncols());
    let mut square = m.clone();
    while n > 0 {
        if n & 1 == 1 {
            result *= &square;
        }
        n >>= 1;
        if n > 0 {
            square = &square * &square;
        }
    }
    result
}

/// The inputs over one step: the excitation and the control force, each `value + slope·τ`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepInputs {
    pub excitation: f64,
    pub excitation_slope: f64,
    pub control: f64,
    pub control_slope: f64,
}

impl StepInputs {
    fn as_array(&self) -> [f64; INPUT_COLUMNS] {
        [
            self.excitation,
            self.excitation_slope,
            self.control,
            self.control_slope,
        ]
    }
}

/// One communication step of the linear model: `x' = Φ x + G [e, ė, c, ċ]`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearStepMap {
    pub step: f64,
    pub params: ShearParameters,
    states: usize,
    /// `[Φ G]`, row-major, 2N rows of 2N + 4.
    rows: Vec<f64>,
    /// The same, column-major, for the step's product ([`product_by_columns`]).
    columns: Vec<f64>,
}

impl LinearStepMap {
    pub fn new(params: &ShearParameters, step: f64) -> Self {
        let n = params.storeys();
        let f = AccelerationRows::new(params).augmented(true);
        let substeps = params.substeps.max(1);
        let p = power(&rk4_substep(&(f * (step / f64::from(substeps)))), substeps);
        let width = 2 * n + INPUT_COLUMNS;
        let mut rows = Vec::with_capacity(2 * n * width);
        for r in 0..2 * n {
            for c in 0..width {
                rows.push(p[(r, c)]);
            }
        }
        let columns = (0..width)
            .flat_map(|c| (0..2 * n).map(move |r| (r, c)))
            .map(|(r, c)| p[(r, c)])
            .collect();
        LinearStepMap {
            step,
            params: params.clone(),
            states: 2 * n,
            rows,
            columns,
        }
    }

    /// `Φ[r][c]`.
    #[inline]
    pub fn phi(&self, r: usize, c: usize) -> f64 {
        self.rows[r * (self.states + INPUT_COLUMNS) + c]
    }

    /// `Φ`'s row `r` (2N).
    #[inline]
    pub fn phi_row(&self, r: usize) -> &[f64] {
        let width = self.states + INPUT_COLUMNS;
        &self.rows[r * width..r * width + self.states]
    }

    pub fn fits(&self, params: &ShearParameters, step: f64) -> bool {
        same_step(self.step, step) && self.params == *params
    }

    /// The state after the step from `x` (2N) under `inputs`, written to `out`.
    #[inline]
    pub fn apply_into(&self, x: &[f64], inputs: &StepInputs, out: &mut [f64]) {
        let n = self.states;
        product_by_columns(&self.columns, &x[..n], &inputs.as_array(), &mut out[..n]);
    }

    pub fn apply(&self, x: &[f64], inputs: &StepInputs) -> Vec<f64> {
        let mut out = vec![0.0; self.states];
        self.apply_into(x, inputs, &mut out);
        out
    }
}

/// `first + Σ a x[c]` over a row's nonzero entries `(c, a)`, in their order: the modal pass
/// and the batch add the same terms in the same order, so their predictions are the same bits.
/// A function of its own, not inlined: inside the modal pass's loop, short of registers, the
/// sum was kept on the stack, a store and a load per term on the chain of additions.
#[inline(never)]
pub(crate) fn sparse_row(first: f64, row: &[(usize, f64)], x: &[f64]) -> f64 {
    row.iter().fold(first, |v, &(c, a)| v + a * x[c])
}

/// `out = A [x; extra]` for `A` stored column-major (`out.len()` rows, one column per entry
/// of `x` then of `extra`). A block of rows at a time, their sums in registers while the
/// columns go by (a plain column-major product reads and writes `out` once per column); each
/// row's terms are added in column order, as a row-major dot product adds them, so the result
/// is the same to the bit whatever the blocks.
///
/// On a CPU with AVX the same code is compiled for it (four doubles a register, blocks of
/// eight rows): the same multiplications and additions in the same order — AVX has no fused
/// multiply-add, and none is asked for — so every result is the same to the bit as without
/// it, on any machine; a 20-state step's product takes 43 % fewer instructions (callgrind,
/// a 10-storey calibration start).
#[inline]
pub(crate) fn product_by_columns(columns: &[f64], x: &[f64], extra: &[f64], out: &mut [f64]) {
    // Below a block of eight rows AVX saves nothing (a 6-state step took 5 % more with it).
    #[cfg(target_arch = "x86_64")]
    if out.len() >= 8 && std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX, checked just above.
        #[allow(unsafe_code)]
        unsafe {
            product_by_columns_avx(columns, x, extra, out)
        };
        return;
    }
    product_by_columns_portable(columns, x, extra, out);
}

/// [`product_by_columns`] compiled for AVX (unsafe only as a function for a CPU feature is:
/// called where the CPU has it).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx")]
unsafe fn product_by_columns_avx(columns: &[f64], x: &[f64], extra: &[f64], out: &mut [f64]) {
    let rows = out.len();
    let mut start = 0;
    while start + 8 <= rows {
        rows_by_columns::<8>(columns, x, extra, out, start);
        start += 8;
    }
    product_tail(columns, x, extra, out, start);
}

/// [`product_by_columns`] for any x86-64 (two doubles a register) and other CPUs.
#[inline(always)]
fn product_by_columns_portable(columns: &[f64], x: &[f64], extra: &[f64], out: &mut [f64]) {
    product_tail(columns, x, extra, out, 0);
}

/// Rows `start..` of [`product_by_columns`] in blocks of four, then two, then one.
#[inline(always)]
fn product_tail(columns: &[f64], x: &[f64], extra: &[f64], out: &mut [f64], mut start: usize) {
    let rows = out.len();
    while start + 4 <= rows {
        rows_by_columns::<4>(columns, x, extra, out, start);
        start += 4;
    }
    if start + 2 <= rows {
        rows_by_columns::<2>(columns, x, extra, out, start);
        start += 2;
    }
    if start < rows {
        rows_by_columns::<1>(columns, x, extra, out, start);
    }
}

/// Rows `start..start + L` of [`product_by_columns`]: their sums in registers while the
/// state's columns and then the extra ones go by (two plain loops: one chained iterator over
/// both cost a 6-state step three times its multiplications).
#[inline(always)]
fn rows_by_columns<const L: usize>(
    columns: &[f64],
    x: &[f64],
    extra: &[f64],
    out: &mut [f64],
    start: usize,
) {
    let rows = out.len();
    let (state, inputs) = columns.split_at(x.len() * rows);
    let mut sums = [0.0f64; L];
    let mut add = |column: &[f64], w: f64| {
        let block = &column[start..start + L];
        for (s, a) in sums.iter_mut().zip(block) {
            *s += a * w;
        }
    };
    for (column, &w) in state.chunks_exact(rows).zip(x) {
        add(column, w);
    }
    for (column, &w) in inputs.chunks_exact(rows).zip(extra) {
        add(column, w);
    }
    out[start..start + L].copy_from_slice(&sums);
}

/// Whether a step of `step` may reuse a map built for `built`: equal but for the rounding of a
/// master's clock. A master on a grid `t0 + k·dt` whose `dt` is not a binary fraction (0.002 s,
/// 1 ms) steps by `t(k+1) − t(k)`, which differs from `dt` by about one unit in the last place
/// of `t`: `k · 2.2e-16` relative, 3e-12 at sample 15,000 and 8e-11 at 360,000 (an hour at
/// 100 Hz). Rebuilding the map for each (an RK4 power, and with sensitivities one per
/// parameter) cost 90 % of a 200 Hz calibration on 20 s and 99 % of a 500 Hz one on 30 s.
/// 1e-9 relative covers a clock to 4.5 million steps; reusing the map changes a step by that
/// at most, far below RK4's own error, and the clock's exact `t(k)` keeps it from adding up.
pub fn same_step(built: f64, step: f64) -> bool {
    (built - step).abs() <= 1e-9 * built.abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The product with AVX (where the CPU has it) and without is the same to the bit, and
    /// both are the row-major dot products, for every row count a block can leave.
    #[test]
    fn the_product_by_columns_is_the_same_with_and_without_avx() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for rows in 1..=41 {
            let (states, inputs) = (rows, 5);
            let columns: Vec<f64> = (0..rows * (states + inputs)).map(|_| next()).collect();
            let x: Vec<f64> = (0..states).map(|_| next() * 1e3).collect();
            let extra: Vec<f64> = (0..inputs).map(|_| next()).collect();
            let mut portable = vec![0.0; rows];
            product_by_columns_portable(&columns, &x, &extra, &mut portable);
            let dot: Vec<f64> = (0..rows)
                .map(|r| {
                    x.iter()
                        .chain(&extra)
                        .enumerate()
                        .fold(0.0, |s, (c, w)| s + columns[c * rows + r] * w)
                })
                .collect();
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&portable), bits(&dot), "{rows} rows");
            let mut dispatched = vec![0.0; rows];
            product_by_columns(&columns, &x, &extra, &mut dispatched);
            assert_eq!(bits(&dispatched), bits(&dot), "{rows} rows");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx") {
                let mut avx = vec![0.0; rows];
                // SAFETY: the CPU has AVX.
                #[allow(unsafe_code)]
                unsafe {
                    product_by_columns_avx(&columns, &x, &extra, &mut avx)
                };
                assert_eq!(bits(&avx), bits(&dot), "{rows} rows with AVX");
            }
        }
    }
    use crate::effects::Effects;
    use crate::model::ShearModel;
    use numerics::ode::rk4_substeps;
    use structure::Structure;

    /// A master's clock at 500 Hz, 100 Hz and 322.58 Hz steps by `t(k+1) − t(k)`: over an
    /// hour's samples every step reuses the map of the nominal step (the clock's rounding grows
    /// with `t`; the old bar of 1e-12 rebuilt it from sample 4,500 on at 500 Hz), and a step
    /// one part in 1e-6 off does not.
    #[test]
    fn a_clock_of_any_rate_reuses_its_map_over_an_hour() {
        for rate in [500.0, 100.0, 322.58] {
            let dt = 1.0 / rate;
            let steps = (3600.0 * rate) as u64;
            for k in (0..steps).step_by(97) {
                let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
                assert!(same_step(dt, t1 - t0), "{rate} Hz, step {k}: {}", t1 - t0);
            }
            assert!(!same_step(dt, dt * (1.0 + 1e-6)));
        }
    }

    /// Five storeys, all different, under a force at floor 4 with the control force on floor 2
    /// and under ground acceleration: the step map built from the matrix polynomial equals RK4
    /// stepped directly on the model's accelerations (numerics' stepper, 10 states) to rounding.
    /// Measured worst 2.7e-15 of the peak; the bar is 1e-12.
    #[test]
    fn the_step_map_equals_rk4_stepped_directly_for_five_storeys() {
        for excitation in [Excitation::Force { floor: 4 }, Excitation::Base] {
            let structure = Structure {
                mass: vec![4.6, 5.3, 4.9, 5.8, 4.1],
                damping: vec![8.1, 3.7, 2.6, 1.2, 0.4],
                stiffness: vec![3850.0, 4100.0, 4680.0, 3300.0, 5100.0],
                excitation,
            };
            let mut params = ShearParameters::from_structure(&structure);
            params.substeps = 16;
            params.control_floor = 2;
            let model = ShearModel::new(params.clone(), Effects::default());
            let h = 1.0 / 51.2;
            let map = LinearStepMap::new(&params, h);
            let (mut a, mut b) = (vec![0.0; 10], [0.0; 10]);
            let (mut peak, mut worst) = (0.0f64, 0.0f64);
            for k in 0..1000 {
                let signal = |k: usize| (0.37 * k as f64).sin() + 0.5 * (1.3 * k as f64).cos();
                let control = |k: usize| 0.3 * (0.11 * k as f64).cos();
                let inputs = StepInputs {
                    excitation: signal(k),
                    excitation_slope: (signal(k + 1) - signal(k)) / h,
                    control: control(k),
                    control_slope: (control(k + 1) - control(k)) / h,
                };
                a = map.apply(&a, &inputs);
                b = rk4_substeps(
                    |tau, x: &[f64; 10]| {
                        let mut acc = [0.0; 5];
                        model.accelerations_into(
                            &x[..5],
                            &x[5..],
                            inputs.excitation + inputs.excitation_slope * tau,
                            inputs.control + inputs.control_slope * tau,
                            &mut acc,
                        );
                        std::array::from_fn(|i| if i < 5 { x[5 + i] } else { acc[i - 5] })
                    },
                    0.0,
                    &b,
                    h,
                    16,
                );
                for i in 0..10 {
                    peak = peak.max(b[i].abs());
                    worst = worst.max((a[i] - b[i]).abs());
                }
            }
            println!("{excitation:?}: {worst:e} of {peak:e}");
            assert!(peak > 1e-4, "the run moves: peak {peak:e}");
            assert!(
                worst <= 1e-12 * peak,
                "map vs direct RK4: {worst:e} of {peak:e}"
            );
        }
    }

    /// The product by columns equals the row-major dot products to the bit, for row counts
    /// with and without a remainder past the blocks of four (the rig's 6 states, 7, 20).
    #[test]
    fn the_product_by_columns_equals_the_dot_products_to_the_bit() {
        for rows in [1usize, 6, 7, 20] {
            let (states, extra) = (rows, 5);
            let width = states + extra;
            let entry = |r: usize, c: usize| ((r * 31 + c * 17) as f64 * 0.37).sin() / 3.0;
            let x: Vec<f64> = (0..states).map(|i| (i as f64 * 1.3).cos() * 1e-3).collect();
            let u: Vec<f64> = (0..extra).map(|j| 2.0 - j as f64 * 0.7).collect();
            let columns: Vec<f64> = (0..width)
                .flat_map(|c| (0..rows).map(move |r| entry(r, c)))
                .collect();
            let mut out = vec![0.0; rows];
            super::product_by_columns(&columns, &x, &u, &mut out);
            for (r, got) in out.iter().enumerate() {
                let mut sum = 0.0;
                for (c, w) in x.iter().chain(&u).enumerate() {
                    sum += entry(r, c) * w;
                }
                assert_eq!(got.to_bits(), sum.to_bits(), "row {r} of {rows}");
            }
        }
    }
}
