//! The substructure FMU's variable table. Value-reference constants carry the XML names.

use std::sync::OnceLock;

use fmi2::{DefaultExperiment, ModelInfo, Unit, Variable};

/// Integer parameter: 0 numerical, 1 physical (specimen floor 3), 2 physical (specimen floors
/// 2 and 3, the paper's split).
pub const ROLE: u32 = 1;
/// m1..m3, c1..c3, k1..k3.
pub const MASS: u32 = 10;
pub const DAMPING: u32 = 13;
pub const STIFFNESS: u32 = 16;
pub const GAP: u32 = 19;
pub const CONTACT_STIFFNESS: u32 = 20;
/// Integer parameter: RK4 steps per fmi2DoStep (numerical) or per motion (physical).
pub const SUBSTEPS: u32 = 21;
pub const CONTROL_STEP: u32 = 22;
/// Numerical role's inputs.
pub const FORCE: u32 = 30;
pub const INTERFACE_FORCE: u32 = 31;
pub const INTERFACE_FORCE_RATE: u32 = 32;
/// Physical role's inputs.
pub const Y2_START: u32 = 40;
pub const V2_START: u32 = 41;
pub const Y2_END: u32 = 42;
pub const V2_END: u32 = 43;
/// Numerical role's outputs.
pub const Y1: u32 = 50;
pub const V1: u32 = 51;
pub const Y2: u32 = 52;
pub const V2: u32 = 53;
/// Physical role's outputs.
pub const MEASURED_FORCE: u32 = 60;
pub const Y3: u32 = 61;
pub const V3: u32 = 62;
pub const RELATIVE: u32 = 63;
pub const A2: u32 = 64;

pub const MODEL_IDENTIFIER: &str = "fmu_substructure";

pub const ROLE_NUMERICAL: i32 = 0;
/// The specimen is storey 3 with the bumper and floor 3, moved at floor 2.
pub const ROLE_PHYSICAL: i32 = 1;
/// The specimen is floors 2 and 3 (the reference paper's eqs 13–14): the measured force
/// carries floor 2's inertia.
pub const ROLE_PHYSICAL_FLOORS_2_3: i32 = 2;

/// The one structure this FMU's variable table serves, the paper's rig: three storeys cut at
/// floor 2 (the orchestrator runs other cuts on its Rust loop, the same `numerics::substructure`).
pub const STOREYS: usize = structure::paper::STOREYS;
pub const SPLIT_FLOOR: usize = structure::paper::SPLIT_FLOOR;

/// The shear FMU's defaults for the structure (the rig's prior means); the bumper of the hybrid
/// test's setup.
pub const DEFAULT_MASS: f64 = structure::paper::MASS;
pub const DEFAULT_DAMPING: f64 = 0.010_001_702_004_705_479; // exp(paper::LOG_DAMPING), a test says so
pub const DEFAULT_STIFFNESS: f64 = structure::paper::STIFFNESS;
pub const DEFAULT_GAP: f64 = 5e-4;
pub const DEFAULT_CONTACT_STIFFNESS: f64 = 0.0;
pub const DEFAULT_SUBSTEPS: i32 = 1;
pub const DEFAULT_CONTROL_STEP: f64 = 1.0 / 51.2 / 16.0;

fn units() -> Vec<Unit> {
    let unit = |name, kg, m, s| Unit { name, kg, m, s };
    vec![
        unit("s", 0, 0, 1),
        unit("kg", 1, 0, 0),
        unit("m", 0, 1, 0),
        unit("m/s", 0, 1, -1),
        unit("m/s2", 0, 1, -2),
        unit("N", 1, 1, -2),
        unit("N/s", 1, 1, -3),
        unit("N.s/m", 1, 0, -1),
        unit("N/m", 1, 0, -2),
    ]
}

/// The model's variables, in value-reference order of their groups: the role and the
/// structure, the bumper and stepping, then each role's inputs and outputs.
fn variables() -> Vec<Variable> {
    let mut v = role_and_structure();
    bumper_and_stepping(&mut v);
    numerical_inputs(&mut v);
    physical_inputs(&mut v);
    numerical_outputs(&mut v);
    physical_outputs(&mut v);
    v
}

/// The role, then each floor's mass and each storey's damping and stiffness.
fn role_and_structure() -> Vec<Variable> {
    let mut v = vec![Variable::integer_parameter("role", ROLE, ROLE_NUMERICAL)
        .min(0.0)
        .max(2.0)
        .describe("0: numerical substructure (floor 1 with storeys 1-2, and floor 2: the specimen's floor 2 under role 2, the twin's model of it as a predictor whose inertia the master takes out of interface_force); 1: physical substructure, specimen floor 3 (storey 3 with the bumper and floor 3, moved at floor 2); 2: physical substructure, specimen floors 2-3 (the reference paper's eqs 13-14: role 1 with floor 2's mass m2, whose inertia is in the measured force). A role ignores the other's inputs; the other's outputs read 0")];
    for i in 0..STOREYS as u32 {
        let n = i + 1;
        let side = match n {
            1 => "numerical",
            2 => "numerical; physical in role 2",
            _ => "physical",
        };
        v.push(
            Variable::real_parameter(&format!("m{n}"), MASS + i, "kg", DEFAULT_MASS)
                .min(0.0)
                .describe(&format!("mass of floor {n} ({side} role)")),
        );
    }
    for i in 0..STOREYS as u32 {
        let n = i + 1;
        let side = if n == 3 { "physical" } else { "numerical" };
        v.push(
            Variable::real_parameter(&format!("c{n}"), DAMPING + i, "N.s/m", DEFAULT_DAMPING)
                .min(0.0)
                .describe(&format!("viscous damping of storey {n} ({side} role)")),
        );
    }
    for i in 0..STOREYS as u32 {
        let n = i + 1;
        let side = if n == 3 { "physical" } else { "numerical" };
        v.push(
            Variable::real_parameter(&format!("k{n}"), STIFFNESS + i, "N/m", DEFAULT_STIFFNESS)
                .min(0.0)
                .describe(&format!("stiffness of storey {n} ({side} role)")),
        );
    }
    v
}

/// The bumper's gap and stiffness, the RK4 substeps and the physical role's motion time.
fn bumper_and_stepping(v: &mut Vec<Variable>) {
    v.push(
        Variable::real_parameter("gap", GAP, "m", DEFAULT_GAP)
            .min(0.0)
            .describe("gap of the bumper between floors 2 and 3: it closes when y2 - y3 > gap (physical role)"),
    );
    v.push(
        Variable::real_parameter(
            "contact_stiffness",
            CONTACT_STIFFNESS,
            "N/m",
            DEFAULT_CONTACT_STIFFNESS,
        )
        .min(0.0)
        .describe("stiffness of the closed bumper (physical role)"),
    );
    v.push(
        Variable::integer_parameter("substeps", SUBSTEPS, DEFAULT_SUBSTEPS)
            .min(1.0)
            .describe(
                "RK4 steps per fmi2DoStep (numerical role) or per imposed motion (physical role)",
            ),
    );
    v.push(
        Variable::real_parameter("control_step", CONTROL_STEP, "s", DEFAULT_CONTROL_STEP)
            .min(0.0)
            .describe("physical role: the duration of the imposed motion; every fmi2DoStep must be this long (1e-9 relative)"),
    );
}

/// The numerical role's inputs: the excitation and floor 2's load with its slope.
fn numerical_inputs(v: &mut Vec<Variable>) {
    v.push(
        Variable::real_input("force", FORCE, "N", 0.0)
            .describe("numerical role: excitation force on floor 1 (first-order interpolation through fmi2SetRealInputDerivatives)"),
    );
    v.push(
        Variable::real_input("interface_force", INTERFACE_FORCE, "N", 0.0)
            .describe("numerical role: floor 2's load at the step's start, acting as -interface_force on floor 2: the measured force F_m when the specimen is floor 3; F_m less the numerical floor 2's inertia when the specimen holds floor 2 (the master's added-mass correction)"),
    );
    v.push(
        Variable::real_input("interface_force_rate", INTERFACE_FORCE_RATE, "N/s", 0.0)
            .describe("numerical role: slope of floor 2's load over the coming step (load(tau) = interface_force + interface_force_rate * tau)"),
    );
}

/// The physical role's inputs: the imposed motion's ends.
fn physical_inputs(v: &mut Vec<Variable>) {
    for (name, vr, unit, what) in [
        (
            "y2_start",
            Y2_START,
            "m",
            "floor 2's displacement at the motion's start",
        ),
        (
            "v2_start",
            V2_START,
            "m/s",
            "floor 2's velocity at the motion's start",
        ),
        (
            "y2_end",
            Y2_END,
            "m",
            "floor 2's displacement at the motion's end",
        ),
        (
            "v2_end",
            V2_END,
            "m/s",
            "floor 2's velocity at the motion's end",
        ),
    ] {
        v.push(Variable::real_input(name, vr, unit, 0.0).describe(&format!(
            "physical role: {what} (the actuator's motion over control_step, a cubic Hermite)"
        )));
    }
}

/// The numerical role's outputs: floors 1 and 2's motion.
fn numerical_outputs(v: &mut Vec<Variable>) {
    for (name, vr, unit, what) in [
        ("y1", Y1, "m", "floor 1's displacement"),
        ("v1", V1, "m/s", "floor 1's velocity"),
        (
            "y2",
            Y2,
            "m",
            "floor 2's displacement (the actuator's target)",
        ),
        ("v2", V2, "m/s", "floor 2's velocity"),
    ] {
        v.push(
            Variable::real_output(name, vr, unit)
                .describe(&format!("numerical role: {what} (0 in the physical role)")),
        );
    }
}

/// The physical role's outputs at the end of the imposed motion.
fn physical_outputs(v: &mut Vec<Variable>) {
    let motion = [Y2_START, V2_START, Y2_END, V2_END];
    for (name, vr, unit, what) in [
        (
            "measured_force",
            MEASURED_FORCE,
            "N",
            "the interface force F_m = c3 (v2 - v3) + k3 (y2 - y3) + contact_stiffness * max(0, y2 - y3 - gap), plus m2 a2 in role 2",
        ),
        ("y3", Y3, "m", "floor 3's displacement"),
        ("v3", V3, "m/s", "floor 3's velocity"),
        ("relative", RELATIVE, "m", "y2 - y3, the bumper's closure"),
        (
            "a2",
            A2,
            "m/s2",
            "floor 2's acceleration (the imposed Hermite's), what an accelerometer on the specimen's floor 2 reads",
        ),
    ] {
        v.push(
            Variable::real_output(name, vr, unit)
                .depends_on(&motion)
                .describe(&format!(
                    "physical role: {what} at the end of the imposed motion (0 in the numerical role)"
                )),
        );
    }
}

/// The table, built and checked once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| {
        ModelInfo::new(
            "HybridSubstructure",
            MODEL_IDENTIFIER,
            "A substructure of the simulated real-time hybrid test of a three-storey shear frame: numerical (floor 1 and floor 2's model, role 0) or physical: storey 3 with a one-sided bumper and floor 3, moved at floor 2 by the actuator (role 1), or with floor 2's mass too, the reference paper's split (role 2); RK4",
            env!("CARGO_PKG_VERSION"),
            variables(),
            units(),
            true,
            Some(DefaultExperiment { start_time: 0.0, stop_time: 10.0, step_size: DEFAULT_CONTROL_STEP }),
        )
        // The table is a constant of this crate; a unit test builds it, so this cannot fail at run time.
        .expect("the substructure FMU's variable table is consistent")
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
        assert_eq!(super::DEFAULT_DAMPING, structure::paper::LOG_DAMPING.exp());
    }
}
