//! The LQR FMU's variable table. Value-reference constants carry the XML names.

use std::sync::OnceLock;

use fmi2::{DefaultExperiment, ModelInfo, Unit, Variability, Variable};

/// The floors this FMU's variables are laid out for (acc1..3, m1..m3, …; the law underneath,
/// `numerics::lqr`, takes any number).
pub const FLOORS: usize = 3;
/// The floor the control force acts on.
pub const DEFAULT_ACTUATOR_FLOOR: usize = 1;

/// gain1..gain6 are GAIN..GAIN+5 (the state `[y1, y2, y3, ẏ1, ẏ2, ẏ3]`).
pub const GAIN: u32 = 1;
pub const STATE_SCALE: u32 = 7;
/// m1..m3, c1..c3, k1..k3: the observer's model of the structure.
pub const MASS: u32 = 10;
pub const DAMPING: u32 = 13;
pub const STIFFNESS: u32 = 16;
/// Integer: 0 integrate, 1 Kalman.
pub const ESTIMATOR: u32 = 20;
pub const HIGHPASS_HZ: u32 = 21;
pub const PROCESS_SD: u32 = 22;
/// sensor_sd1..3.
pub const SENSOR_SD: u32 = 23;
pub const SAMPLE_INTERVAL: u32 = 26;
/// Inputs acc1..acc3 and force.
pub const ACC: u32 = 30;
pub const FORCE: u32 = 33;
/// Output.
pub const CONTROL_FORCE: u32 = 40;

pub const MODEL_IDENTIFIER: &str = "fmu_lqr";

/// The shear FMU's defaults (the reference paper's prior means), checked against it by a test.
pub const DEFAULT_MASS: f64 = 5.2;
pub const DEFAULT_DAMPING: f64 = 0.010_001_702_004_705_479; // exp(−4.605)
pub const DEFAULT_STIFFNESS: f64 = 4021.0;
pub const DEFAULT_HIGHPASS_HZ: f64 = 0.5;
pub const DEFAULT_PROCESS_SD: f64 = 0.1;
pub const DEFAULT_SENSOR_SD: f64 = 0.01;
pub const DEFAULT_SAMPLE_INTERVAL: f64 = 1.0 / 51.2;

fn units() -> Vec<Unit> {
    let unit = |name, kg, m, s| Unit { name, kg, m, s };
    vec![
        unit("s", 0, 0, 1),
        unit("Hz", 0, 0, -1),
        unit("kg", 1, 0, 0),
        unit("m", 0, 1, 0),
        unit("m/s2", 0, 1, -2),
        unit("N", 1, 1, -2),
        unit("N.s/m", 1, 0, -1),
        unit("N/m", 1, 0, -2),
    ]
}

fn variables() -> Vec<Variable> {
    let mut v = Vec::new();
    for i in 0..FLOORS as u32 {
        let floor = i + 1;
        v.push(
            Variable::real_input(&format!("acc{floor}"), ACC + i, "m/s2", 0.0).describe(&format!(
                "measured absolute acceleration of floor {floor}, sampled at fmi2DoStep"
            )),
        );
    }
    v.push(
        Variable::real_input("force", FORCE, "N", 0.0)
            .describe("excitation force on floor 1 now (the Kalman observer's known input)"),
    );
    let mut out = Variable::real_output("control_force", CONTROL_FORCE, "N").describe(
        "the command computed at the last fmi2DoStep from the sample at its start; it acts on the structure over the next step",
    );
    // Changes only at fmi2DoStep: no direct feedthrough from the inputs.
    out.variability = Variability::Discrete;
    v.push(out);
    let states = ["y1", "y2", "y3", "v1", "v2", "v3"];
    for (i, s) in states.iter().enumerate() {
        let mut g = Variable::real_parameter(&format!("gain{}", i + 1), GAIN + i as u32, "N", 0.0)
            .describe(&format!(
                "LQR gain on state {s} (N per state unit; f_c = sum gain_i w_i)"
            ));
        // N per state unit: the unit depends on state_scale.
        g.unit = None;
        v.push(g);
    }
    v.push(
        Variable::real_parameter("state_scale", STATE_SCALE, "m", 1.0)
            .min(0.0)
            .describe("metres per state unit (1e-3: the state in mm and mm/s)"),
    );
    for i in 0..FLOORS as u32 {
        let n = i + 1;
        v.push(
            Variable::real_parameter(&format!("m{n}"), MASS + i, "kg", DEFAULT_MASS)
                .min(0.0)
                .describe(&format!("mass of floor {n} (the observer's model)")),
        );
    }
    for i in 0..FLOORS as u32 {
        let n = i + 1;
        v.push(
            Variable::real_parameter(&format!("c{n}"), DAMPING + i, "N.s/m", DEFAULT_DAMPING)
                .min(0.0)
                .describe(&format!(
                    "viscous damping of storey {n} (the observer's model)"
                )),
        );
    }
    for i in 0..FLOORS as u32 {
        let n = i + 1;
        v.push(
            Variable::real_parameter(&format!("k{n}"), STIFFNESS + i, "N/m", DEFAULT_STIFFNESS)
                .min(0.0)
                .describe(&format!("stiffness of storey {n} (the observer's model)")),
        );
    }
    v.push(
        Variable::integer_parameter("estimator", ESTIMATOR, 0)
            .min(0.0)
            .max(1.0)
            .describe("0: integrate the accelerations with drift removal (highpass_hz); 1: steady-state Kalman observer (process_sd, sensor_sd1..3)"),
    );
    v.push(
        Variable::real_parameter("highpass_hz", HIGHPASS_HZ, "Hz", DEFAULT_HIGHPASS_HZ)
            .min(0.0)
            .describe("corner of the integrating estimator's drift removal"),
    );
    v.push(
        Variable::real_parameter("process_sd", PROCESS_SD, "N", DEFAULT_PROCESS_SD)
            .min(0.0)
            .describe("Kalman observer: sd of a white force error on floor 1 per sample"),
    );
    for i in 0..FLOORS as u32 {
        let n = i + 1;
        v.push(
            Variable::real_parameter(
                &format!("sensor_sd{n}"),
                SENSOR_SD + i,
                "m/s2",
                DEFAULT_SENSOR_SD,
            )
            .min(0.0)
            .describe(&format!(
                "Kalman observer: noise sd of floor {n}'s accelerometer"
            )),
        );
    }
    v.push(
        Variable::real_parameter(
            "sample_interval",
            SAMPLE_INTERVAL,
            "s",
            DEFAULT_SAMPLE_INTERVAL,
        )
        .min(0.0)
        .describe(
            "the controller's sample interval: every fmi2DoStep must be this long (1e-9 relative)",
        ),
    );
    v
}

/// The table, built and checked once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "LqrController3",
            MODEL_IDENTIFIER,
            "LQR controller of a three-storey shear frame: state estimated from the floor accelerations (integration or Kalman observer), command f_c = K w computed at each fmi2DoStep and acting over the next step",
            env!("CARGO_PKG_VERSION"),
            variables(),
            units(),
            false,
            Some(DefaultExperiment { start_time: 0.0, stop_time: 20.0, step_size: DEFAULT_SAMPLE_INTERVAL }),
        )
        // The table is a constant of this crate; a unit test builds it, so this cannot fail at run time.
        .expect("the LQR FMU's variable table is consistent")
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_table_is_consistent() {
        assert_eq!(super::info().model_identifier, super::MODEL_IDENTIFIER);
    }

    #[test]
    fn the_default_damping_is_the_shear_fmus() {
        assert_eq!(super::DEFAULT_DAMPING, (-4.605f64).exp());
    }
}
