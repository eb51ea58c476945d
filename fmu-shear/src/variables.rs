//! The shear FMU's variable table. Value-reference constants carry the XML names.

use std::sync::OnceLock;

use fmi2::{DefaultExperiment, ModelInfo, Unit, Variable};

use crate::effects::Effects;
use crate::model::{ShearParameters, DEFAULT_SUBSTEPS};

pub const FORCE: u32 = 1;
pub const CONTROL_FORCE: u32 = 2;
/// acc1..acc3 are ACC..ACC+2; likewise for the other per-floor outputs and parameters.
pub const ACC: u32 = 10;
pub const DISP: u32 = 13;
pub const VEL: u32 = 16;
pub const DRIFT: u32 = 19;
pub const MASS: u32 = 30;
pub const DAMPING: u32 = 33;
pub const STIFFNESS: u32 = 36;
pub const SUBSTEPS: u32 = 40;
pub const INTEGRATOR: u32 = 41;
pub const SENSITIVITIES: u32 = 42;
/// `d_acc{f}_d_{p}` is SENSITIVITY + 9 (f − 1) + the index of p in
/// [`crate::sensitivity::PARAMETERS`].
pub const SENSITIVITY: u32 = 50;

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

fn variables() -> Vec<Variable> {
    let p = ShearParameters::default();
    let mut v = vec![
        Variable::real_input("force", FORCE, "N", 0.0)
            .describe("excitation force on floor 1 (the shaker)"),
        Variable::real_input("control_force", CONTROL_FORCE, "N", 0.0)
            .describe("control force on floor 1, acting against the excitation"),
    ];
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("acc{floor}"), ACC + i, "m/s2")
                .describe(&format!("absolute acceleration of floor {floor}"))
                .depends_on(&[FORCE, CONTROL_FORCE]),
        );
    }
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("disp{floor}"), DISP + i, "m")
                .describe(&format!("displacement of floor {floor}")),
        );
    }
    for i in 0..3u32 {
        let floor = i + 1;
        v.push(
            Variable::real_output(&format!("vel{floor}"), VEL + i, "m/s")
                .describe(&format!("velocity of floor {floor}")),
        );
    }
    for i in 0..3u32 {
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
    for i in 0..3usize {
        let n = i + 1;
        v.push(
            Variable::real_parameter(&format!("m{n}"), MASS + i as u32, "kg", p.mass[i])
                .min(0.0)
                .describe(&format!("mass of floor {n}")),
        );
    }
    for i in 0..3usize {
        let n = i + 1;
        v.push(
            Variable::real_parameter(&format!("c{n}"), DAMPING + i as u32, "N.s/m", p.damping[i])
                .min(0.0)
                .describe(&format!("viscous damping of storey {n}")),
        );
    }
    for i in 0..3usize {
        let n = i + 1;
        v.push(
            Variable::real_parameter(
                &format!("k{n}"),
                STIFFNESS + i as u32,
                "N/m",
                p.stiffness[i],
            )
            .min(0.0)
            .describe(&format!("lateral stiffness of storey {n}")),
        );
    }
    v.push(
        Variable::integer_parameter("substeps", SUBSTEPS, DEFAULT_SUBSTEPS as i32)
            .min(1.0)
            .max(10000.0)
            .describe("RK4 sub-steps per communication step: the linear model's step map; with effects, when integrator = 1 (or 2 and not contacts alone)"),
    );
    v.push(
        Variable::integer_parameter("integrator", INTEGRATOR, 0)
            .min(0.0)
            .max(2.0)
            .describe("with effects: 0 exact step maps per contact region (contacts alone) or error-controlled Dormand-Prince 5(4) (other effects), split at contact kinks; 1 RK4 with substeps fixed sub-steps, split at contact kinks; 2 exact for contacts alone, otherwise as 1"),
    );
    v.push(
        Variable::boolean_parameter("sensitivities", SENSITIVITIES, false).describe(
            "carry the forward sensitivities of the accelerations to m1..m3, c1..c3, k1..k3 (the linear model: with an effect on they are NaN)",
        ),
    );
    for f in 0..3u32 {
        for (j, p) in crate::sensitivity::PARAMETERS.iter().enumerate() {
            let unit = ["m/(s2.kg)", "m/(kg.s)", "m/kg"][j / 3];
            let floor = f + 1;
            v.push(
                Variable::real_output(
                    &format!("d_acc{floor}_d_{p}"),
                    SENSITIVITY + 9 * f + j as u32,
                    unit,
                )
                .describe(&format!(
                    "derivative of acc{floor} with respect to {p} along the run (NaN unless sensitivities is on and no effect is)"
                ))
                .depends_on(&[FORCE, CONTROL_FORCE]),
            );
        }
    }
    v.extend(Effects::all_variables());
    v
}

/// The table, built and checked once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "ShearFrame3",
            MODEL_IDENTIFIER,
            "Three-storey shear frame (3-DOF, eq. 1 of the reference paper) shaken at floor 1, RK4 with sub-steps and optional gap contact, cubic stiffness, friction and up to six discovered terms coefficient·f(x, v)",
            env!("CARGO_PKG_VERSION"),
            variables(),
            units(),
            true,
            Some(DefaultExperiment { start_time: 0.0, stop_time: 20.0, step_size: 1.0 / 51.2 }),
        )
        // The table is a constant of this crate; a unit test builds it, so this cannot fail at run time.
        .expect("the shear FMU's variable table is consistent")
    })
}
