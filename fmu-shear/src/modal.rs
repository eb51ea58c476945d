//! The linear model's derivatives through its modes, for a least-squares fit's normal equations
//! and for a band over a whole record, without a sensitivity state per parameter.
//!
//! The state's map of one step is a function of `A` ([`crate::linear::LinearStepMap`]: RK4's
//! polynomial, composed over the sub-steps), so on `A = V Λ V⁻¹` it acts mode by mode: from
//! rest, `x_k = Σⱼ vⱼ βⱼ zⱼₖ` with `βⱼ = wⱼᵀ b` (`wⱼᵀ` the rows of `V⁻¹`) and `zⱼ` the scalar
//! recursion `zⱼ,ₖ₊₁ = φ(λⱼ) zⱼₖ + γ₀(λⱼ) eₖ + γ₁(λⱼ) ėₖ` of the same sub-steps. A parameter
//! moves each mode's eigenvalue (`λⱼ' = wⱼᵀ A' vⱼ`) and its projector
//! (`Pⱼ' = Σᵢ≠ⱼ (Pᵢ A' Pⱼ + Pⱼ A' Pᵢ)/(λⱼ − λᵢ)`, simple eigenvalues), so an output's derivative
//! is a fixed linear combination of `zⱼ`, `∂zⱼ/∂λ` (a second scalar recursion) and the input
//! (the state, from rest `Σⱼ vⱼ βⱼ zⱼ`, folded into the `zⱼ` terms): `∂yₖ/∂θ = K ζₖ`, `ζₖ` of
//! `4N + 1` entries. Per sample that is O(N) recursions and one row of `ζ`; a fit's
//! `Jᵀ J` is `K (Σₖ ζₖ ζₖᵀ) Kᵀ` — one Gram matrix of `ζ` for every channel and parameter, where
//! the sensitivity state costs `2N × 3N × 2N` a sample ([`crate::batch`]).
//!
//! The derivatives are those of the same discrete map as [`crate::batch`]'s (to rounding: the
//! eigenvectors' conditioning enters), and exist only for distinct eigenvalues: for a repeated
//! (or nearly repeated) one, [`Modal::new`] says None and the caller takes the sensitivity
//! state. A conjugate pair enters once, as twice its real part.

use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::solvers::DenseSolveCore;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use nalgebra::{Complex, DMatrix, DVector, SMatrix};
use structure::Excitation;

use crate::batch::LinearRecord;
use crate::linear::{sparse_row, AccelerationRows, LinearStepMap, StepInputs};
use crate::model::ShearParameters;

type C64 = Complex<f64>;

/// Two eigenvalues closer than this share of the largest are taken as repeated.
const DISTINCT: f64 = 1e-7;

/// Samples whose `ζ` are built before their block's Gram product.
const BLOCK: usize = 256;

/// One mode's scalar step and its derivative in the eigenvalue.
#[derive(Clone, Copy, Debug)]
struct ModeStep {
    phi: C64,
    g0: C64,
    g1: C64,
    dphi: C64,
    dg0: C64,
    dg1: C64,
}

/// RK4's map of `n` sub-steps of `ż = λ z + e` with the input a ramp (`e' = ė`), and its
/// derivative in `λ`: the block system `[[F, 0], [E, F]]` on `[z, e, ė, ∂z/∂λ, …]`, `E` the
/// derivative of `F` in `λ` — its lower-left block after the steps is the derivative of the
/// upper-left (as `crate::sensitivity` does for the state).
fn mode_step(lambda: C64, step: f64, substeps: u32) -> ModeStep {
    let one = C64::new(1.0, 0.0);
    let mut b = Block6::zeros();
    for o in [0, 3] {
        b[(o, o)] = lambda;
        b[(o, o + 1)] = one;
        b[(o + 1, o + 2)] = one;
    }
    b[(3, 0)] = one;
    let n = substeps.max(1);
    let r = power(&rk4(&(b * C64::new(step / f64::from(n), 0.0))), n);
    ModeStep {
        phi: r[(0, 0)],
        g0: r[(0, 1)],
        g1: r[(0, 2)],
        dphi: r[(3, 0)],
        dg0: r[(3, 1)],
        dg1: r[(3, 2)],
    }
}

/// The block system of [`mode_step`]: fixed size, on the stack.
type Block6 = SMatrix<C64, 6, 6>;

fn rk4(hf: &Block6) -> Block6 {
    let id = Block6::identity();
    let mut r = id + hf / C64::new(4.0, 0.0);
    r = id + hf * r / C64::new(3.0, 0.0);
    r = id + hf * r / C64::new(2.0, 0.0);
    id + hf * r
}

fn power(m: &Block6, mut n: u32) -> Block6 {
    let mut result = Block6::identity();
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

/// The modes of `A` (2N): eigenvalues, right eigenvectors (columns of `v`), `V⁻¹` (`wt`), and
/// the modes that enter (one of each conjugate pair with weight 2, a real one with weight 1).
struct Modes {
    lambda: Vec<C64>,
    v: DMatrix<C64>,
    wt: DMatrix<C64>,
    /// (mode, weight)
    kept: Vec<(usize, f64)>,
    /// `wⱼᵀ b` of every mode, `b` the excitation's column.
    beta: Vec<C64>,
}

impl Modes {
    fn new(rows: &AccelerationRows) -> Option<Modes> {
        let n = rows.b_excitation.len();
        let s = 2 * n;
        let a = Mat::<f64>::from_fn(s, s, |r, c| {
            if r < n {
                f64::from(u8::from(c == n + r))
            } else {
                rows.a[(r - n, c)]
            }
        });
        let eigen = a.eigen().ok()?;
        let values = eigen.S().column_vector();
        let vectors = eigen.U();
        let lambda: Vec<C64> = (0..s).map(|j| values[j]).collect();
        let v = DMatrix::from_fn(s, s, |r, c| vectors[(r, c)]);
        // V⁻¹ by faer's LU (ten times nalgebra's at 40 states); a singular V shows as
        // non-finite entries, refused below.
        let inverse = Mat::<C64>::from_fn(s, s, |r, c| vectors[(r, c)])
            .partial_piv_lu()
            .inverse();
        let wt = DMatrix::from_fn(s, s, |r, c| inverse[(r, c)]);
        let scale = lambda.iter().map(|l| l.norm()).fold(0.0, f64::max);
        let distinct = (0..s).all(|i| {
            (0..i).all(|j| (lambda[i] - lambda[j]).norm() > DISTINCT * scale.max(f64::MIN_POSITIVE))
        });
        let (upper, lower) = (
            lambda.iter().filter(|l| l.im > 0.0).count(),
            lambda.iter().filter(|l| l.im < 0.0).count(),
        );
        let finite = wt
            .iter()
            .chain(v.iter())
            .all(|x| x.re.is_finite() && x.im.is_finite());
        if !distinct || upper != lower || !finite {
            return None;
        }
        let kept = (0..s)
            .filter_map(|j| {
                let im = lambda[j].im;
                if im > 0.0 {
                    Some((j, 2.0))
                } else {
                    (im == 0.0).then_some((j, 1.0))
                }
            })
            .collect();
        let mut modes = Modes {
            lambda,
            v,
            wt,
            kept,
            beta: Vec::new(),
        };
        modes.beta = modes.project_rows(&rows.b_excitation);
        Some(modes)
    }

    /// `1/(λⱼ − λᵢ)` at `(i, m)` for each kept mode `m = jₘ`, 0 at `i = jₘ`.
    fn inverse_gaps(&self) -> DMatrix<C64> {
        let s = self.lambda.len();
        DMatrix::from_fn(s, self.kept.len(), |i, m| {
            let j = self.kept[m].0;
            if i == j {
                C64::new(0.0, 0.0)
            } else {
                C64::new(1.0, 0.0) / (self.lambda[j] - self.lambda[i])
            }
        })
    }

    /// `wⱼᵀ [0; q]` for every mode: a vector on the acceleration rows in modal coordinates.
    fn project_rows(&self, q: &[f64]) -> Vec<C64> {
        let n = q.len();
        (0..self.lambda.len())
            .map(|j| (0..n).map(|r| self.wt[(j, n + r)] * q[r]).sum())
            .collect()
    }
}

/// The derivatives of the measured accelerations through the modes: `∂yₖ/∂(direction a)` is
/// row `a` of `coefficients[slot]` times `ζₖ` (`[Re z, Im z, Re ∂z/∂λ, Im ∂z/∂λ]` of each kept
/// mode, then the excitation). A run starts at rest, so the state is the modes' sum
/// `xₖ = Σⱼ vⱼ βⱼ zⱼₖ`: its part of a derivative is folded into the modes' `z` coefficients and
/// `ζ` carries no state (`4 · kept + 1` entries, not `4 · kept + 2N + 1`).
pub struct Modal {
    map: LinearStepMap,
    steps: Vec<ModeStep>,
    /// Per measured slot, d × L.
    coefficients: Vec<DMatrix<f64>>,
    /// Per slot: the acceleration row's nonzero entries and the excitation's coefficient.
    outputs: Vec<(Vec<(usize, f64)>, f64)>,
    base: bool,
    states: usize,
}

impl Modal {
    /// For `params` stepped by `dt`, the accelerometers on `floors` (0-based) and the
    /// `directions` (3N × d, in `m1..mN, c1..cN, k1..kN`); None when the eigenvalues are not
    /// distinct (or not finite).
    pub fn new(
        params: &ShearParameters,
        dt: f64,
        floors: &[usize],
        directions: &DMatrix<f64>,
    ) -> Option<Modal> {
        let n = params.storeys();
        let s = 2 * n;
        assert_eq!(directions.nrows(), 3 * n, "a direction per parameter");
        let rows = AccelerationRows::new(params);
        let modes = Modes::new(&rows)?;
        let steps = modes
            .kept
            .iter()
            .map(|&(j, _)| mode_step(modes.lambda[j], dt, params.substeps))
            .collect();
        // α = the slots' acceleration rows on the modes (slots × 2N).
        let alpha = Mat::<C64>::from_fn(floors.len(), s, |c, j| {
            (0..s)
                .map(|q| modes.v[(q, j)] * rows.a[(floors[c], q)])
                .sum()
        });
        let derivatives: Vec<AccelerationRows> = (0..3 * n)
            .map(|theta| AccelerationRows::derivative(params, theta))
            .collect();
        let parts = ModeParts::new(&modes, &derivatives, &alpha, floors);
        // One slot's 3N × L coefficients at a time, in one buffer, taken along the directions.
        let mut k = DMatrix::zeros(derivatives.len(), 4 * modes.kept.len() + 1);
        let unit = unit_rows(directions);
        let coefficients = floors
            .iter()
            .enumerate()
            .map(|(slot, _)| {
                assemble(&modes, &parts, &alpha, &derivatives, slot, &mut k);
                along(directions, unit.as_deref(), &k)
            })
            .collect();
        let outputs = floors
            .iter()
            .map(|&f| {
                let sparse = (0..s)
                    .filter_map(|c| Some((c, rows.a[(f, c)])).filter(|(_, a)| *a != 0.0))
                    .collect();
                (sparse, rows.b_excitation[f])
            })
            .collect();
        Some(Modal {
            map: LinearStepMap::new(params, dt),
            steps,
            coefficients,
            outputs,
            base: matches!(params.excitation, Excitation::Base),
            states: s,
        })
    }

    /// The length of `ζₖ`.
    pub fn width(&self) -> usize {
        4 * self.steps.len() + 1
    }

    /// Per slot, the d × L coefficients of `ζ`.
    pub fn coefficients(&self) -> &[DMatrix<f64>] {
        &self.coefficients
    }

    /// Run over `record` from rest: `each(k0, predictions, zeta)` for each block of samples from
    /// `k0`, `predictions[slot][b]` what the accelerometer of `slot` reads at sample `k0 + b`
    /// (as [`crate::batch::accelerations_along`] gives it, to the bit) and `zeta` (L × block,
    /// column-major) their `ζ`.
    pub fn run(&self, record: &LinearRecord, each: impl FnMut(usize, &[Vec<f64>], &[f64])) {
        self.pass(record, true, each);
    }

    /// [`Modal::run`]'s `ζ` alone (`each(k0, zeta)`), without the state the predictions need.
    pub fn zeta(&self, record: &LinearRecord, mut each: impl FnMut(usize, &[f64])) {
        self.pass(record, false, |k0, _, zeta| each(k0, zeta));
    }

    fn pass(
        &self,
        record: &LinearRecord,
        predict: bool,
        mut each: impl FnMut(usize, &[Vec<f64>], &[f64]),
    ) {
        let (s, width) = (self.states, self.width());
        let e = record.excitation;
        let samples = e.len();
        let mut x = vec![0.0; s];
        let mut next = vec![0.0; s];
        let mut z = vec![C64::new(0.0, 0.0); self.steps.len()];
        let mut w = z.clone();
        let mut zeta = vec![0.0; width * BLOCK];
        let mut predictions = vec![Vec::with_capacity(BLOCK); self.outputs.len()];
        let mut start = 0;
        while start < samples {
            let len = BLOCK.min(samples - start);
            predictions.iter_mut().for_each(Vec::clear);
            for b in 0..len {
                let k = start + b;
                let slope = e.get(k + 1).map_or(0.0, |after| (after - e[k]) / record.dt);
                let column = &mut zeta[b * width..(b + 1) * width];
                for (m, (zm, wm)) in z.iter().zip(&w).enumerate() {
                    column[4 * m..4 * m + 4].copy_from_slice(&[zm.re, zm.im, wm.re, wm.im]);
                }
                column[4 * self.steps.len()] = e[k];
                for ((step, zm), wm) in self.steps.iter().zip(&mut z).zip(&mut w) {
                    let input = step.g0 * e[k] + step.g1 * slope;
                    *wm = step.phi * *wm + step.dphi * *zm + step.dg0 * e[k] + step.dg1 * slope;
                    *zm = step.phi * *zm + input;
                }
                if !predict {
                    continue;
                }
                for ((sparse, b_e), out) in self.outputs.iter().zip(&mut predictions) {
                    let value = sparse_row(b_e * e[k], sparse, &x);
                    out.push(if self.base { value + e[k] } else { value });
                }
                let inputs = StepInputs {
                    excitation: e[k],
                    excitation_slope: slope,
                    control: 0.0,
                    control_slope: 0.0,
                };
                self.map.apply_into(&x, &inputs, &mut next);
                std::mem::swap(&mut x, &mut next);
            }
            each(start, &predictions, &zeta[..width * len]);
            start += len;
        }
    }
}

/// What each parameter does to each kept mode: the measured slots' coefficient of `zⱼ` through
/// the projector's part in the other modes and through the state at a fixed state (`A'`'s row of
/// the slot's floor times `vⱼ βⱼ`: the state from rest is `Σⱼ vⱼ βⱼ zⱼ`) (`outputs`: slots ×
/// (3N · kept), column `θ · kept + m`), its part through the mode itself (`own`, to be taken
/// times αⱼ) and the eigenvalue's derivative (`dlambda`), both 3N × kept; the slots' floors.
struct ModeParts {
    floors: Vec<usize>,
    outputs: Mat<C64>,
    own: DMatrix<C64>,
    dlambda: DMatrix<C64>,
}

impl ModeParts {
    /// `Wᵀ A' V` is needed in the kept modes' columns and rows. `A'` is nonzero only in the
    /// acceleration rows, and there in one row (a mass) or two (a storey's damping or
    /// stiffness): with `Y = A'_a V` (those rows only) every entry is a sum over at most two
    /// rows. The outputs' part `Σᵢ αᵢ (Wᵀ A' V)ᵢⱼ βⱼ / (λⱼ − λᵢ)` is `βⱼ Σᵣ Yᵣⱼ Gⱼ[r]`, with
    /// `Gⱼ = (α ∘ 1/(λⱼ − λ)) Wᵀ_a` the same for every parameter: one product per kept mode, and
    /// O(N) a parameter after it (where a dense `Wᵀ A' V` costs O(N³) a parameter).
    fn new(
        modes: &Modes,
        derivatives: &[AccelerationRows],
        alpha: &Mat<C64>,
        floors: &[usize],
    ) -> ModeParts {
        let s = modes.lambda.len();
        let n = s / 2;
        let p = derivatives.len();
        let kept = modes.kept.len();
        let slots = alpha.nrows();
        // gaps[(i, m)] = 1/(λⱼ − λᵢ) and weighted[(i, m)] = βᵢ/(λⱼ − λᵢ) for kept mode m = jₘ.
        let gaps = modes.inverse_gaps();
        let weighted = Mat::<C64>::from_fn(s, kept, |i, m| modes.beta[i] * gaps[(i, m)]);
        let wt_acc = Mat::<C64>::from_fn(s, n, |i, r| modes.wt[(i, n + r)]);
        // g: (kept · slots) × N, rows m · slots.. = Gⱼₘ, one product for every kept mode.
        let scaled = Mat::<C64>::from_fn(kept * slots, s, |row, i| {
            alpha[(row % slots, i)] * gaps[(i, row / slots)]
        });
        let mut g = Mat::<C64>::zeros(kept * slots, n);
        matmul(
            g.as_mut(),
            Accum::Replace,
            scaled.as_ref(),
            wt_acc.as_ref(),
            C64::new(1.0, 0.0),
            Par::Seq,
        );
        let mut outputs = Mat::<C64>::zeros(slots, p * kept);
        let mut own = DMatrix::<C64>::zeros(p, kept);
        let mut dlambda = DMatrix::<C64>::zeros(p, kept);
        for (theta, d) in derivatives.iter().enumerate() {
            let y = SparseRows::new(d, &modes.v);
            for (m, &(j, _)) in modes.kept.iter().enumerate() {
                let col = theta * kept + m;
                let beta = modes.beta[j];
                for (slot, floor) in floors.iter().enumerate() {
                    let through: C64 = y
                        .rows
                        .iter()
                        .zip(&y.values)
                        .map(|(&r, yr)| {
                            let state = if r == *floor {
                                yr[j]
                            } else {
                                C64::new(0.0, 0.0)
                            };
                            yr[j] * g[(m * slots + slot, r)] + state
                        })
                        .sum();
                    outputs[(slot, col)] = through * beta;
                }
                // βⱼ' = wⱼᵀ b': b' is nonzero where the excitation's coefficient moves.
                let mut sum: C64 = d
                    .b_excitation
                    .iter()
                    .enumerate()
                    .filter(|(_, b)| **b != 0.0)
                    .map(|(r, b)| modes.wt[(j, n + r)] * *b)
                    .sum();
                let mut eigen = C64::new(0.0, 0.0);
                for (&r, yr) in y.rows.iter().zip(&y.values) {
                    let w = modes.wt[(j, n + r)];
                    let h: C64 = (0..s).map(|i| yr[i] * weighted[(i, m)]).sum();
                    sum += w * h;
                    eigen += w * yr[j];
                }
                own[(theta, m)] = sum;
                dlambda[(theta, m)] = eigen;
            }
        }
        ModeParts {
            floors: floors.to_vec(),
            outputs,
            own,
            dlambda,
        }
    }
}

/// `Y = A'_a V` on the acceleration rows where `A'` has a nonzero entry.
struct SparseRows {
    rows: Vec<usize>,
    values: Vec<Vec<C64>>,
}

impl SparseRows {
    fn new(d: &AccelerationRows, v: &DMatrix<C64>) -> SparseRows {
        let (n, s) = (d.a.nrows(), d.a.ncols());
        let mut rows = Vec::new();
        let mut values = Vec::new();
        for r in 0..n {
            let entries: Vec<(usize, f64)> = (0..s)
                .map(|c| (c, d.a[(r, c)]))
                .filter(|(_, a)| *a != 0.0)
                .collect();
            if entries.is_empty() {
                continue;
            }
            rows.push(r);
            values.push(
                (0..s)
                    .map(|i| entries.iter().map(|&(c, a)| v[(c, i)] * a).sum())
                    .collect(),
            );
        }
        SparseRows { rows, values }
    }
}

/// The derivatives' coefficients of `ζ` of the slot `(slot, floor)` along the 3N parameters,
/// into `k` (3N × L): each kept mode's `zⱼ` (`Σᵢ … + αⱼ own`, the first with the state's part
/// at a fixed state, see [`ModeParts`]) and `∂zⱼ/∂λ` (`αⱼ βⱼ λⱼ'`), as twice the real part of a
/// conjugate pair, then the excitation's at a fixed state.
fn assemble(
    modes: &Modes,
    parts: &ModeParts,
    alpha: &Mat<C64>,
    derivatives: &[AccelerationRows],
    slot: usize,
    k: &mut DMatrix<f64>,
) {
    let kept = modes.kept.len();
    let cz = &parts.outputs;
    // Column by column (the matrix's order): a mode's four, then the excitation's, each down
    // the parameters.
    for (m, &(j, weight)) in modes.kept.iter().enumerate() {
        let a = alpha[(slot, j)];
        let ab = a * modes.beta[j];
        for theta in 0..derivatives.len() {
            let z = cz[(slot, theta * kept + m)] + a * parts.own[(theta, m)];
            let w = ab * parts.dlambda[(theta, m)];
            k[(theta, 4 * m)] = weight * z.re;
            k[(theta, 4 * m + 1)] = -weight * z.im;
            k[(theta, 4 * m + 2)] = weight * w.re;
            k[(theta, 4 * m + 3)] = -weight * w.im;
        }
    }
    for (theta, d) in derivatives.iter().enumerate() {
        k[(theta, 4 * kept)] = d.b_excitation[parts.floors[slot]];
    }
}

/// The parameter each direction is, when every direction is one parameter (a unit column).
fn unit_rows(directions: &DMatrix<f64>) -> Option<Vec<usize>> {
    directions
        .column_iter()
        .map(|d| {
            let mut nonzero = d.iter().enumerate().filter(|(_, x)| **x != 0.0);
            match (nonzero.next(), nonzero.next()) {
                (Some((j, &x)), None) => (x == 1.0).then_some(j),
                _ => None,
            }
        })
        .collect()
}

/// `directionsᵀ k`: the coefficients along the directions; where every direction is one
/// parameter (`unit`, from [`unit_rows`]), their rows.
fn along(directions: &DMatrix<f64>, unit: Option<&[usize]>, k: &DMatrix<f64>) -> DMatrix<f64> {
    match unit {
        // Every parameter in its own order: `k` itself.
        Some(rows) if rows.len() == k.nrows() && rows.iter().enumerate().all(|(a, &r)| a == r) => {
            k.clone()
        }
        Some(rows) => DMatrix::from_fn(rows.len(), k.ncols(), |a, l| k[(rows[a], l)]),
        // faer's product, sequential: nalgebra's (matrixmultiply) packs into megabyte buffers
        // that a process touches fresh each call, 25 % of a 20-storey compare's page faults.
        None => {
            let (rows, d) = directions.shape();
            let mut out = DMatrix::zeros(d, k.ncols());
            let (out_rows, out_cols) = out.shape();
            matmul(
                MatMut::from_column_major_slice_mut(out.as_mut_slice(), out_rows, out_cols),
                Accum::Replace,
                MatRef::from_column_major_slice(directions.as_slice(), rows, d).transpose(),
                MatRef::from_column_major_slice(k.as_slice(), k.nrows(), k.ncols()),
                1.0,
                Par::Seq,
            );
            out
        }
    }
}

/// A least-squares pass over one record: what each slot predicts at every sample, and over the
/// `used` samples each slot's `Σ ∂ŷ ∂ŷᵀ` and `Σ ∂ŷ (y − ŷ)` along the directions.
pub struct Normals {
    pub predictions: Vec<Vec<f64>>,
    pub blocks: Vec<(DMatrix<f64>, DVector<f64>)>,
}

/// [`Normals`] of `modal` over `record`, `measured[slot]` the slot's record, `used` its samples
/// in the fit (ascending).
pub fn normals(
    modal: &Modal,
    record: &LinearRecord,
    measured: &[&[f64]],
    used: &[usize],
) -> Normals {
    let width = modal.width();
    let slots = measured.len();
    let mut gram = Mat::<f64>::zeros(width, width);
    let mut projections = Mat::<f64>::zeros(width, slots);
    let mut predictions: Vec<Vec<f64>> = vec![Vec::with_capacity(record.excitation.len()); slots];
    let mut picked = vec![0.0; width * BLOCK];
    let mut residuals = vec![0.0; BLOCK * slots];
    let mut next_used = 0;
    modal.run(record, |k0, block, zeta| {
        let len = block.first().map_or(0, Vec::len);
        let mut count = 0;
        while next_used < used.len() && used[next_used] < k0 + len {
            let b = used[next_used] - k0;
            picked[count * width..(count + 1) * width]
                .copy_from_slice(&zeta[b * width..(b + 1) * width]);
            for slot in 0..slots {
                residuals[slot * BLOCK + count] = measured[slot][k0 + b] - block[slot][b];
            }
            count += 1;
            next_used += 1;
        }
        for (all, part) in predictions.iter_mut().zip(block) {
            all.extend_from_slice(part);
        }
        if count == 0 {
            return;
        }
        let z = MatRef::from_column_major_slice(&picked[..width * count], width, count);
        // Σ ζ ζᵀ is symmetric: its lower half here, mirrored after the pass.
        triangular::matmul(
            gram.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Add,
            z,
            BlockStructure::Rectangular,
            z.transpose(),
            BlockStructure::Rectangular,
            1.0,
            Par::Seq,
        );
        let r = MatRef::from_column_major_slice_with_stride(&residuals, count, slots, BLOCK);
        matmul(projections.as_mut(), Accum::Add, z, r, 1.0, Par::Seq);
    });
    for c in 0..width {
        for r in 0..c {
            gram[(r, c)] = gram[(c, r)];
        }
    }
    let blocks = modal
        .coefficients
        .iter()
        .enumerate()
        .map(|(slot, k)| {
            let kf = MatRef::from_column_major_slice(k.as_slice(), k.nrows(), width);
            let mut kg = Mat::<f64>::zeros(k.nrows(), width);
            matmul(
                kg.as_mut(),
                Accum::Replace,
                kf,
                gram.as_ref(),
                1.0,
                Par::Seq,
            );
            let mut jtj = DMatrix::<f64>::zeros(k.nrows(), k.nrows());
            matmul(
                MatMut::from_column_major_slice_mut(jtj.as_mut_slice(), k.nrows(), k.nrows()),
                Accum::Replace,
                kg.as_ref(),
                kf.transpose(),
                1.0,
                Par::Seq,
            );
            let jtr = DVector::from_fn(k.nrows(), |a, _| {
                (0..width).map(|l| k[(a, l)] * projections[(l, slot)]).sum()
            });
            (jtj, jtr)
        })
        .collect();
    Normals {
        predictions,
        blocks,
    }
}

/// `Σₐ (∂yₖ/∂dₐ)²` per slot and sample of `record` over the directions `dₐ` of `modal`: a
/// band's variance, the directions the rows of its covariance's root. Per block of samples one
/// product of each slot's coefficients with the block's `ζ`.
///
/// `coefficients` are the slots' (all of [`Modal::coefficients`], or some of them: a host may
/// share the slots among threads, each group a pass of its own, the variances the same to the
/// bit).
pub fn band(modal: &Modal, record: &LinearRecord, coefficients: &[DMatrix<f64>]) -> Vec<Vec<f64>> {
    let width = modal.width();
    let samples = record.excitation.len();
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(samples); coefficients.len()];
    let d = coefficients.first().map_or(0, DMatrix::nrows);
    let mut along = Mat::<f64>::zeros(d, BLOCK);
    modal.zeta(record, |_, zeta| {
        let len = zeta.len() / width;
        let z = MatRef::from_column_major_slice(zeta, width, len);
        for (k, variances) in coefficients.iter().zip(&mut out) {
            let kf = MatRef::from_column_major_slice(k.as_slice(), d, width);
            matmul(
                along.as_mut().submatrix_mut(0, 0, d, len),
                Accum::Replace,
                kf,
                z,
                1.0,
                Par::Seq,
            );
            for b in 0..len {
                variances.push(along.col(b).iter().map(|x| x * x).sum());
            }
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::accelerations_along;
    use structure::Structure;

    fn building(n: usize, excitation: Excitation) -> ShearParameters {
        ShearParameters::from_structure(&Structure {
            mass: (0..n).map(|i| 4.0 + 0.3 * (i % 3) as f64).collect(),
            damping: (0..n).map(|i| 2.0 + 0.7 * (i % 4) as f64).collect(),
            stiffness: (0..n).map(|i| 4000.0 - 90.0 * i as f64).collect(),
            excitation,
        })
    }

    /// The largest difference between `K ζₖ` and the sensitivity state's derivatives over
    /// `record`, and the largest derivative; the predictions equal to the bit.
    fn against_the_state(
        params: &ShearParameters,
        record: &LinearRecord,
        directions: &DMatrix<f64>,
    ) -> (f64, f64) {
        let d = directions.ncols();
        let mut want = Vec::new();
        accelerations_along(params, record, directions, |_, v, dv| {
            want.push((v.to_vec(), dv.to_vec()))
        });
        let modal =
            Modal::new(params, record.dt, record.floors, directions).expect("distinct modes");
        let width = modal.width();
        let (mut worst, mut peak) = (0.0f64, 0.0f64);
        modal.run(record, |k0, predictions, zeta| {
            for (b, column) in zeta.chunks_exact(width).enumerate() {
                let (values, derivatives) = &want[k0 + b];
                for (slot, k) in modal.coefficients().iter().enumerate() {
                    assert_eq!(predictions[slot][b], values[slot], "sample {}", k0 + b);
                    for a in 0..d {
                        let got: f64 = (0..width).map(|l| k[(a, l)] * column[l]).sum();
                        let w = derivatives[slot * d + a];
                        peak = peak.max(w.abs());
                        worst = worst.max((got - w).abs());
                    }
                }
            }
        });
        (worst, peak)
    }

    /// Four, twelve and twenty storeys, a force and ground motion: `K ζₖ` is the sensitivity
    /// state's derivative at every sample, and the predictions are its values to the bit.
    /// Measured worst 7.8e-12 of the largest derivative (twenty storeys, ground motion); the bar
    /// 1e-8.
    #[test]
    fn the_modes_give_the_sensitivity_states_derivatives() {
        for (n, excitation) in [
            (4, Excitation::Force { floor: 2 }),
            (4, Excitation::Base),
            (12, Excitation::Force { floor: 1 }),
            (20, Excitation::Base),
        ] {
            let params = building(n, excitation);
            let dt = 1.0 / 51.2;
            let e: Vec<f64> = (0..700)
                .map(|k| (0.37 * k as f64).sin() + 0.5 * (1.3 * k as f64).cos())
                .collect();
            let floors: Vec<usize> = (0..n).step_by(2).chain([n - 1]).collect();
            let d = 5;
            let directions =
                DMatrix::from_fn(3 * n, d, |j, a| ((j * 7 + a * 5) % 11) as f64 / 11.0 - 0.4);
            let record = LinearRecord {
                dt,
                excitation: &e,
                floors: &floors,
            };
            let (worst, peak) = against_the_state(&params, &record, &directions);
            println!("{n} storeys, {excitation:?}: {worst:e} of {peak:e}");
            assert!(peak > 1e-6, "the derivatives move");
            assert!(worst <= 1e-8 * peak, "{worst:e} of {peak:e}");
        }
    }

    /// Storey dampers strong enough to overdamp some modes: their real eigenvalues enter once,
    /// and the derivatives are still the sensitivity state's (measured 2.5e-12 of the largest;
    /// the bar 1e-8).
    #[test]
    fn overdamped_modes_enter_once() {
        let n = 4;
        let mut params = building(n, Excitation::Force { floor: 1 });
        params.damping = vec![900.0, 20.0, 700.0, 3.0];
        let dt = 0.01;
        let e: Vec<f64> = (0..500).map(|k| (0.3 * k as f64).sin()).collect();
        let floors = [0, 3];
        let directions = DMatrix::identity(3 * n, 3 * n);
        let record = LinearRecord {
            dt,
            excitation: &e,
            floors: &floors,
        };
        let rows = AccelerationRows::new(&params);
        let modes = Modes::new(&rows).expect("distinct modes");
        assert!(
            modes.kept.iter().any(|&(_, w)| w == 1.0),
            "some modes are overdamped: {:?}",
            modes.lambda
        );
        let (worst, peak) = against_the_state(&params, &record, &directions);
        println!("{worst:e} of {peak:e}");
        assert!(peak > 0.0 && worst <= 1e-8 * peak, "{worst:e} of {peak:e}");
    }

    /// The band through the modes is the sensitivity state's `Σₐ (∂y/∂dₐ)²`: measured 5e-12 of
    /// the largest value at twelve storeys, the bar 1e-8.
    #[test]
    fn the_band_through_the_modes_is_the_sensitivity_states() {
        let n = 12;
        let params = building(n, Excitation::Force { floor: 3 });
        let dt = 0.01;
        let e: Vec<f64> = (0..900)
            .map(|k| (0.21 * k as f64).sin() + (0.9 * k as f64).cos())
            .collect();
        let floors = [0, 5, 11];
        let d = 3 * n;
        let directions =
            DMatrix::from_fn(3 * n, d, |j, a| ((j * 7 + a * 5) % 11) as f64 / 11.0 - 0.4);
        let record = LinearRecord {
            dt,
            excitation: &e,
            floors: &floors,
        };
        let modal = Modal::new(&params, dt, &floors, &directions).expect("distinct modes");
        let got = band(&modal, &record, modal.coefficients());
        let (mut worst, mut peak) = (0.0f64, 0.0f64);
        accelerations_along(&params, &record, &directions, |k, _, dv| {
            for slot in 0..floors.len() {
                let want: f64 = dv[slot * d..(slot + 1) * d].iter().map(|x| x * x).sum();
                worst = worst.max((got[slot][k] - want).abs());
                peak = peak.max(want);
            }
        });
        println!("{worst:e} of {peak:e}");
        assert!(got.iter().all(|b| b.len() == e.len()));
        assert!(peak > 0.0 && worst <= 1e-8 * peak, "{worst:e} of {peak:e}");
    }

    /// The normal equations from the Gram matrix are those of the derivatives taken sample by
    /// sample (bar 1e-8 of the largest entry).
    #[test]
    fn the_normal_equations_are_the_derivatives_sums() {
        let n = 5;
        let params = building(n, Excitation::Force { floor: 1 });
        let dt = 0.01;
        let e: Vec<f64> = (0..600).map(|k| (0.21 * k as f64).sin()).collect();
        let floors = [0, 2, 4];
        let directions = DMatrix::identity(3 * n, 3 * n);
        let record = LinearRecord {
            dt,
            excitation: &e,
            floors: &floors,
        };
        let measured: Vec<Vec<f64>> = (0..3)
            .map(|c| (0..600).map(|k| (0.05 * (k + c) as f64).cos()).collect())
            .collect();
        let measured_refs: Vec<&[f64]> = measured.iter().map(Vec::as_slice).collect();
        let used: Vec<usize> = (40..600).filter(|k| k % 3 != 1).collect();
        let modal = Modal::new(&params, dt, &floors, &directions).expect("distinct modes");
        let got = normals(&modal, &record, &measured_refs, &used);
        let p = 3 * n;
        let mut jtj = vec![DMatrix::<f64>::zeros(p, p); 3];
        let mut jtr = vec![DVector::<f64>::zeros(p); 3];
        let mut batch_predictions = vec![Vec::new(); jtj.len()];
        accelerations_along(&params, &record, &directions, |k, v, dv| {
            for (all, value) in batch_predictions.iter_mut().zip(v) {
                all.push(*value);
            }
            if used.binary_search(&k).is_err() {
                return;
            }
            for slot in 0..3 {
                let row = DVector::from_column_slice(&dv[slot * p..(slot + 1) * p]);
                jtj[slot] += &row * row.transpose();
                jtr[slot] += &row * (measured[slot][k] - v[slot]);
            }
        });
        // The predictions are the batch's to the bit: the same terms in the same order.
        assert_eq!(
            got.predictions, batch_predictions,
            "the batch's predictions"
        );
        for slot in 0..3 {
            let (a, g) = &got.blocks[slot];
            let scale = jtj[slot].amax();
            assert!(
                (a - &jtj[slot]).amax() <= 1e-8 * scale,
                "JᵀJ of slot {slot}"
            );
            let scale = jtr[slot].amax();
            assert!(
                (g - &jtr[slot]).amax() <= 1e-8 * scale,
                "Jᵀr of slot {slot}"
            );
        }
    }
}
