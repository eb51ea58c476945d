//! The GP corrector's variable table. Value-reference constants carry the XML names.

use std::sync::OnceLock;

use fmi2::{Causality, DefaultExperiment, ModelInfo, Start, Unit, VarType, Variability, Variable};

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

pub const MODEL_IDENTIFIER: &str = "fmu_gp_corrector";

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
        description: "number of points in each floor's training set".to_owned(),
        depends_on: Vec::new(),
    });
    v.push(
        Variable::integer_parameter("lags", LAGS, DEFAULT_LAGS as i32)
            .min(0.0)
            .max(MAX_LAGS as f64)
            .describe("q: the GP inputs are the current and q previous samples of physics_acc1..3 and force, 4 (q + 1) values"),
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
            .describe("the most training points a floor's GP keeps while learning: beyond, the oldest goes"),
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
        .describe("signal variance of a GP the training data give no hyperparameters for"),
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
    .describe("length scale, for every input, of a GP the training data give no hyperparameters for (in the unit of each input: m/s2 or N)");
    // The inputs mix m/s² and N: the one value applies to each in its own unit.
    length_scale.unit = None;
    v.push(length_scale);
    v
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
}
