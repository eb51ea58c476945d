//! The LQR design on the twin (eqs 16–22): the calibrated M, C, K → A, B in the chosen state
//! unit; Q = q·diag(0, I); the Riccati equation solved with its checks; the gain.

use std::collections::BTreeMap;

use fmu_shear::StructureResource;
use nalgebra::DMatrix;
use numerics::control::solve_care;
use numerics::lqr::StateSpace;
use serde::Serialize;
use structure::channel::Channel;
use structure::Structure;

use super::ControlError;
use crate::twin::{ParameterValue, Twin, PHYSICS};

/// The unit the state is designed in: the weights q and R mean something only with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StateUnit {
    /// Metres and metres per second (the SI units the twin's parameters are in).
    M,
    /// Millimetres and millimetres per second.
    Mm,
}

impl crate::choice::Choice for StateUnit {
    const CHOICES: &'static [(&'static str, &'static str, Self)] = &[
        ("m", "metres and metres per second", StateUnit::M),
        (
            "mm",
            "millimetres and millimetres per second",
            StateUnit::Mm,
        ),
    ];
}

crate::choice::display_by_name!(StateUnit);

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

/// What the twin's physics FMU says about the structure it models: its
/// `resources/structure.json` (the structure `twin init` wrote and the control force's floor),
/// the paper's rig when it has none.
// Until the twin reads its structure itself (Twin::structure), the control workflow reads the
// resource here, in this one function.
pub fn physics_resource(twin: &Twin) -> Result<StructureResource, ControlError> {
    let physics = twin.component(PHYSICS).ok_or_else(|| {
        ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component to control",
            twin.describe()
        ))
    })?;
    let path = &physics.fmu_path;
    let bad = |why: String| ControlError::Twin(format!("{}: {why}", path.display()));
    let file = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| bad(e.to_string()))?;
    let text = match archive.by_name(STRUCTURE_ENTRY) {
        Ok(mut entry) => {
            let mut text = String::new();
            std::io::Read::read_to_string(&mut entry, &mut text)
                .map_err(|e| bad(format!("{STRUCTURE_ENTRY}: {e}")))?;
            text
        }
        Err(zip::result::ZipError::FileNotFound) => {
            return Ok(StructureResource {
                structure: Structure::default(),
                control_floor: 1,
            })
        }
        Err(e) => return Err(bad(e.to_string())),
    };
    let resource: StructureResource =
        serde_json::from_str(&text).map_err(|e| bad(format!("{STRUCTURE_ENTRY}: {e}")))?;
    resource
        .parameters()
        .map_err(|e| bad(format!("{STRUCTURE_ENTRY}: {e}")))?;
    Ok(resource)
}

/// The FMU entry that names the structure.
const STRUCTURE_ENTRY: &str = "resources/structure.json";

/// The twin's linear structure: its physics FMU's structure (storeys, excitation, nominal
/// m/c/k; the paper's rig when the FMU names none) with the twin's m1..mN, c1..cN, k1..kN.
pub fn structure_of(twin: &Twin) -> Result<Structure, ControlError> {
    let mut s = physics_resource(twin)?.structure;
    let physics = twin.component(PHYSICS).ok_or_else(|| {
        ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component to control",
            twin.describe()
        ))
    })?;
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

/// `--actuator-floor K` checked against the structure: a floor it has.
pub fn check_actuator_floor(floor: usize, structure: &Structure) -> Result<(), ControlError> {
    let n = structure.storeys();
    if (1..=n).contains(&floor) {
        Ok(())
    } else {
        Err(ControlError::Options(format!(
            "--actuator-floor {floor}: the structure has floors 1 to {n}"
        )))
    }
}

/// The twin with its control force acting on `floor`: itself when its physics FMU's control
/// force is there already, else a copy whose physics is the built-in shear FMU written for the
/// same structure with the control force on `floor` (a temporary FMU that lives as long as the
/// copy). Refused, naming the option, when the twin sets a parameter that FMU does not have.
pub fn with_actuator_at(twin: &Twin, floor: usize) -> Result<Twin, ControlError> {
    let resource = physics_resource(twin)?;
    check_actuator_floor(floor, &resource.structure)?;
    if resource.control_floor == floor {
        return Ok(twin.duplicate());
    }
    let moved = StructureResource {
        structure: resource.structure,
        control_floor: floor,
    };
    let params = moved
        .parameters()
        .map_err(|e| ControlError::Options(format!("--actuator-floor {floor}: {e}")))?;
    let table = fmu_shear::variables::table(&params);
    let mut copy = twin.duplicate();
    let physics = copy.component_mut(PHYSICS).ok_or_else(|| {
        ControlError::Twin(format!(
            "{} has no '{PHYSICS}' component to control",
            twin.describe()
        ))
    })?;
    if let Some(name) = physics
        .parameters
        .keys()
        .find(|name| table.by_name(name).is_none())
    {
        return Err(ControlError::Options(format!(
            "--actuator-floor {floor}: {} sets '{name}', which the shear FMU with its control \
             force on floor {floor} does not have",
            twin.describe()
        )));
    }
    let bytes = crate::twin::structure::shear_fmu_bytes(&moved)?;
    let dir = tempfile::tempdir().map_err(|e| {
        ControlError::Twin(format!("a temporary directory for the physics FMU: {e}"))
    })?;
    let path = dir.path().join(crate::twin::SHEAR_FMU);
    std::fs::write(&path, bytes)
        .map_err(|e| ControlError::Twin(format!("{}: {e}", path.display())))?;
    physics.fmu_path = path;
    copy.keep_alive(std::sync::Arc::new(dir));
    Ok(copy)
}

/// m1..kN by name, for the report.
pub fn parameter_map(s: &Structure) -> BTreeMap<String, f64> {
    s.parameter_names()
        .into_iter()
        .zip(s.parameters())
        .collect()
}

/// The LQR's plant: `structure` with the actuator at `actuator_floor`, reading every floor's
/// acceleration, the state in units of `state_scale` metres.
pub fn plant_of(
    structure: &Structure,
    actuator_floor: usize,
    state_scale: f64,
) -> Result<StateSpace, ControlError> {
    fmu_lqr::model::plant(structure, actuator_floor, state_scale).map_err(ControlError::Twin)
}

/// The LQR's plant reading the channels `measured`.
pub fn plant_measuring(
    structure: &Structure,
    actuator_floor: usize,
    measured: &[Channel],
    state_scale: f64,
) -> Result<StateSpace, ControlError> {
    fmu_lqr::model::plant_measuring(structure, actuator_floor, measured, state_scale)
        .map_err(ControlError::Twin)
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
