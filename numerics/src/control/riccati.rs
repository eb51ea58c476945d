//! The continuous-time algebraic Riccati equation of the LQR,
//!
//! ```text
//! AᵀX + XA − XGX + Q = 0,   G = B R⁻¹ Bᵀ,
//! ```
//!
//! for the stabilising solution `X = Xᵀ ⪰ 0` and the gain `K = R⁻¹BᵀX` (`u = −K w`).
//!
//! Written here because no Rust crate solves it robustly. The method is the matrix sign function
//! of the Hamiltonian followed by Newton's method on the equation itself:
//!
//! 1. **Inputs** are checked before any arithmetic: shapes (A n×n, B n×m, Q n×n, R m×m, n, m ≥ 1,
//!    n ≤ [`MAX_STATES`]), finite entries, Q and R symmetric to 1e-12 (relative, Frobenius), R
//!    positive definite (smallest eigenvalue above `m ε` times the largest), Q positive
//!    semidefinite (smallest eigenvalue above `−100 n ε` times the largest magnitude).
//! 2. **Scaling.** `G = BR⁻¹Bᵀ` through the Cholesky factor of R. With `X = σX̃` the equation
//!    becomes one in `σG` and `Q/σ`; `σ = √(‖Q‖/‖G‖)` gives both the same norm (a similarity of the
//!    Hamiltonian by `diag(I, σI)`, which leaves its eigenvalues alone and makes what follows
//!    independent of the units of X: states in millimetres put 10⁶ into G).
//! 3. **The imaginary axis.** The eigenvalues of `H = [[A, −σG], [−Q/σ, −Aᵀ]]` (balanced, real
//!    Schur) are checked against the imaginary axis: the margin `min |Re λ| / ‖H‖_F` (H balanced)
//!    must exceed `100 · 2n · ε` ([`AXIS_TOLERANCE_PER_DIMENSION`], where the choice is argued).
//!    Given a stabilisable (A, B), R ≻ 0 and Q ⪰ 0, a stabilising solution exists exactly when no
//!    eigenvalue lies on the axis; one there means `(Q, A)` has an unobservable mode on the axis.
//! 4. **Sign function.** `Z ← (cZ + (cZ)⁻¹)/2` from `Z = H`, with determinant scaling
//!    `c = |det Z|^(−1/2n)` until the relative change falls below 1e-2, then unscaled, to a
//!    relative change of 1e-10 or until it stops falling (quadratic convergence has then reached
//!    rounding). `W = sign(H)`; the stable invariant subspace is the null space of `W + I`, so
//!    `[W₁₂; W₂₂ + I] X̃ = −[W₁₁ + I; W₂₁]`, solved by least squares (thin QR), symmetrised.
//! 5. **Newton–Kleinman polishing** in the original units: `A_c = A − GX`, solve the Lyapunov
//!    equation `A_cᵀΔ + ΔA_c = −Res(X)` for symmetric Δ, `X ← X + Δ`, while the relative residual
//!    at least halves (at most 20 steps; usually one or two from the sign function's answer). The
//!    Lyapunov equation is solved as a dense linear system in the `n(n+1)/2` unknowns of Δ
//!    (LU with partial pivoting, O(n⁶) work): fine to [`MAX_STATES`] = 40 states, the limit.
//! 6. **Checks on the answer**: relative residual ([`Care::relative_residual`]) at most 1e-10,
//!    X positive semidefinite (smallest eigenvalue at least `−1e-10 ‖X‖₂`), every pole of
//!    `A − BK` strictly in the left half plane. Any failure is an error, never a gain.

// The checks are written `!(value < limit)` on purpose: a NaN must fail them.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::linalg::balancing::balance_parlett_reinsch;
use nalgebra::{Complex, DMatrix, DVector, Schur};

/// The largest state dimension accepted: the polishing's Lyapunov solve is a dense system in
/// `n(n+1)/2` unknowns (820 at n = 40, a fraction of a second).
pub const MAX_STATES: usize = 40;

/// The imaginary-axis test's tolerance per dimension of the Hamiltonian: an eigenvalue with
/// `|Re λ| ≤ 100 · 2n · ε · ‖H‖_F` (H balanced) is taken to be on the axis. The QR algorithm's
/// backward error is a small multiple of `2n ε ‖H‖`, so a simple eigenvalue nearer the axis cannot
/// be told from one on it; a relative tolerance much larger would refuse real problems (the shear
/// model in millimetres at q = 10⁶ has a closed-loop pole at −7·10⁻⁴ beside ‖H‖ ~ 10⁶: margin
/// ~10⁻⁹). Eigenvalues on the axis are double (λ and −λ̄ coincide) and, when defective, rounding
/// can move them O(√ε) off it; those pass this test and are caught by the ones after it (the
/// sign iteration's convergence, the residual, the stability of A − BK), whose errors also say
/// that no stabilising solution was found.
pub const AXIS_TOLERANCE_PER_DIMENSION: f64 = 100.0 * f64::EPSILON;

/// The PBH rank test's tolerance: `σ_min([A − λI, B]) ≤ 1.5e-7 ‖[A, B]‖_F` means λ is not
/// controllable (10 √ε: an uncontrollable eigenvalue that is defective is known only to O(√ε)).
pub const STABILISABILITY_TOLERANCE: f64 = 1.5e-7;

/// The relative residual the answer must reach (after polishing).
pub const RESIDUAL_TOLERANCE: f64 = 1e-10;

const SYMMETRY_TOLERANCE: f64 = 1e-12;
const PSD_TOLERANCE: f64 = 1e-10;
const MAX_SIGN_ITERATIONS: usize = 100;
const SIGN_TOLERANCE: f64 = 1e-10;
const MAX_POLISHING_STEPS: usize = 20;
const MAX_SCHUR_ITERATIONS: usize = 10_000;

/// The stabilising solution of `AᵀX + XA − XBR⁻¹BᵀX + Q = 0` (the LQR's CARE), with the checks
/// made on it.
#[derive(Debug, Clone, PartialEq)]
pub struct Care {
    /// X, n×n, symmetric positive semidefinite.
    pub x: DMatrix<f64>,
    /// `K = R⁻¹BᵀX`, m×n; the control law is `u = −K w`.
    pub gain: DMatrix<f64>,
    /// `‖AᵀX + XA − XGX + Q‖_F / (‖Q‖_F + 2‖AᵀX‖_F + ‖XGX‖_F)`, `G = BR⁻¹Bᵀ` (0 when X = Q = 0).
    pub relative_residual: f64,
    /// The eigenvalues of `A − BK`, sorted by imaginary part, then real part.
    pub closed_loop_poles: Vec<Complex<f64>>,
    /// `min |Re λ(H)| / ‖H‖_F`, H the Hamiltonian with Q and G scaled to equal norms (step 2 of
    /// the module doc) and balanced (Parlett–Reinsch): how far H's spectrum is from the imaginary
    /// axis, relative to the scale of its rounding errors.
    pub hamiltonian_margin: f64,
    /// Newton iterations of the sign function.
    pub sign_iterations: usize,
    /// Newton–Kleinman steps accepted while polishing.
    pub polishing_steps: usize,
}

/// Why no solution was returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RiccatiError {
    #[error("{matrix} is {rows}×{cols}, expected {expected}")]
    Dimensions {
        matrix: &'static str,
        expected: String,
        rows: usize,
        cols: usize,
    },
    #[error("{matrix}[({row}, {col})] is not finite ({value})")]
    NonFinite {
        matrix: &'static str,
        row: usize,
        col: usize,
        value: f64,
    },
    #[error(
        "{matrix} is not symmetric: ‖{matrix} − {matrix}ᵀ‖_F / ‖{matrix}‖_F = {relative_asymmetry:e} \
         (tolerance 1e-12)"
    )]
    NotSymmetric {
        matrix: &'static str,
        relative_asymmetry: f64,
    },
    #[error(
        "R is not symmetric positive definite: its smallest eigenvalue is {min_eigenvalue:e} \
         (largest {max_eigenvalue:e})"
    )]
    RNotPositiveDefinite {
        min_eigenvalue: f64,
        max_eigenvalue: f64,
    },
    #[error(
        "Q is not symmetric positive semidefinite: its smallest eigenvalue is {min_eigenvalue:e} \
         (largest {max_eigenvalue:e})"
    )]
    QNotPositiveSemidefinite {
        min_eigenvalue: f64,
        max_eigenvalue: f64,
    },
    #[error(
        "no stabilising solution: the system is not stabilisable or (Q, A) has an unobservable \
         mode on the imaginary axis (the Hamiltonian has the eigenvalue {eigenvalue}, \
         min |Re λ|/‖H‖ = {margin:e} ≤ {tolerance:e})"
    )]
    ImaginaryAxisEigenvalue {
        eigenvalue: Complex<f64>,
        margin: f64,
        tolerance: f64,
    },
    #[error(
        "no stabilising solution: the system is not stabilisable (A's eigenvalue {eigenvalue} is \
         not in the open left half plane and not controllable: σ_min([A − λI, B]) / ‖[A, B]‖_F = \
         {distance:e} ≤ {tolerance:e})"
    )]
    NotStabilisable {
        eigenvalue: Complex<f64>,
        distance: f64,
        tolerance: f64,
    },
    #[error(
        "the sign-function iteration did not converge in {iterations} iterations (last relative \
         change {change:e}): the Hamiltonian has eigenvalues too near the imaginary axis, so there \
         may be no stabilising solution"
    )]
    NoConvergence { iterations: usize, change: f64 },
    #[error("{what} is singular to working precision")]
    Singular { what: &'static str },
    #[error("the eigenvalues of {what} did not converge")]
    Eigenvalues { what: &'static str },
    #[error("relative residual {relative_residual:e} after polishing, above the tolerance 1e-10")]
    ResidualTooLarge { relative_residual: f64 },
    #[error(
        "X is not positive semidefinite: its smallest eigenvalue is {min_eigenvalue:e} \
         (largest {max_eigenvalue:e})"
    )]
    XNotPositiveSemidefinite {
        min_eigenvalue: f64,
        max_eigenvalue: f64,
    },
    #[error(
        "no stabilising solution found: the closed loop A − BK has the pole {pole} (the system \
         is not stabilisable or (Q, A) has an unobservable mode on or near the imaginary axis)"
    )]
    UnstableClosedLoop { pole: Complex<f64> },
    #[error(
        "{n} states: the Newton polishing's Lyapunov solve (dense, O(n⁶)) is limited to {max}"
    )]
    TooManyStates { n: usize, max: usize },
}

/// Solves the LQR's CARE `AᵀX + XA − XBR⁻¹BᵀX + Q = 0` for its stabilising solution; A n×n,
/// B n×m, Q n×n symmetric positive semidefinite, R m×m symmetric positive definite. The method
/// and every check are in the module documentation.
pub fn solve_care(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<Care, RiccatiError> {
    let (n, m) = check_dimensions(a, b, q, r)?;
    for (name, matrix) in [("A", a), ("B", b), ("Q", q), ("R", r)] {
        check_finite(name, matrix)?;
    }
    let q = symmetric_part("Q", q)?;
    let r = symmetric_part("R", r)?;

    let r_inv_bt = check_weights(&q, &r, b, n, m)?;
    // G = B R⁻¹ Bᵀ, symmetric by construction up to rounding.
    let g = symmetrised(b * &r_inv_bt);

    check_stabilisable(a, b)?;

    // Step 2: X = σ X̃ with ‖σG‖ = ‖Q/σ‖.
    let (q_norm, g_norm) = (q.norm(), g.norm());
    let sigma = if q_norm > 0.0 && g_norm > 0.0 {
        (q_norm / g_norm).sqrt()
    } else {
        1.0
    };
    let h = hamiltonian(a, &(&g * sigma), &(&q / sigma));

    // Step 3: the imaginary axis.
    let (eigenvalues, h_norm) = eigenvalues_and_balanced_norm(h.clone(), "the Hamiltonian")?;
    let axis_tolerance = AXIS_TOLERANCE_PER_DIMENSION * (2 * n) as f64;
    let closest = eigenvalues
        .iter()
        .copied()
        .min_by(|x, y| x.re.abs().total_cmp(&y.re.abs()))
        .ok_or(RiccatiError::Eigenvalues {
            what: "the Hamiltonian",
        })?;
    let hamiltonian_margin = closest.re.abs() / h_norm;
    if !(hamiltonian_margin > axis_tolerance) {
        return Err(RiccatiError::ImaginaryAxisEigenvalue {
            eigenvalue: closest,
            margin: hamiltonian_margin,
            tolerance: axis_tolerance,
        });
    }

    // Step 4: the sign function and the stable invariant subspace.
    let (w, sign_iterations) = sign_function(h)?;
    let x = symmetrised(stable_subspace_solution(&w, n)? * sigma);

    // Step 5: Newton–Kleinman polishing.
    let (x, relative_residual, polishing_steps) = polish(a, &g, &q, x);

    // Step 6: the checks on the answer.
    if !(relative_residual <= RESIDUAL_TOLERANCE) {
        return Err(RiccatiError::ResidualTooLarge { relative_residual });
    }
    let (x_min, x_max) = eigenvalue_range(&x);
    if x_min < -PSD_TOLERANCE * x_min.abs().max(x_max.abs()) {
        return Err(RiccatiError::XNotPositiveSemidefinite {
            min_eigenvalue: x_min,
            max_eigenvalue: x_max,
        });
    }
    let gain = &r_inv_bt * &x;
    let closed_loop_poles = stable_closed_loop(a, b, &gain)?;
    Ok(Care {
        x,
        gain,
        relative_residual,
        closed_loop_poles,
        hamiltonian_margin,
        sign_iterations,
        polishing_steps,
    })
}

/// `R` positive definite and `Q` positive semidefinite (to rounding); `R⁻¹Bᵀ` (m×n).
fn check_weights(
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    b: &DMatrix<f64>,
    n: usize,
    m: usize,
) -> Result<DMatrix<f64>, RiccatiError> {
    let (r_min, r_max) = eigenvalue_range(r);
    if !(r_min > m as f64 * f64::EPSILON * r_max) {
        return Err(RiccatiError::RNotPositiveDefinite {
            min_eigenvalue: r_min,
            max_eigenvalue: r_max,
        });
    }
    let (q_min, q_max) = eigenvalue_range(q);
    if q_min < -100.0 * n as f64 * f64::EPSILON * q_min.abs().max(q_max.abs()) {
        return Err(RiccatiError::QNotPositiveSemidefinite {
            min_eigenvalue: q_min,
            max_eigenvalue: q_max,
        });
    }
    let cholesky = r
        .clone()
        .cholesky()
        .ok_or(RiccatiError::RNotPositiveDefinite {
            min_eigenvalue: r_min,
            max_eigenvalue: r_max,
        })?;
    Ok(cholesky.solve(&b.transpose()))
}

/// Newton–Kleinman steps from `x` while each halves the relative residual (one more that
/// only lowers it is kept, then no more): the solution, its relative residual and the steps.
fn polish(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    mut x: DMatrix<f64>,
) -> (DMatrix<f64>, f64, usize) {
    let mut relative_residual = residual(a, g, q, &x).1;
    let mut polishing_steps = 0;
    for _ in 0..MAX_POLISHING_STEPS {
        let (res, _) = residual(a, g, q, &x);
        let closed = a - g * &x;
        let Some(delta) = solve_lyapunov_symmetric(&closed, &(-res)) else {
            break;
        };
        let candidate = symmetrised(&x + delta);
        let candidate_residual = residual(a, g, q, &candidate).1;
        if !(candidate_residual < relative_residual) {
            break;
        }
        let falling = candidate_residual < 0.5 * relative_residual;
        x = candidate;
        relative_residual = candidate_residual;
        polishing_steps += 1;
        if !falling || relative_residual == 0.0 {
            break;
        }
    }
    (x, relative_residual, polishing_steps)
}

/// The poles of `A − BK`, sorted by imaginary then real part, every one in the open left
/// half-plane.
fn stable_closed_loop(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    gain: &DMatrix<f64>,
) -> Result<Vec<Complex<f64>>, RiccatiError> {
    let mut poles: Vec<Complex<f64>> = eigenvalues_of(a - b * gain, "the closed loop A − BK")?;
    poles.sort_by(|x, y| x.im.total_cmp(&y.im).then(x.re.total_cmp(&y.re)));
    if let Some(&pole) = poles.iter().find(|p| !(p.re < 0.0)) {
        return Err(RiccatiError::UnstableClosedLoop { pole });
    }
    Ok(poles)
}

/// `n` and `m` from the shapes, or the first matrix whose shape is wrong.
fn check_dimensions(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<(usize, usize), RiccatiError> {
    let wrong = |matrix: &'static str, expected: String, m: &DMatrix<f64>| {
        Err(RiccatiError::Dimensions {
            matrix,
            expected,
            rows: m.nrows(),
            cols: m.ncols(),
        })
    };
    let n = a.nrows();
    if n == 0 || a.ncols() != n {
        return wrong("A", "n×n with n ≥ 1".into(), a);
    }
    if n > MAX_STATES {
        return Err(RiccatiError::TooManyStates { n, max: MAX_STATES });
    }
    let m = b.ncols();
    if b.nrows() != n || m == 0 {
        return wrong("B", format!("{n}×m with m ≥ 1 (A is {n}×{n})"), b);
    }
    if q.shape() != (n, n) {
        return wrong("Q", format!("{n}×{n} (A is {n}×{n})"), q);
    }
    if r.shape() != (m, m) {
        return wrong("R", format!("{m}×{m} (B is {n}×{m})"), r);
    }
    Ok((n, m))
}

fn check_finite(matrix: &'static str, m: &DMatrix<f64>) -> Result<(), RiccatiError> {
    for col in 0..m.ncols() {
        for row in 0..m.nrows() {
            let value = m[(row, col)];
            if !value.is_finite() {
                return Err(RiccatiError::NonFinite {
                    matrix,
                    row,
                    col,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// The PBH test on every eigenvalue λ of A not clearly in the left half plane
/// (`Re λ ≥ −tol ‖[A, B]‖_F`): `[A − λI, B]` must have full row rank, its smallest singular value
/// above `tol ‖[A, B]‖_F`, tol = [`STABILISABILITY_TOLERANCE`].
fn check_stabilisable(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<(), RiccatiError> {
    let (n, m) = b.shape();
    let scale = (a.norm_squared() + b.norm_squared()).sqrt();
    for eigenvalue in eigenvalues(a, "A")? {
        if eigenvalue.re < -STABILISABILITY_TOLERANCE * scale {
            continue;
        }
        let pbh = DMatrix::<Complex<f64>>::from_fn(n, n + m, |i, j| {
            if j < n {
                let diagonal = if i == j {
                    eigenvalue
                } else {
                    Complex::new(0.0, 0.0)
                };
                Complex::new(a[(i, j)], 0.0) - diagonal
            } else {
                Complex::new(b[(i, j - n)], 0.0)
            }
        });
        let distance = pbh.singular_values().min() / scale;
        if !(distance > STABILISABILITY_TOLERANCE) {
            return Err(RiccatiError::NotStabilisable {
                eigenvalue,
                distance,
                tolerance: STABILISABILITY_TOLERANCE,
            });
        }
    }
    Ok(())
}

/// `(M + Mᵀ)/2` after checking that `‖M − Mᵀ‖_F ≤ 1e-12 ‖M‖_F`.
fn symmetric_part(matrix: &'static str, m: &DMatrix<f64>) -> Result<DMatrix<f64>, RiccatiError> {
    let asymmetry = (m - m.transpose()).norm();
    let norm = m.norm();
    if asymmetry > SYMMETRY_TOLERANCE * norm {
        return Err(RiccatiError::NotSymmetric {
            matrix,
            relative_asymmetry: asymmetry / norm,
        });
    }
    Ok(symmetrised(m.clone()))
}

fn symmetrised(mut m: DMatrix<f64>) -> DMatrix<f64> {
    let n = m.nrows();
    for j in 0..n {
        for i in 0..j {
            let mean = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = mean;
            m[(j, i)] = mean;
        }
    }
    m
}

/// Smallest and largest eigenvalue of a symmetric matrix.
fn eigenvalue_range(m: &DMatrix<f64>) -> (f64, f64) {
    let eigenvalues = m.symmetric_eigenvalues();
    (eigenvalues.min(), eigenvalues.max())
}

/// `[[A, −G], [−Q, −Aᵀ]]`.
fn hamiltonian(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut h = DMatrix::zeros(2 * n, 2 * n);
    h.view_mut((0, 0), (n, n)).copy_from(a);
    h.view_mut((0, n), (n, n)).copy_from(&(-g));
    h.view_mut((n, 0), (n, n)).copy_from(&(-q));
    h.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    h
}

/// The eigenvalues of a general real matrix: balanced (Parlett–Reinsch, a diagonal similarity),
/// then the real Schur form.
fn eigenvalues_of(m: DMatrix<f64>, what: &'static str) -> Result<Vec<Complex<f64>>, RiccatiError> {
    Ok(eigenvalues_and_balanced_norm(m, what)?.0)
}

/// [`eigenvalues_of`], and the Frobenius norm of the balanced matrix (the scale of the
/// eigenvalues' rounding errors).
fn eigenvalues_and_balanced_norm(
    mut m: DMatrix<f64>,
    what: &'static str,
) -> Result<(Vec<Complex<f64>>, f64), RiccatiError> {
    balance_parlett_reinsch(&mut m);
    let norm = m.norm();
    let schur = Schur::try_new(m, f64::EPSILON, MAX_SCHUR_ITERATIONS)
        .ok_or(RiccatiError::Eigenvalues { what })?;
    Ok((schur.complex_eigenvalues().iter().copied().collect(), norm))
}

fn eigenvalues(m: &DMatrix<f64>, what: &'static str) -> Result<Vec<Complex<f64>>, RiccatiError> {
    eigenvalues_of(m.clone(), what)
}

/// sign(Z) by Newton's iteration with determinant scaling (step 4 of the module doc), and the
/// number of iterations.
fn sign_function(mut z: DMatrix<f64>) -> Result<(DMatrix<f64>, usize), RiccatiError> {
    let dim = z.nrows();
    let mut scaling = true;
    let mut previous_change = f64::INFINITY;
    for iteration in 1..=MAX_SIGN_ITERATIONS {
        let lu = z.clone().lu();
        let u = lu.u();
        let mut log_det = 0.0;
        for i in 0..dim {
            let pivot = u[(i, i)].abs();
            if !(pivot > 0.0) || !pivot.is_finite() {
                return Err(RiccatiError::Singular {
                    what: "an iterate of the sign function",
                });
            }
            log_det += pivot.ln();
        }
        let inverse = lu.try_inverse().ok_or(RiccatiError::Singular {
            what: "an iterate of the sign function",
        })?;
        let c = if scaling {
            (-log_det / dim as f64).exp()
        } else {
            1.0
        };
        let next = (&z * (0.5 * c)) + inverse * (0.5 / c);
        let change = (&next - &z).norm() / next.norm();
        z = next;
        if !change.is_finite() {
            return Err(RiccatiError::NoConvergence {
                iterations: iteration,
                change,
            });
        }
        if change <= SIGN_TOLERANCE {
            return Ok((z, iteration));
        }
        // Quadratic convergence had begun and the change stopped halving: rounding level.
        if previous_change < 1e-6 && change > 0.5 * previous_change {
            return Ok((z, iteration));
        }
        if change < 1e-2 {
            scaling = false;
        }
        previous_change = change;
    }
    Err(RiccatiError::NoConvergence {
        iterations: MAX_SIGN_ITERATIONS,
        change: previous_change,
    })
}

/// X̃ from `W = sign(H)`: the least-squares solution of `[W₁₂; W₂₂ + I] X̃ = −[W₁₁ + I; W₂₁]`
/// by a thin QR factorisation.
fn stable_subspace_solution(w: &DMatrix<f64>, n: usize) -> Result<DMatrix<f64>, RiccatiError> {
    let identity = DMatrix::<f64>::identity(n, n);
    let mut lhs = DMatrix::zeros(2 * n, n);
    lhs.view_mut((0, 0), (n, n))
        .copy_from(&w.view((0, n), (n, n)));
    lhs.view_mut((n, 0), (n, n))
        .copy_from(&(w.view((n, n), (n, n)) + &identity));
    let mut rhs = DMatrix::zeros(2 * n, n);
    rhs.view_mut((0, 0), (n, n))
        .copy_from(&(-(w.view((0, 0), (n, n)) + &identity)));
    rhs.view_mut((n, 0), (n, n))
        .copy_from(&(-w.view((n, 0), (n, n))));
    let qr = lhs.qr();
    let qt_rhs = qr.q().tr_mul(&rhs);
    qr.r()
        .solve_upper_triangular(&qt_rhs)
        .ok_or(RiccatiError::Singular {
            what: "the stable invariant subspace's basis",
        })
}

/// The residual `AᵀX + XA − XGX + Q` (symmetrised) of a symmetric X and its relative size
/// `‖Res‖_F / (‖Q‖_F + 2‖AᵀX‖_F + ‖XGX‖_F)`.
fn residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> (DMatrix<f64>, f64) {
    let atx = a.tr_mul(x);
    let xgx = symmetrised(x * g * x);
    let res = symmetrised(&atx + atx.transpose() - &xgx + q);
    let scale = q.norm() + 2.0 * atx.norm() + xgx.norm();
    let norm = res.norm();
    let relative = if scale > 0.0 { norm / scale } else { norm };
    (res, relative)
}

/// The symmetric solution Δ of `AᵀΔ + ΔA = C` (C symmetric), as a dense linear system in the
/// `n(n+1)/2` entries on and above the diagonal; `None` when it is singular (A has eigenvalues
/// `λᵢ + λⱼ = 0`).
fn solve_lyapunov_symmetric(a: &DMatrix<f64>, c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    // Position of Δ[i][j], i ≤ j, row by row of the upper triangle.
    let index = |i: usize, j: usize| {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        i * (2 * n - i + 1) / 2 + (j - i)
    };
    let size = n * (n + 1) / 2;
    let mut system = DMatrix::<f64>::zeros(size, size);
    let mut rhs = DVector::<f64>::zeros(size);
    for i in 0..n {
        for j in i..n {
            let equation = index(i, j);
            rhs[equation] = c[(i, j)];
            // (AᵀΔ + ΔA)[i][j] = Σₖ A[k][i] Δ[k][j] + Σₖ Δ[i][k] A[k][j]
            for k in 0..n {
                system[(equation, index(k, j))] += a[(k, i)];
                system[(equation, index(i, k))] += a[(k, j)];
            }
        }
    }
    let solution = system.lu().solve(&rhs)?;
    let mut delta = DMatrix::zeros(n, n);
    for i in 0..n {
        for j in i..n {
            let value = solution[index(i, j)];
            delta[(i, j)] = value;
            delta[(j, i)] = value;
        }
    }
    Some(delta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_lyapunov_solve_matches_the_equation() {
        let a = DMatrix::from_row_slice(3, 3, &[-1.0, 2.0, 0.0, 0.5, -3.0, 1.0, 0.0, -1.0, -2.0]);
        let c = DMatrix::from_row_slice(3, 3, &[1.0, 0.2, 0.3, 0.2, 2.0, -0.4, 0.3, -0.4, 3.0]);
        let delta = solve_lyapunov_symmetric(&a, &c).expect("nonsingular");
        let check = a.transpose() * &delta + &delta * &a - &c;
        assert!(check.norm() < 1e-13, "{check}");
    }

    #[test]
    fn scalar_equation_has_its_closed_form() {
        // 2aX − X²b²/r + q = 0 → X = r(a + √(a² + b²q/r))/b².
        let (a, b, q, r) = (0.5, 2.0, 3.0, 0.7);
        let care = solve_care(
            &DMatrix::from_element(1, 1, a),
            &DMatrix::from_element(1, 1, b),
            &DMatrix::from_element(1, 1, q),
            &DMatrix::from_element(1, 1, r),
        )
        .expect("solvable");
        let exact = r * (a + (a * a + b * b * q / r).sqrt()) / (b * b);
        assert!((care.x[(0, 0)] - exact).abs() <= 1e-15 * exact);
        assert!((care.gain[(0, 0)] - b * exact / r).abs() <= 1e-14 * exact);
    }
}
