//! The LQR design on the twin (eqs 16–22): the calibrated M, C, K → A, B in the chosen state
//! unit; Q = q·diag(0, I); the Riccati equation solved with its checks; the gain.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use numerics::control::solve_care;
use numerics::lqr::StateSpace;
use serde::Serialize;
use structure::{Excitation, Structure};

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

/// The twin's linear structure: its physics component's m1..mN, c1..cN, k1..kN (the shear FMU's
/// defaults where the twin sets none), shaken at floor 1.
pub fn structure_of(twin: &Twin) -> Result<Structure, ControlError> {
    let defaults = fmu_shear::ShearParameters::default();
    let physics = twin.component(PHYSICS).ok_or_else(|| {
        ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component to control",
            twin.describe()
        ))
    })?;
    let mut s = Structure {
        mass: defaults.mass.to_vec(),
        damping: defaults.damping.to_vec(),
        stiffness: defaults.stiffness.to_vec(),
        excitation: Excitation::Force { floor: 1 },
    };
    for name in s.parameter_names() {
        match physics.parameters.get(&name) {
            None => {}
            Some(ParameterValue::Real(x)) if x.is_finite() => {
                s.set(&name, *x);
            }
            Some(other) => {
                return Err(ControlError::Twin(format!(
                    "{}: parameter '{name}' is {other:?}, not a finite real",
                    twin.describe()
                )))
            }
        }
    }
    s.validate()
        .map_err(|e| ControlError::Twin(format!("{}: {e}", twin.describe())))?;
    Ok(s)
}

/// m1..kN by name, for the report.
pub fn parameter_map(s: &Structure) -> BTreeMap<String, f64> {
    s.parameter_names()
        .into_iter()
        .zip(s.parameters())
        .collect()
}

/// The LQR's plant: `structure` with the actuator at `actuator_floor`, the state in units of `state_scale` metres.
pub fn plant_of(
    structure: &Structure,
    actuator_floor: usize,
    state_scale: f64,
) -> Result<StateSpace, ControlError> {
    fmu_lqr::model::plant(structure, actuator_floor, state_scale).map_err(ControlError::Twin)
}

/// One LQR design.
#[derive(Clone, Debug, Serialize)]
pub struct Design {
    pub q: f64,
    #[serde(rename = "Q")]
    pub q_matrix: Vec<Vec<f64>>,
    /// N per state unit: `f_c = gain · w`, one per state.
    pub gain: Vec<f64>,
    pub riccati_residual: f64,
    /// `[re, im]` of the eigenvalues of A − B·gain, 1/s.
    pub closed_loop_poles: Vec<[f64; 2]>,
    /// The distance of the Hamiltonian's spectrum from the imaginary axis, relative.
    pub hamiltonian_margin: f64,
}

pub fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter()
        .map(|row| row.iter().copied().collect())
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
    let (states, floors) = (plant.states(), plant.floors());
    let a = &plant.a;
    let b = DMatrix::from_column_slice(states, 1, plant.b.as_slice());
    let q_matrix = DMatrix::from_fn(
        states,
        states,
        |i, j| {
            if i == j && i >= floors {
                q
            } else {
                0.0
            }
        },
    );
    let r_matrix = DMatrix::from_element(1, 1, r);
    let care = solve_care(a, &b, &q_matrix, &r_matrix).map_err(|e| ControlError::Design {
        q,
        message: e.to_string(),
    })?;
    let gain = care.gain.row(0).iter().copied().collect();
    Ok(Design {
        q,
        q_matrix: rows(&q_matrix),
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
