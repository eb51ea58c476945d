//! The committed `modelDescription/fmu_substructure.xml` is exactly what the variable table
//! generates, and its GUID is the one `fmi2Instantiate` checks. Regenerate on purpose with
//! `UPDATE_MODEL_DESCRIPTION=1 cargo test -p fmu-substructure --test model_description`.

use std::path::PathBuf;

use fmi2::{Causality, CoSimModel, InstantiateContext, Start, VarType};
use fmu_substructure::variables::*;
use fmu_substructure::SubstructureModel;
use numerics::substructure::{Frame, Imposed, Numerical, Physical, Split};

fn committed_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../modelDescription/fmu_substructure.xml")
}

#[test]
fn committed_model_description_matches_the_variable_table() {
    if let Err(problem) =
        SubstructureModel::info().check_committed_model_description(&committed_path())
    {
        panic!("{problem}");
    }
}

#[test]
fn the_table_has_both_roles_interfaces() {
    let info = SubstructureModel::info();
    let check = |name: &str, var_type: VarType, causality: Causality| {
        let v = info
            .by_name(name)
            .unwrap_or_else(|| panic!("variable {name} is in the table"));
        assert_eq!((v.var_type, v.causality), (var_type, causality), "{name}");
        v.clone()
    };
    assert!(info.can_interpolate_inputs);
    assert_eq!(
        check("role", VarType::Integer, Causality::Parameter).start,
        Start::Integer(0)
    );
    assert_eq!(
        check("substeps", VarType::Integer, Causality::Parameter).start,
        Start::Integer(1)
    );
    for name in [
        "m1",
        "m2",
        "m3",
        "c1",
        "c2",
        "c3",
        "k1",
        "k2",
        "k3",
        "gap",
        "contact_stiffness",
        "control_step",
    ] {
        check(name, VarType::Real, Causality::Parameter);
    }
    for name in [
        "force",
        "interface_force",
        "interface_force_rate",
        "y2_start",
        "v2_start",
        "y2_end",
        "v2_end",
    ] {
        check(name, VarType::Real, Causality::Input);
    }
    for name in ["y1", "v1", "y2", "v2"] {
        assert!(check(name, VarType::Real, Causality::Output)
            .depends_on
            .is_empty());
    }
    for name in ["measured_force", "y3", "v3", "relative", "a2"] {
        assert_eq!(
            check(name, VarType::Real, Causality::Output).depends_on,
            vec![Y2_START, V2_START, Y2_END, V2_END]
        );
    }
}

fn frame() -> Frame {
    Frame {
        mass: vec![4.6, 5.3, 4.9],
        damping: vec![8.0, 3.5, 2.6],
        stiffness: vec![3850.0, 4100.0, 4650.0],
        floor: 2,
        gap: 5e-4,
        contact_stiffness: 9000.0,
    }
}

fn model(role: i32, f: &Frame, h: f64) -> SubstructureModel {
    let mut m = SubstructureModel::instantiate(&InstantiateContext::default()).expect("model");
    m.set_integer(ROLE, role).expect("role");
    for i in 0..3u32 {
        m.set_real(MASS + i, f.mass[i as usize]).expect("m");
        m.set_real(DAMPING + i, f.damping[i as usize]).expect("c");
        m.set_real(STIFFNESS + i, f.stiffness[i as usize])
            .expect("k");
    }
    m.set_real(GAP, f.gap).expect("gap");
    m.set_real(CONTACT_STIFFNESS, f.contact_stiffness)
        .expect("k_nl");
    m.set_real(CONTROL_STEP, h).expect("h");
    m.exit_initialization().expect("parameters accepted");
    m
}

/// The numerical role's step is `Numerical::step` with the force and the interface force
/// linear over the step, bit for bit; the physical outputs read 0.
#[test]
fn the_numerical_role_is_the_shared_model() {
    let (f, h) = (frame(), 1e-3);
    let mut m = model(ROLE_NUMERICAL, &f, h);
    let mut reference = Numerical::at_rest(&f);
    for k in 0..50 {
        let (u, du, fm, rate) = ((k as f64 * 0.3).sin(), 2.0, 0.1 * k as f64, -3.0 + k as f64);
        m.set_real(FORCE, u).expect("force");
        m.set_real_input_derivative(FORCE, du).expect("slope");
        m.set_real(INTERFACE_FORCE, fm).expect("fm");
        m.set_real(INTERFACE_FORCE_RATE, rate).expect("rate");
        m.do_step(k as f64 * h, h).expect("step");
        reference.step(&f, h, (u, du), (fm, rate));
        assert_eq!(m.get_real(Y2).expect("y2"), reference.y[1]);
        assert_eq!(m.get_real(V1).expect("v1"), reference.v[0]);
        assert_eq!(m.get_real(MEASURED_FORCE).expect("fm"), 0.0);
    }
}

/// The physical roles' outputs are the specimen at the end of the motion set (role 2's force
/// with floor 2's inertia), and the step keeps that state; the numerical outputs read 0.
#[test]
fn the_physical_roles_are_the_shared_model() {
    for (role, split) in [
        (ROLE_PHYSICAL, Split::FloorNumerical),
        (ROLE_PHYSICAL_FLOORS_2_3, Split::FloorPhysical),
    ] {
        physical_role_is_the_shared_model(role, split);
    }
}

fn physical_role_is_the_shared_model(role: i32, split: Split) {
    let (f, h) = (frame(), 1e-3);
    let mut m = model(role, &f, h);
    let mut reference = Physical::at_rest(&f);
    let (mut y0, mut v0) = (0.0, 0.0);
    for k in 0..200 {
        let t = (k + 1) as f64 * h;
        let (y1, v1) = (2e-3 * (30.0 * t).sin(), 6e-2 * (30.0 * t).cos());
        for (vr, x) in [(Y2_START, y0), (V2_START, v0), (Y2_END, y1), (V2_END, v1)] {
            m.set_real(vr, x).expect("motion");
        }
        let imposed = Imposed { y0, v0, y1, v1, h };
        reference.step(&f, h, &imposed, 0.0);
        let a2 = imposed.acceleration_at_end();
        let expected = f.interface_force(split, y1, v1, a2, &reference);
        assert_eq!(m.get_real(MEASURED_FORCE).expect("fm"), expected);
        assert_eq!(m.get_real(A2).expect("a2"), a2);
        let storey3 = f.storey_above_force(y1, v1, &reference);
        match split {
            Split::FloorNumerical => assert_eq!(expected, storey3),
            Split::FloorPhysical => assert_eq!(expected, f.mass[1] * a2 + storey3),
        }
        assert_eq!(m.get_real(RELATIVE).expect("yr"), y1 - reference.y[0]);
        m.do_step(k as f64 * h, h).expect("step");
        // The kept state; the outputs now preview the same motion again, until the next is set.
        assert_eq!(m.physical, reference);
        assert_eq!(m.get_real(Y2).expect("y2"), 0.0);
        (y0, v0) = (y1, v1);
    }
    let e = m.do_step(200.0 * h, 2.0 * h).expect_err("another step");
    assert!(e.to_string().contains("control_step"), "{e}");
}

#[test]
fn bad_parameters_are_refused_by_name() {
    let mut m = SubstructureModel::instantiate(&InstantiateContext::default()).expect("model");
    let e = m.set_integer(ROLE, 3).expect_err("role 3");
    assert!(e.to_string().contains("'role'"), "{e}");
    for (vr, value, name) in [
        (MASS + 1, 0.0, "'m2'"),
        (MASS + 2, -1.0, "'m3'"),
        (GAP, -1e-3, "'gap'"),
        (CONTROL_STEP, 0.0, "'control_step'"),
    ] {
        let mut m = SubstructureModel::instantiate(&InstantiateContext::default()).expect("model");
        m.set_real(vr, value).expect("set");
        let e = m.exit_initialization().expect_err("refused").to_string();
        assert!(e.contains(name), "{e}");
    }
}
