//! The LQR design on the twin (eqs 16–22): the calibrated M, C, K → A, B in the chosen state
//! unit; Q = q·diag(0, I); the Riccati equation solved with its checks; the gain.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use numerics::control::solve_care;
use numerics::lqr::{ShearMatrices, StateSpace, FLOORS, STATES};
use serde::Serialize;

use super::ControlError;
use crate::twin::{ParameterValue, Twin, PHYSICS};

/// The unit the state is designed in: the weights q and R mean something only with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum StateUnit {
    /// Metres and metres per second (the SI units the twin's parameters are in).
    M,
    /// Millimetres and millimetres per second.
    Mm,
}

impl StateUnit {
    /// Metres per state unit.
    pub fn scale(self) -> f64 {
        match self {
            StateUnit::M => 1.0,
            StateUnit::Mm => 1e-3,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            StateUnit::M => "m",
            StateUnit::Mm => "mm",
        }
    }
}

/// The twin's linear structure: its physics component's m1..3, c1..3, k1..3 (the shear FMU's
/// defaults where the twin sets none).
pub fn structure_of(twin: &Twin) -> Result<ShearMatrices, ControlError> {
    let defaults = fmu_shear::ShearParameters::default();
    let physics = twin.component(PHYSICS).ok_or_else(|| {
        ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component to control",
            twin.describe()
        ))
    })?;
    let value = |name: &str, default: f64| -> Result<f64, ControlError> {
        match physics.parameters.get(name) {
            None => Ok(default),
            Some(ParameterValue::Real(x)) if x.is_finite() => Ok(*x),
            Some(other) => Err(ControlError::Twin(format!(
                "{}: parameter '{name}' is {other:?}, not a finite real",
                twin.describe()
            ))),
        }
    };
    let mut s = ShearMatrices {
        mass: std::array::from_fn(|i| defaults.mass[i]),
        damping: std::array::from_fn(|i| defaults.damping[i]),
        stiffness: std::array::from_fn(|i| defaults.stiffness[i]),
    };
    for i in 0..FLOORS {
        s.mass[i] = value(&format!("m{}", i + 1), defaults.mass[i])?;
        s.damping[i] = value(&format!("c{}", i + 1), defaults.damping[i])?;
        s.stiffness[i] = value(&format!("k{}", i + 1), defaults.stiffness[i])?;
    }
    s.check()
        .map_err(|e| ControlError::Twin(format!("{}: {e}", twin.describe())))?;
    Ok(s)
}

/// m1..k3 by name, for the report.
pub fn parameter_map(s: &ShearMatrices) -> BTreeMap<String, f64> {
    let mut map = BTreeMap::new();
    for i in 0..FLOORS {
        map.insert(format!("m{}", i + 1), s.mass[i]);
        map.insert(format!("c{}", i + 1), s.damping[i]);
        map.insert(format!("k{}", i + 1), s.stiffness[i]);
    }
    map
}

/// One LQR design.
#[derive(Clone, Debug, Serialize)]
pub struct Design {
    pub q: f64,
    #[serde(rename = "Q")]
    pub q_matrix: Vec<Vec<f64>>,
    /// N per state unit: `f_c = gain · w`.
    pub gain: [f64; STATES],
    pub riccati_residual: f64,
    /// `[re, im]` of the eigenvalues of A − B·gain, 1/s.
    pub closed_loop_poles: Vec<[f64; 2]>,
    /// The distance of the Hamiltonian's spectrum from the imaginary axis, relative.
    pub hamiltonian_margin: f64,
}

pub fn rows<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f64, R, C>) -> Vec<Vec<f64>> {
    (0..R)
        .map(|i| (0..C).map(|j| m[(i, j)]).collect())
        .collect()
}

/// Solve the LQR for state weight `q` and control weight `r` on `plant`.
pub fn design(plant: &StateSpace, q: f64, r: f64) -> Result<Design, ControlError> {
    if !(q.is_finite() && q >= 0.0) {
        return Err(ControlError::Options(format!(
            "q must be a finite number ≥ 0, got {q}"
        )));
    }
    if !(r.is_finite() && r > 0.0) {
        return Err(ControlError::Options(format!(
            "R must be a finite number > 0, got {r}"
        )));
    }
    let a = DMatrix::from_fn(STATES, STATES, |i, j| plant.a[(i, j)]);
    let b = DMatrix::from_fn(STATES, 1, |i, _| plant.b[i]);
    let q_matrix = DMatrix::from_fn(
        STATES,
        STATES,
        |i, j| {
            if i == j && i >= FLOORS {
                q
            } else {
                0.0
            }
        },
    );
    let r_matrix = DMatrix::from_element(1, 1, r);
    let care = solve_care(&a, &b, &q_matrix, &r_matrix).map_err(|e| ControlError::Design {
        q,
        message: e.to_string(),
    })?;
    let mut gain = [0.0; STATES];
    for (j, g) in gain.iter_mut().enumerate() {
        *g = care.gain[(0, j)];
    }
    Ok(Design {
        q,
        q_matrix: (0..STATES)
            .map(|i| (0..STATES).map(|j| q_matrix[(i, j)]).collect())
            .collect(),
        gain,
        riccati_residual: care.relative_residual,
        closed_loop_poles: care
            .closed_loop_poles
            .iter()
            .map(|p| [p.re, p.im])
            .collect(),
        hamiltonian_margin: care.hamiltonian_margin,
    })
}
