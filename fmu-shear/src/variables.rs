//! The shear FMU's variable table, per structure. Value-reference constants carry the XML names.

use std::sync::{Mutex, OnceLock};

use fmi2::{DefaultExperiment, ModelInfo, Unit, Variable};
use structure::{Excitation, MAX_STOREYS};

use crate::effects::Effects;
use crate::model::ShearParameters;

pub const FORCE: u32 = 1;
pub const CONTROL_FORCE: u32 = 2;
/// The excitation input under ground motion (instead of `force`).
pub const GROUND_ACC: u32 = 3;
pub const SUBSTEPS: u32 = 40;
pub const INTEGRATOR: u32 = 41;
pub const SENSITIVITIES: u32 = 42;
/// Per-floor and per-storey quantities: `acc{i}` is `ACC + i − 1`, and likewise for the others,
/// each a block of [`BLOCK`] references (wide enough for [`MAX_STOREYS`]). Below 1000: the
/// effect library (`effects`).
pub const BLOCK: u32 = 100;
pub const ACC: u32 = 1000;
pub const DISP: u32 = ACC + BLOCK;
pub const VEL: u32 = DISP + BLOCK;
pub const DRIFT: u32 = VEL + BLOCK;
pub const MASS: u32 = DRIFT + BLOCK;
pub const DAMPING: u32 = MASS + BLOCK;
pub const STIFFNESS: u32 = DAMPING + BLOCK;
/// The state a run starts from: `disp{i}_start`, `vel{i}_start` (0: at rest).
pub const DISP_START: u32 = STIFFNESS + BLOCK;
pub const VEL_START: u32 = DISP_START + BLOCK;
/// `d_acc{f}_d_{p}` is `SENSITIVITY + 3·MAX_STOREYS·(f − 1) + MAX_STOREYS·g + i − 1` for the
/// parameter `p` = `m_i` (g = 0), `c_i` (g = 1) or `k_i` (g = 2).
pub const SENSITIVITY: u32 = 10_000;
const PER_FLOOR: u32 = 3 * MAX_STOREYS as u32;

const _: () = assert!(MAX_STOREYS as u32 <= BLOCK);

/// The value reference of `d_acc{floor}_d_{parameter}`, both 0-based (the parameter in
/// `m1..mN, c1..cN, k1..kN` order of a structure of `storeys`).
pub fn sensitivity_vr(floor: usize, parameter: usize, storeys: usize) -> u32 {
    let (group, i) = (parameter / storeys, parameter % storeys);
    SENSITIVITY + PER_FLOOR * floor as u32 + MAX_STOREYS as u32 * group as u32 + i as u32
}

/// The inverse of [`sensitivity_vr`]: (floor, parameter), 0-based, when `vr` is one.
pub fn sensitivity_index(vr: u32, storeys: usize) -> Option<(usize, usize)> {
    let offset = vr.checked_sub(SENSITIVITY)?;
    let floor = (offset / PER_FLOOR) as usize;
    let within = offset % PER_FLOOR;
    let (group, i) = (
        (within / MAX_STOREYS as u32) as usize,
        (within % MAX_STOREYS as u32) as usize,
    );
    (floor < storeys && i < storeys).then_some((floor, group * storeys + i))
}

pub const MODEL_IDENTIFIER: &str = "fmu_shear";

fn units() -> Vec<Unit> {
    vec![
        Unit {
            name: "s",
            kg: 0,
            m: 0,
            s: 1,
        },
        Unit {
            name: "kg",
            kg: 1,
            m: 0,
            s: 0,
        },
        Unit {
            name: "m",
            kg: 0,
            m: 1,
            s: 0,
        },
        Unit {
            name: "m/s",
            kg: 0,
            m: 1,
            s: -1,
        },
        Unit {
            name: "m/s2",
            kg: 0,
            m: 1,
            s: -2,
        },
        Unit {
            name: "N",
            kg: 1,
            m: 1,
            s: -2,
        },
        Unit {
            name: "N.s/m",
            kg: 1,
            m: 0,
            s: -1,
        },
        Unit {
            name: "N/m",
            kg: 1,
            m: 0,
            s: -2,
        },
        Unit {
            name: "m/(s2.kg)",
            kg: -1,
            m: 1,
            s: -2,
        },
        Unit {
            name: "m/(kg.s)",
            kg: -1,
            m: 1,
            s: -1,
        },
        Unit {
            name: "m/kg",
            kg: -1,
            m: 1,
            s: 0,
        },
        Unit {
            name: "N/m3",
            kg: 1,
            m: -2,
            s: -2,
        },
    ]
}

fn variables(p: &ShearParameters) -> Vec<Variable> {
    let n = p.storeys();
    let excitation = excitation_input(p);
    let input_vr = excitation.vr;
    let mut v = vec![excitation, control_force_input(p)];
    v.extend(responses(p, input_vr));
    v.extend(structure_parameters(p));
    v.extend(start_state(n));
    v.extend(integration_parameters(p));
    v.extend(sensitivities(n, input_vr));
    v.extend(Effects::variables(n));
    v
}

/// The excitation input: `force` on its floor, or `ground_acc` at the base.
fn excitation_input(p: &ShearParameters) -> Variable {
    match p.excitation {
        Excitation::Force { floor } => Variable::real_input("force", FORCE, "N", 0.0)
            .describe(&format!("excitation force on floor {floor} (the shaker)")),
        Excitation::Base => Variable::real_input("ground_acc", GROUND_ACC, "m/s2", 0.0).describe(
            "ground acceleration at the base (the model is in coordinates relative to the ground)",
        ),
    }
}

fn control_force_input(p: &ShearParameters) -> Variable {
    Variable::real_input("control_force", CONTROL_FORCE, "N", 0.0).describe(&format!(
        "control force on floor {}, acting against the excitation",
        p.control_floor
    ))
}

/// `acc{i}`, `disp{i}`, `vel{i}` per floor and `drift{i}` per storey, in that order.
fn responses(p: &ShearParameters, input_vr: u32) -> Vec<Variable> {
    let n = p.storeys() as u32;
    let mut v = Vec::new();
    let reads = match p.excitation {
        Excitation::Force { .. } => "absolute acceleration",
        Excitation::Base => "absolute acceleration (relative plus ground_acc)",
    };
    for i in 0..n {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("acc{floor}"), ACC + i, "m/s2")
                .describe(&format!("{reads} of floor {floor}"))
                .depends_on(&[input_vr, CONTROL_FORCE]),
        );
    }
    for i in 0..n {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("disp{floor}"), DISP + i, "m").describe(&format!(
                "displacement of floor {floor} relative to the ground"
            )),
        );
    }
    for i in 0..n {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("vel{floor}"), VEL + i, "m/s")
                .describe(&format!("velocity of floor {floor} relative to the ground")),
        );
    }
    for i in 0..n {
        let storey = i + 1;
        let below = if i == 0 {
            "the ground".to_owned()
        } else {
            format!("floor {i}")
        };
        v.push(
            Variable::real_output(&format!("drift{storey}"), DRIFT + i, "m").describe(&format!(
                "inter-storey drift of storey {storey}: floor {storey} minus {below}"
            )),
        );
    }
    v
}

/// `m{i}`, `c{i}`, `k{i}` at the structure's values.
fn structure_parameters(p: &ShearParameters) -> Vec<Variable> {
    let n = p.storeys();
    let mut v = Vec::new();
    for i in 0..n {
        let k = i + 1;
        v.push(
            Variable::real_parameter(&format!("m{k}"), MASS + i as u32, "kg", p.mass[i])
                .min(0.0)
                .describe(&format!("mass of floor {k}")),
        );
    }
    for i in 0..n {
        let k = i + 1;
        v.push(
            Variable::real_parameter(&format!("c{k}"), DAMPING + i as u32, "N.s/m", p.damping[i])
                .min(0.0)
                .describe(&format!("viscous damping of storey {k}")),
        );
    }
    for i in 0..n {
        let k = i + 1;
        v.push(
            Variable::real_parameter(
                &format!("k{k}"),
                STIFFNESS + i as u32,
                "N/m",
                p.stiffness[i],
            )
            .min(0.0)
            .describe(&format!("lateral stiffness of storey {k}")),
        );
    }
    v
}

/// `disp{i}_start`, `vel{i}_start`: the state a run starts from.
fn start_state(n: usize) -> Vec<Variable> {
    let n = n as u32;
    let mut v = Vec::new();
    for (first, name, unit, what) in [
        (DISP_START, "disp", "m", "displacement"),
        (VEL_START, "vel", "m/s", "velocity"),
    ] {
        for i in 0..n {
            let floor = i + 1;
            v.push(
                Variable::real_parameter(&format!("{name}{floor}_start"), first + i, unit, 0.0)
                    .describe(&format!(
                        "{what} of floor {floor} relative to the ground at the start time (a run that starts from a known state: 0, at rest)"
                    )),
            );
        }
    }
    v
}

/// `substeps` and `integrator`.
fn integration_parameters(p: &ShearParameters) -> Vec<Variable> {
    vec![
        Variable::integer_parameter("substeps", SUBSTEPS, p.substeps as i32)
            .min(1.0)
            .max(10000.0)
            .describe("RK4 sub-steps per communication step: the linear model's step map; with effects, when integrator = 1 (or 2 and not contacts alone)"),
        Variable::integer_parameter("integrator", INTEGRATOR, 0)
            .min(0.0)
            .max(2.0)
            .describe("with effects: 0 exact step maps per contact region (contacts alone) or error-controlled Dormand-Prince 5(4) (other effects), split at contact kinks; 1 RK4 with substeps fixed sub-steps, split at contact kinks; 2 exact for contacts alone, otherwise as 1"),
    ]
}

/// The `sensitivities` switch and the outputs `d_acc{f}_d_{p}` it turns on.
fn sensitivities(n: usize, input_vr: u32) -> Vec<Variable> {
    let names = structure::building::parameter_names(n);
    let mut v = vec![
        Variable::boolean_parameter("sensitivities", SENSITIVITIES, false).describe(&format!(
            "carry the forward sensitivities of the accelerations to {}..{}, {}..{}, {}..{} (the linear model: with an effect on they are NaN)",
            names[0], names[n - 1], names[n], names[2 * n - 1],
            names[2 * n], names[3 * n - 1]
        )),
    ];
    for f in 0..n {
        for (j, name) in names.iter().enumerate() {
            let unit = ["m/(s2.kg)", "m/(kg.s)", "m/kg"][j / n];
            let floor = f + 1;
            v.push(
                Variable::real_output(
                    &format!("d_acc{floor}_d_{name}"),
                    sensitivity_vr(f, j, n),
                    unit,
                )
                .describe(&format!(
                    "derivative of acc{floor} with respect to {name} along the run (NaN unless sensitivities is on and no effect is)"
                ))
                .depends_on(&[input_vr, CONTROL_FORCE]),
            );
        }
    }
    v
}

/// The model's name, and its description, for a structure.
fn identity(p: &ShearParameters) -> (String, String) {
    let n = p.storeys();
    let effects = " and optional gap contact, cubic stiffness, friction and up to six discovered terms coefficient·f(x, v)";
    (
        format!("ShearFrame{n}"),
        format!(
            "{n}-storey shear frame ({n}-DOF, eq. 1 of the reference paper) under {}, the exact step map of RK4 with sub-steps{effects}",
            p.excitation.describe()
        ),
    )
}

fn build(p: &ShearParameters) -> ModelInfo {
    let (name, description) = identity(p);
    ModelInfo::new(
        &name,
        MODEL_IDENTIFIER,
        &description,
        env!("CARGO_PKG_VERSION"),
        variables(p),
        units(),
        true,
        Some(DefaultExperiment {
            start_time: 0.0,
            stop_time: 20.0,
            step_size: 1.0 / 51.2,
        }),
    )
    // Built from a validated structure; the unit tests build it for every storey count.
    .expect("the shear FMU's variable table is consistent")
}

/// The table of the paper's rig (3 storeys, a force at floor 1), built once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| build(&ShearParameters::default()))
}

/// The table of the structure `p` describes (its storeys, excitation, control floor and the
/// start values of its parameters), built once per structure and kept for the life of the
/// library: FMI 2.0 fixes the variables in modelDescription.xml, so each structure has its own
/// table and GUID, and one library serves them all.
pub fn table(p: &ShearParameters) -> &'static ModelInfo {
    static TABLES: OnceLock<Mutex<Vec<(ShearParameters, &'static ModelInfo)>>> = OnceLock::new();
    let tables = TABLES.get_or_init(Default::default);
    // A poisoned lock only means another thread panicked while pushing; the list is still whole.
    let mut tables = tables.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, info)) = tables.iter().find(|(q, _)| q == p) {
        return info;
    }
    let info: &'static ModelInfo = if *p == ShearParameters::default() {
        info()
    } else {
        Box::leak(Box::new(build(p)))
    };
    tables.push((p.clone(), info));
    info
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(storeys: usize, excitation: Excitation) -> ShearParameters {
        let mut s = structure::Structure::default();
        s.mass = (0..storeys).map(|i| 5.0 + 0.1 * i as f64).collect();
        s.damping = vec![0.5; storeys];
        s.stiffness = vec![4000.0; storeys];
        s.excitation = excitation;
        ShearParameters::from_structure(&s)
    }

    /// Every storey count up to MAX_STOREYS and both excitations: the table builds (distinct
    /// names and value references, checked by `ModelInfo::new`), has exactly the floors' and
    /// storeys' variables and N × 3N sensitivities, the excitation's input alone, and the effect
    /// library at every site.
    #[test]
    fn the_table_is_laid_out_for_every_storey_count() {
        let mut guids = std::collections::HashSet::new();
        for storeys in [1, 2, 3, 5, 10, 20, MAX_STOREYS] {
            for excitation in [Excitation::Force { floor: storeys }, Excitation::Base] {
                let p = params(storeys, excitation);
                let info = table(&p);
                assert!(
                    guids.insert(info.guid.clone()),
                    "{storeys} {excitation:?}: GUID shared"
                );
                assert!(std::ptr::eq(info, table(&p)), "built once");
                for i in 1..=storeys {
                    for name in ["acc", "disp", "vel", "drift", "m", "c", "k"] {
                        assert!(info.by_name(&format!("{name}{i}")).is_some(), "{name}{i}");
                    }
                    for name in ["disp", "vel"] {
                        let start = format!("{name}{i}_start");
                        assert!(info.by_name(&start).is_some(), "{start}");
                    }
                }
                for name in ["acc", "m", "k"] {
                    assert!(info.by_name(&format!("{name}{}", storeys + 1)).is_none());
                }
                let base = excitation == Excitation::Base;
                assert_eq!(info.by_name("ground_acc").is_some(), base);
                assert_eq!(info.by_name("force").is_some(), !base);
                let sensitivities = info
                    .variables
                    .iter()
                    .filter(|v| v.name.starts_with("d_acc"))
                    .count();
                assert_eq!(sensitivities, storeys * 3 * storeys);
                let last = format!("d_acc{storeys}_d_k{storeys}");
                assert_eq!(
                    info.by_name(&last).map(|v| v.vr),
                    Some(sensitivity_vr(storeys - 1, 3 * storeys - 1, storeys))
                );
                assert_eq!(info.by_name("contact23_enabled").is_some(), storeys >= 3);
                let top = storeys - 1;
                for kind in crate::effects::Kind::ALL {
                    let name = format!("{}_enabled", kind.prefix(top));
                    let vr = info.by_name(&name).map(|v| v.vr);
                    let base = [100, 200, 300][kind as usize];
                    assert_eq!(vr, Some(crate::effects::site_vr(base, top)), "{name}");
                }
                assert!(info
                    .by_name(&format!(
                        "{}_enabled",
                        crate::effects::Kind::Cubic.prefix(storeys)
                    ))
                    .is_none());
                assert_eq!(
                    info.by_name(&format!("m{storeys}"))
                        .map(|v| v.start.clone()),
                    Some(fmi2::Start::Real(p.mass[storeys - 1]))
                );
            }
        }
        assert!(info().by_name("contact23_enabled").is_some());
        assert!(std::ptr::eq(table(&ShearParameters::default()), info()));
    }

    #[test]
    fn sensitivity_references_round_trip() {
        for storeys in [1, 3, 7, MAX_STOREYS] {
            for floor in 0..storeys {
                for parameter in 0..3 * storeys {
                    let vr = sensitivity_vr(floor, parameter, storeys);
                    assert!(vr >= SENSITIVITY);
                    assert_eq!(sensitivity_index(vr, storeys), Some((floor, parameter)));
                }
            }
            assert_eq!(
                sensitivity_index(SENSITIVITY + PER_FLOOR * storeys as u32, storeys),
                None
            );
            if storeys < MAX_STOREYS {
                // Past the last storey of the m block.
                assert_eq!(
                    sensitivity_index(SENSITIVITY + storeys as u32, storeys),
                    None
                );
            }
        }
    }
}
