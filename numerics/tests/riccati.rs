//! numerics::control::solve_care against scipy and python-control (SLICOT) on the cases of
//! tests/data/care_reference.json (written by scripts/riccati_reference.py: the 3-storey shear
//! model lightly and moderately damped, in metres and millimetres, q = 1 … 1e6, and three generic
//! systems), and the failures it must report instead of a gain.

// The checks are written `!(value <= limit)` on purpose: a NaN must fail them.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use numerics::control::{solve_care, Care, DMatrix, RiccatiError};
use serde::Deserialize;

#[derive(Deserialize)]
struct Reference {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    name: String,
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    q: Vec<Vec<f64>>,
    r: Vec<Vec<f64>>,
    scipy: Solution,
    control: Solution,
    agreement: Agreement,
}

#[derive(Deserialize)]
struct Solution {
    x: Vec<Vec<f64>>,
    gain: Vec<Vec<f64>>,
    relative_residual: f64,
}

#[derive(Deserialize)]
struct Agreement {
    x: f64,
    gain: f64,
}

fn matrix(rows: &[Vec<f64>]) -> DMatrix<f64> {
    let ncols = rows.first().map_or(0, Vec::len);
    DMatrix::from_fn(rows.len(), ncols, |i, j| rows[i][j])
}

fn relative(ours: &DMatrix<f64>, reference: &DMatrix<f64>) -> f64 {
    (ours - reference).norm() / reference.norm()
}

fn reference() -> Reference {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/care_reference.json"
    );
    let text = std::fs::read_to_string(path).expect("care_reference.json");
    serde_json::from_str(&text).expect("care_reference.json parses")
}

/// The agreement asked of us against each reference: 1e-8 relative against scipy (residuals
/// ~1e-14), and against SLICOT 1e-8 plus its recorded distance from scipy (its residuals reach
/// ~1e-8 on the q ≥ 1e5 cases, so it is itself only that close to the solution).
const AGREEMENT: f64 = 1e-8;

#[test]
fn agrees_with_scipy_and_python_control_on_every_reference_case() {
    let reference = reference();
    assert_eq!(reference.cases.len(), 31);
    let mut failures = Vec::new();
    println!(
        "{:<28} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}  sign/NK",
        "case", "residual", "scipy", "K scipy", "X scipy", "K ctrl", "X ctrl", "margin"
    );
    for case in &reference.cases {
        let [a, b, q, r] = [&case.a, &case.b, &case.q, &case.r].map(|m| matrix(m));
        let care = match solve_care(&a, &b, &q, &r) {
            Ok(care) => care,
            Err(error) => {
                failures.push(format!("{}: {error}", case.name));
                continue;
            }
        };
        let k_scipy = relative(&care.gain, &matrix(&case.scipy.gain));
        let x_scipy = relative(&care.x, &matrix(&case.scipy.x));
        let k_control = relative(&care.gain, &matrix(&case.control.gain));
        let x_control = relative(&care.x, &matrix(&case.control.x));
        println!(
            "{:<28} {:>9.1e} {:>9.1e} {:>9.1e} {:>9.1e} {:>9.1e} {:>9.1e} {:>9.1e}  {}/{}",
            case.name,
            care.relative_residual,
            case.scipy.relative_residual,
            k_scipy,
            x_scipy,
            k_control,
            x_control,
            care.hamiltonian_margin,
            care.sign_iterations,
            care.polishing_steps
        );
        let checks = [
            ("residual", care.relative_residual, 1e-10),
            ("K vs scipy", k_scipy, AGREEMENT),
            ("X vs scipy", x_scipy, AGREEMENT),
            ("K vs control", k_control, AGREEMENT + case.agreement.gain),
            ("X vs control", x_control, AGREEMENT + case.agreement.x),
        ];
        for (what, value, limit) in checks {
            if !(value <= limit) {
                failures.push(format!("{}: {what} {value:e} > {limit:e}", case.name));
            }
        }
        check_answer(&case.name, &care, &a, &b, &mut failures);
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The structural promises of an answer: X symmetric, gain = R⁻¹BᵀX's shape, poles stable and
/// sorted, poles the eigenvalues of A − BK (their sum is its trace).
fn check_answer(
    name: &str,
    care: &Care,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    failures: &mut Vec<String>,
) {
    let n = a.nrows();
    if care.x != care.x.transpose() {
        failures.push(format!("{name}: X not symmetric"));
    }
    if care.gain.shape() != (b.ncols(), n) || care.closed_loop_poles.len() != n {
        failures.push(format!("{name}: wrong shapes"));
    }
    if care.closed_loop_poles.iter().any(|p| !(p.re < 0.0)) {
        failures.push(format!("{name}: unstable pole"));
    }
    if care
        .closed_loop_poles
        .windows(2)
        .any(|w| w[0].im > w[1].im || (w[0].im == w[1].im && w[0].re > w[1].re))
    {
        failures.push(format!("{name}: poles not sorted"));
    }
    let trace = (a - b * &care.gain).trace();
    let sum: f64 = care.closed_loop_poles.iter().map(|p| p.re).sum();
    if (trace - sum).abs() > 1e-9 * trace.abs().max(1.0) {
        failures.push(format!("{name}: poles sum to {sum}, trace is {trace}"));
    }
}

fn m(rows: usize, cols: usize, values: &[f64]) -> DMatrix<f64> {
    DMatrix::from_row_slice(rows, cols, values)
}

/// A solvable 2-state problem (the double integrator) to break one matrix at a time.
fn double_integrator() -> [DMatrix<f64>; 4] {
    [
        m(2, 2, &[0.0, 1.0, 0.0, 0.0]),
        m(2, 1, &[0.0, 1.0]),
        DMatrix::identity(2, 2),
        m(1, 1, &[1.0]),
    ]
}

fn solve(problem: &[DMatrix<f64>; 4]) -> Result<Care, RiccatiError> {
    let [a, b, q, r] = problem;
    solve_care(a, b, q, r)
}

#[test]
fn uncontrollable_unstable_mode_has_no_stabilising_solution() {
    // The mode at +1 is not reached by B, whether Q sees it or not.
    for q in [DMatrix::identity(2, 2), m(2, 2, &[0.0, 0.0, 0.0, 1.0])] {
        let problem = [
            m(2, 2, &[1.0, 0.0, 0.0, -1.0]),
            m(2, 1, &[0.0, 1.0]),
            q,
            m(1, 1, &[1.0]),
        ];
        let error = solve(&problem).expect_err("no stabilising solution");
        assert!(
            matches!(
                error,
                RiccatiError::NotStabilisable { .. } | RiccatiError::ImaginaryAxisEigenvalue { .. }
            ),
            "{error}"
        );
        assert!(
            error.to_string().contains("no stabilising solution"),
            "{error}"
        );
    }
    // An uncontrollable undamped oscillator beside a controlled stable state.
    let a = m(3, 3, &[0.0, 1.0, 0.0, -4.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
    let problem = [
        a,
        m(3, 1, &[0.0, 0.0, 1.0]),
        DMatrix::identity(3, 3),
        m(1, 1, &[1.0]),
    ];
    let error = solve(&problem).expect_err("no stabilising solution");
    assert!(
        error.to_string().contains("no stabilising solution"),
        "{error}"
    );
}

#[test]
fn unobservable_undamped_oscillator_puts_an_eigenvalue_on_the_imaginary_axis() {
    // Controllable, but Q weights only the third (stable, decoupled) state: the oscillator's ±2i
    // are eigenvalues of the Hamiltonian.
    let a = m(3, 3, &[0.0, 1.0, 0.0, -4.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
    let b = m(3, 2, &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]);
    let q = m(3, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    let error = solve(&[a, b, q, DMatrix::identity(2, 2)]).expect_err("axis eigenvalue");
    let RiccatiError::ImaginaryAxisEigenvalue { eigenvalue, .. } = error else {
        panic!("expected an imaginary-axis eigenvalue, got {error}");
    };
    assert!((eigenvalue.im.abs() - 2.0).abs() < 1e-6, "{eigenvalue}");
    assert!(error
        .to_string()
        .contains("unobservable mode on the imaginary axis"));
}

#[test]
fn r_must_be_positive_definite() {
    for r in [0.0, -1.0] {
        let mut problem = double_integrator();
        problem[3] = m(1, 1, &[r]);
        let error = solve(&problem).expect_err("R not positive definite");
        assert!(
            matches!(error, RiccatiError::RNotPositiveDefinite { min_eigenvalue, .. } if min_eigenvalue == r),
            "{error}"
        );
    }
    let mut problem = double_integrator();
    problem[1] = m(2, 2, &[0.0, 1.0, 1.0, 0.0]);
    problem[3] = m(2, 2, &[1.0, 2.0, 2.0, 1.0]); // eigenvalues 3 and −1
    let error = solve(&problem).expect_err("indefinite R");
    assert!(
        error
            .to_string()
            .contains("R is not symmetric positive definite"),
        "{error}"
    );
}

#[test]
fn q_must_be_symmetric_positive_semidefinite() {
    let mut problem = double_integrator();
    problem[2] = DMatrix::identity(2, 2) * -1.0; // q < 0
    let error = solve(&problem).expect_err("Q negative");
    assert!(
        matches!(error, RiccatiError::QNotPositiveSemidefinite { .. }),
        "{error}"
    );
    problem[2] = m(2, 2, &[1.0, 0.5, 0.0, 1.0]);
    let error = solve(&problem).expect_err("Q not symmetric");
    assert!(
        matches!(error, RiccatiError::NotSymmetric { matrix: "Q", .. }),
        "{error}"
    );
}

#[test]
fn non_finite_entries_are_refused() {
    for (index, name) in [(0, "A"), (1, "B"), (2, "Q"), (3, "R")] {
        for bad in [f64::NAN, f64::INFINITY] {
            let mut problem = double_integrator();
            let last = problem[index].len() - 1;
            problem[index][last] = bad;
            let error = solve(&problem).expect_err("non-finite");
            assert!(
                matches!(error, RiccatiError::NonFinite { matrix, .. } if matrix == name),
                "{name}: {error}"
            );
        }
    }
}

#[test]
fn wrong_shapes_are_refused() {
    let cases: [(usize, DMatrix<f64>, &str); 5] = [
        (0, DMatrix::zeros(2, 3), "A"),
        (0, DMatrix::zeros(0, 0), "A"),
        (1, DMatrix::zeros(3, 1), "B"),
        (2, DMatrix::identity(3, 3), "Q"),
        (3, DMatrix::identity(2, 2), "R"),
    ];
    for (index, wrong, name) in cases {
        let mut problem = double_integrator();
        problem[index] = wrong;
        let error = solve(&problem).expect_err("wrong shape");
        assert!(
            matches!(error, RiccatiError::Dimensions { matrix, .. } if matrix == name),
            "{name}: {error}"
        );
    }
    let mut problem = double_integrator();
    problem[1] = DMatrix::zeros(2, 0);
    assert!(matches!(
        solve(&problem),
        Err(RiccatiError::Dimensions { matrix: "B", .. })
    ));
}

#[test]
fn axis_eigenvalues_in_rotated_coordinates_still_give_no_gain() {
    // The problems above seen through an orthogonal change of state coordinates, so that the
    // eigenvalues on the axis are no longer computed exactly: still an error, never a gain.
    let angle: f64 = 0.7;
    let (c, s) = (angle.cos(), angle.sin());
    let t = m(3, 3, &[c, -s, 0.0, s * c, c * c, -s, s * s, s * c, c]);
    let t = t.clone().qr().q(); // orthogonal
    let rotate = |a: &DMatrix<f64>| t.transpose() * a * &t;
    let oscillator = m(3, 3, &[0.0, 1.0, 0.0, -4.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
    let cases = [
        // unobservable undamped oscillator (controllable)
        (
            rotate(&oscillator),
            t.transpose() * m(3, 2, &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]),
            rotate(&m(3, 3, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])),
        ),
        // uncontrollable undamped oscillator (observable)
        (
            rotate(&oscillator),
            t.transpose() * m(3, 1, &[0.0, 0.0, 1.0]),
            DMatrix::identity(3, 3),
        ),
        // uncontrollable unstable mode
        (
            rotate(&m(3, 3, &[0.5, 1.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, -1.0])),
            t.transpose() * m(3, 1, &[0.0, 0.0, 1.0]),
            DMatrix::identity(3, 3),
        ),
    ];
    for (a, b, q) in cases {
        let q = (&q + q.transpose()) * 0.5;
        match solve_care(&a, &b, &q, &DMatrix::identity(b.ncols(), b.ncols())) {
            Ok(care) => panic!("a gain for a problem without a stabilising solution: {care:?}"),
            Err(error) => println!("{error}"),
        }
    }
}
