//! The GP corrector's variable table, per layout ([`crate::layout`]). Value-reference constants
//! carry the XML names.
//!
//! FMI 2.0 fixes the variables in modelDescription.xml, so each layout has its own table and
//! GUID, and one library serves them all ([`table`]). The paper's rig (acc1..3, force) keeps the
//! value references and names below ([`info`], `modelDescription/fmu_gp_corrector.xml`); another
//! layout has, for its j-th channel `<c>` (from 0, in the layout's order), the input
//! `physics_<c>` at [`LAYOUT_PHYSICS`] + j and `measured_<c>` at [`LAYOUT_MEASURED`] + j, and
//! the outputs `<c>` (corrected), the latent variance and the predictive sd
//! ([`crate::layout::band_name`]: `latent_var<i>`/`sd<i>` for `acc<i>`, `latent_var_<c>`/`sd_<c>`
//! otherwise) at [`LAYOUT_CORRECTED`], [`LAYOUT_LATENT_VAR`], [`LAYOUT_SD`] + j; the excitation
//! `force` (vr 4) or `ground_acc` (vr 9); the parameters as on the rig.

use std::sync::{Mutex, OnceLock};

use fmi2::{Causality, DefaultExperiment, ModelInfo, Start, Unit, VarType, Variability, Variable};
use structure::channel::{Channel, ExcitationKind, Quantity};

use crate::layout::{band_name, Layout};

use crate::model::{
    DEFAULT_LAGS, DEFAULT_REFIT_EVERY, INITIAL_LENGTH_SCALE, INITIAL_NOISE_VARIANCE,
    INITIAL_SIGNAL_VARIANCE,
};
use crate::training::{MAX_LAGS, MAX_TRAINING_POINTS};

/// physics_acc1..3 are PHYSICS_ACC..PHYSICS_ACC+2; likewise for the other per-floor variables.
pub const PHYSICS_ACC: u32 = 1;
pub const FORCE: u32 = 4;
pub const MEASURED_ACC: u32 = 5;
/// Boolean input.
pub const LEARN: u32 = 8;
pub const ACC: u32 = 10;
pub const LATENT_VAR: u32 = 13;
pub const SD: u32 = 16;
/// Integer output.
pub const TRAINING_POINTS: u32 = 20;
/// Integer parameters.
pub const LAGS: u32 = 30;
pub const TARGET: u32 = 31;
pub const REFIT_EVERY: u32 = 32;
/// String parameter.
pub const TRAINING_PATH: u32 = 33;
/// Real parameters: the hyperparameters of a floor whose GP has no training point yet.
pub const INITIAL_SIGNAL_VARIANCE_VR: u32 = 34;
pub const INITIAL_NOISE_VARIANCE_VR: u32 = 35;
pub const INITIAL_LENGTH_SCALE_VR: u32 = 36;
/// The most training points a floor's GP keeps while learning (the oldest go first).
pub const BUDGET: u32 = 37;

/// Another layout's excitation when it is ground motion (m/s²).
pub const GROUND_ACC: u32 = 9;
/// Another layout's per-channel variables: the j-th channel's at base + j.
pub const LAYOUT_PHYSICS: u32 = 1000;
pub const LAYOUT_MEASURED: u32 = 2000;
pub const LAYOUT_CORRECTED: u32 = 3000;
pub const LAYOUT_LATENT_VAR: u32 = 4000;
pub const LAYOUT_SD: u32 = 5000;

// Three channels a floor fit in a block.
const _: () = assert!(3 * structure::MAX_STOREYS as u32 <= 1000);

pub const MODEL_IDENTIFIER: &str = "fmu_gp_corrector";

/// A per-channel variable's role.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Physics,
    Measured,
    Corrected,
    LatentVar,
    Sd,
}

const ROLES: [Role; 5] = [
    Role::Physics,
    Role::Measured,
    Role::Corrected,
    Role::LatentVar,
    Role::Sd,
];

fn base(layout: &Layout, role: Role) -> u32 {
    let rig = layout.is_paper();
    match role {
        Role::Physics if rig => PHYSICS_ACC,
        Role::Measured if rig => MEASURED_ACC,
        Role::Corrected if rig => ACC,
        Role::LatentVar if rig => LATENT_VAR,
        Role::Sd if rig => SD,
        Role::Physics => LAYOUT_PHYSICS,
        Role::Measured => LAYOUT_MEASURED,
        Role::Corrected => LAYOUT_CORRECTED,
        Role::LatentVar => LAYOUT_LATENT_VAR,
        Role::Sd => LAYOUT_SD,
    }
}

/// The value reference of channel `j`'s variable of `role` in `layout`'s table.
pub fn vr_of(layout: &Layout, role: Role, j: usize) -> u32 {
    base(layout, role) + j as u32
}

/// Which channel's variable of which role `vr` is in `layout`'s table.
pub fn role_of(layout: &Layout, vr: u32) -> Option<(Role, usize)> {
    let m = layout.channels.len();
    ROLES.into_iter().find_map(|role| {
        vr.checked_sub(base(layout, role))
            .map(|j| j as usize)
            .filter(|&j| j < m)
            .map(|j| (role, j))
    })
}

/// The excitation's input in `layout`'s table: `force` or `ground_acc`.
pub fn excitation_vr(layout: &Layout) -> u32 {
    match layout.excitation {
        ExcitationKind::Force => FORCE,
        ExcitationKind::GroundAcc => GROUND_ACC,
    }
}

/// The value references the corrected outputs depend on directly: the current sample of the
/// lag vector.
pub const FEEDTHROUGH: [u32; 4] = [PHYSICS_ACC, PHYSICS_ACC + 1, PHYSICS_ACC + 2, FORCE];

fn units() -> Vec<Unit> {
    vec![
        Unit {
            name: "m/s2",
            kg: 0,
            m: 1,
            s: -2,
        },
        Unit {
            name: "m2/s4",
            kg: 0,
            m: 2,
            s: -4,
        },
        Unit {
            name: "N",
            kg: 1,
            m: 1,
            s: -2,
        },
    ]
}

/// The paper rig's variables: those of `modelDescription/fmu_gp_corrector.xml`.
fn variables() -> Vec<Variable> {
    let mut v = Vec::new();
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_input(&format!("physics_acc{floor}"), PHYSICS_ACC + i, "m/s2", 0.0)
                .describe(&format!(
                    "acceleration of floor {floor} predicted by the physics model"
                )),
        );
    }
    v.push(
        Variable::real_input("force", FORCE, "N", 0.0)
            .describe("excitation force on floor 1, as given to the physics model"),
    );
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_input(
                &format!("measured_acc{floor}"),
                MEASURED_ACC + i,
                "m/s2",
                0.0,
            )
            .describe(&format!(
                "measured acceleration of floor {floor}: the training target when learn is true"
            )),
        );
    }
    v.push(Variable::boolean_input("learn", LEARN, false).describe(
        "at each fmi2DoStep with learn true, the current sample joins every floor's training set",
    ));
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("acc{floor}"), ACC + i, "m/s2")
                .describe(&format!(
                    "corrected acceleration of floor {floor}: physics + GP mean (target 0) or GP mean (target 1)"
                ))
                .depends_on(&FEEDTHROUGH),
        );
    }
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("latent_var{floor}"), LATENT_VAR + i, "m2/s4")
                .describe(&format!(
                    "latent predictive variance V(f*) of floor {floor}'s GP (noise excluded)"
                ))
                .depends_on(&FEEDTHROUGH),
        );
    }
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("sd{floor}"), SD + i, "m/s2")
                .describe(&format!(
                    "predictive standard deviation sqrt(V(f*) + noise variance) of floor {floor}"
                ))
                .depends_on(&FEEDTHROUGH),
        );
    }
    v.extend(parameters(true));
    v
}

/// The parameters and the `training_points` output, the same in every layout (only the rig's
/// descriptions name its floors).
fn parameters(rig: bool) -> Vec<Variable> {
    let mut v = Vec::new();
    v.push(Variable {
        name: "training_points".to_owned(),
        vr: TRAINING_POINTS,
        var_type: VarType::Integer,
        causality: Causality::Output,
        variability: Variability::Discrete,
        start: Start::None,
        unit: None,
        min: None,
        max: None,
        description: if rig {
            "number of points in each floor's training set".to_owned()
        } else {
            "number of points in each channel's training set".to_owned()
        },
        depends_on: Vec::new(),
    });
    v.push(
        Variable::integer_parameter("lags", LAGS, DEFAULT_LAGS as i32)
            .min(0.0)
            .max(MAX_LAGS as f64)
            .describe(if rig {
                "q: the GP inputs are the current and q previous samples of physics_acc1..3 and force, 4 (q + 1) values"
            } else {
                "q: each channel's GP takes the current and q previous samples of its own physics prediction, of at most two measured neighbours' and of the excitation, at most 4 (q + 1) values"
            }),
    );
    v.push(
        Variable::integer_parameter("target", TARGET, 0)
            .min(0.0)
            .max(1.0)
            .describe("0: the GP models measured − physics (corrected = physics + mean); 1: the GP models the measured acceleration (zero mean, corrected = mean)"),
    );
    v.push(
        Variable::integer_parameter("budget", BUDGET, MAX_TRAINING_POINTS as i32)
            .min(1.0)
            .max(MAX_TRAINING_POINTS as f64)
            .tunable()
            .describe(if rig {
                "the most training points a floor's GP keeps while learning: beyond, the oldest goes"
            } else {
                "the most training points a channel's GP keeps while learning: beyond, the oldest goes"
            }),
    );
    v.push(
        Variable::integer_parameter("refit_every", REFIT_EVERY, DEFAULT_REFIT_EVERY as i32)
            .min(0.0)
            .tunable()
            .describe("refit the hyperparameters (warm-started type-II maximum likelihood) after this many learned points; 0: never"),
    );
    v.push(
        Variable::string_parameter("training_path", TRAINING_PATH, "").describe(
            "training file (JSON); relative paths are taken from the FMU's resources folder; empty: resources/training.json if present, else no training data",
        ),
    );
    v.push(
        Variable::real_parameter(
            "initial_signal_variance",
            INITIAL_SIGNAL_VARIANCE_VR,
            "m2/s4",
            INITIAL_SIGNAL_VARIANCE,
        )
        .min(0.0)
        .describe(if rig {
            "signal variance of a GP the training data give no hyperparameters for"
        } else {
            "signal variance of a GP the training data give no hyperparameters for (in the unit of its channel squared; the unit shown is an acceleration's)"
        }),
    );
    v.push(
        Variable::real_parameter(
            "initial_noise_variance",
            INITIAL_NOISE_VARIANCE_VR,
            "m2/s4",
            INITIAL_NOISE_VARIANCE,
        )
        .min(0.0)
        .describe("noise variance of a GP the training data give no hyperparameters for"),
    );
    let mut length_scale = Variable::real_parameter(
        "initial_length_scale",
        INITIAL_LENGTH_SCALE_VR,
        "N",
        INITIAL_LENGTH_SCALE,
    )
    .min(0.0)
    .describe(if rig {
        "length scale, for every input, of a GP the training data give no hyperparameters for (in the unit of each input: m/s2 or N)"
    } else {
        "length scale, for every input, of a GP the training data give no hyperparameters for (in the unit of each input)"
    });
    // The inputs mix m/s² and N: the one value applies to each in its own unit.
    length_scale.unit = None;
    v.push(length_scale);
    v
}

/// The SI unit of a channel's quantity and of its square.
fn units_of(c: &Channel) -> (&'static str, &'static str) {
    match c.quantity() {
        Quantity::Velocity => ("m/s", "m2/s2"),
        Quantity::Displacement => ("m", "m2"),
        _ => ("m/s2", "m2/s4"),
    }
}

fn describe(c: &Channel) -> String {
    match *c {
        Channel::Response { quantity, floor } => match quantity {
            Quantity::Velocity => format!("velocity of floor {floor} relative to the ground"),
            Quantity::Displacement => {
                format!("displacement of floor {floor} relative to the ground")
            }
            _ => format!("absolute acceleration of floor {floor}"),
        },
        _ => c.name(),
    }
}

/// Another layout's variables (see the module documentation).
fn layout_variables(layout: &Layout) -> Vec<Variable> {
    let mut v = Vec::new();
    let exc = excitation_vr(layout);
    for (j, c) in layout.channels.iter().enumerate() {
        let name = c.name();
        v.push(
            Variable::real_input(
                &format!("physics_{name}"),
                vr_of(layout, Role::Physics, j),
                units_of(c).0,
                0.0,
            )
            .describe(&format!("{} predicted by the physics model", describe(c))),
        );
    }
    v.push(match layout.excitation {
        ExcitationKind::Force => Variable::real_input("force", exc, "N", 0.0)
            .describe("excitation force, as given to the physics model"),
        ExcitationKind::GroundAcc => Variable::real_input("ground_acc", exc, "m/s2", 0.0)
            .describe("ground acceleration at the base, as given to the physics model"),
    });
    for (j, c) in layout.channels.iter().enumerate() {
        let name = c.name();
        v.push(
            Variable::real_input(
                &format!("measured_{name}"),
                vr_of(layout, Role::Measured, j),
                units_of(c).0,
                0.0,
            )
            .describe(&format!(
                "measured {}: the training target when learn is true",
                describe(c)
            )),
        );
    }
    v.push(Variable::boolean_input("learn", LEARN, false).describe(
        "at each fmi2DoStep with learn true, the current sample joins every channel's training set",
    ));
    let depends = |j: usize| -> Vec<u32> {
        layout
            .columns_of(j)
            .into_iter()
            .map(|col| {
                if col == layout.channels.len() {
                    exc
                } else {
                    vr_of(layout, Role::Physics, col)
                }
            })
            .collect()
    };
    for (role, what) in [
        (Role::Corrected, "corrected"),
        (Role::LatentVar, "latent"),
        (Role::Sd, "sd"),
    ] {
        for (j, c) in layout.channels.iter().enumerate() {
            let (unit, squared) = units_of(c);
            let vr = vr_of(layout, role, j);
            let var = match what {
                "corrected" => Variable::real_output(&c.name(), vr, unit).describe(&format!(
                    "corrected {}: physics + GP mean (target 0) or GP mean (target 1)",
                    describe(c)
                )),
                "latent" => Variable::real_output(&band_name("latent_var", c), vr, squared)
                    .describe(&format!(
                        "latent predictive variance V(f*) of {}'s GP (noise excluded)",
                        c.name()
                    )),
                _ => Variable::real_output(&band_name("sd", c), vr, unit).describe(&format!(
                    "predictive standard deviation sqrt(V(f*) + noise variance) of {}",
                    c.name()
                )),
            };
            v.push(var.depends_on(&depends(j)));
        }
    }
    v.extend(parameters(false));
    v
}

fn layout_units(layout: &Layout) -> Vec<Unit> {
    let mut names: Vec<&'static str> = vec!["m/s2", "m2/s4"];
    for c in &layout.channels {
        let (a, b) = units_of(c);
        names.extend([a, b]);
    }
    if layout.excitation == ExcitationKind::Force {
        names.push("N");
    }
    let mut out: Vec<Unit> = Vec::new();
    for name in names {
        if out.iter().any(|u| u.name == name) {
            continue;
        }
        let (kg, m, s) = match name {
            "m/s2" => (0, 1, -2),
            "m2/s4" => (0, 2, -4),
            "m/s" => (0, 1, -1),
            "m2/s2" => (0, 2, -2),
            "m" => (0, 1, 0),
            "m2" => (0, 2, 0),
            _ => (1, 1, -2),
        };
        out.push(Unit { name, kg, m, s });
    }
    out
}

fn build(layout: &Layout) -> ModelInfo {
    let names = layout.names();
    ModelInfo::new(
        &format!("GpCorrector{}", names.len()),
        MODEL_IDENTIFIER,
        &format!(
            "Gaussian-process bias corrector of a shear frame's physics model: one zero-mean Matérn 3/2 ARD GP per measured channel ({}) on lags of the physics predictions of the channel and its nearest measured neighbours and of the {}, with online learning",
            names.join(", "),
            layout.excitation_name()
        ),
        env!("CARGO_PKG_VERSION"),
        layout_variables(layout),
        layout_units(layout),
        false,
        Some(DefaultExperiment { start_time: 0.0, stop_time: 20.0, step_size: 1.0 / 51.2 }),
    )
    // Built from a checked layout; the unit tests build tables of several layouts.
    .expect("the GP corrector's variable table is consistent")
}

/// The table of a checked layout: [`info`] for the paper's rig, else built once per layout and
/// kept for the life of the library.
pub fn table(layout: &Layout) -> &'static ModelInfo {
    static TABLES: OnceLock<Mutex<Vec<(Layout, &'static ModelInfo)>>> = OnceLock::new();
    if layout.is_paper() {
        return info();
    }
    let tables = TABLES.get_or_init(Default::default);
    // A poisoned lock only means another thread panicked while pushing; the list is still whole.
    let mut tables = tables.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, info)) = tables.iter().find(|(l, _)| l == layout) {
        return info;
    }
    let info: &'static ModelInfo = Box::leak(Box::new(build(layout)));
    tables.push((layout.clone(), info));
    info
}

/// The table, built and checked once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "GpCorrector3",
            MODEL_IDENTIFIER,
            "Gaussian-process bias corrector of a three-storey shear frame's physics model: one zero-mean Matérn 3/2 ARD GP per floor on lagged physics accelerations and force, with online learning",
            env!("CARGO_PKG_VERSION"),
            variables(),
            units(),
            false,
            Some(DefaultExperiment { start_time: 0.0, stop_time: 20.0, step_size: 1.0 / 51.2 }),
        )
        // The table is a constant of this crate; a unit test builds it, so this cannot fail at run time.
        .expect("the GP corrector's variable table is consistent")
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_table_is_consistent() {
        let info = super::info();
        assert_eq!(info.model_identifier, super::MODEL_IDENTIFIER);
    }

    /// Other layouts build (distinct names and value references, checked by `ModelInfo::new`),
    /// with their channels' variables and the rig's parameters, and a GUID of their own.
    #[test]
    fn other_layouts_have_tables_of_their_own() {
        use super::*;
        let five = Layout::from_names(&["acc1", "acc3", "acc5", "vel2"], "ground_acc")
            .expect("test value");
        let t = table(&five);
        for name in [
            "physics_acc3",
            "measured_vel2",
            "acc5",
            "vel2",
            "latent_var3",
            "sd_vel2",
            "latent_var_vel2",
            "ground_acc",
            "lags",
            "training_path",
        ] {
            assert!(t.by_name(name).is_some(), "{name}");
        }
        assert!(t.by_name("force").is_none());
        assert!(t.by_name("acc2").is_none());
        assert_ne!(t.guid, info().guid);
        assert_eq!(table(&Layout::default()).guid, info().guid);
        let vel = t.by_name("sd_vel2").expect("test value");
        assert_eq!(vel.unit, Some("m/s"));
        assert_eq!(role_of(&five, vel.vr), Some((Role::Sd, 3)));
        // vel2's GP: itself, acc1 and acc3 (floor distance 1), the ground acceleration.
        assert_eq!(
            vel.depends_on,
            vec![
                vr_of(&five, Role::Physics, 0),
                vr_of(&five, Role::Physics, 1),
                vr_of(&five, Role::Physics, 3),
                GROUND_ACC
            ]
        );
        let every: Vec<String> = (1..=structure::MAX_STOREYS)
            .flat_map(|f| [format!("acc{f}"), format!("vel{f}"), format!("disp{f}")])
            .collect();
        let all = Layout::from_names(&every, "force").expect("test value");
        assert_eq!(
            table(&all).by_name("disp50").map(|v| v.vr),
            Some(LAYOUT_CORRECTED + 149)
        );
    }
}
