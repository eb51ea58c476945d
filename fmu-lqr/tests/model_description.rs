//! The committed `modelDescription/fmu_lqr.xml` is exactly what the variable table generates,
//! and its GUID is the one `fmi2Instantiate` checks. Regenerate on purpose with
//! `UPDATE_MODEL_DESCRIPTION=1 cargo test -p fmu-lqr --test model_description`.

use std::path::PathBuf;

use fmi2::{Causality, CoSimModel, Start, VarType};
use fmu_lqr::LqrModel;

fn committed_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../modelDescription/fmu_lqr.xml")
}

#[test]
fn committed_model_description_matches_the_variable_table() {
    if let Err(problem) = LqrModel::info().check_committed_model_description(&committed_path()) {
        panic!("{problem}");
    }
}

#[test]
fn the_table_has_the_interface_the_controlled_system_connects_to() {
    let info = LqrModel::info();
    let check = |name: &str, var_type: VarType, causality: Causality| {
        let v = info
            .by_name(name)
            .unwrap_or_else(|| panic!("variable {name} is in the table"));
        assert_eq!((v.var_type, v.causality), (var_type, causality), "{name}");
        v.clone()
    };
    for floor in 1..=3 {
        check(&format!("acc{floor}"), VarType::Real, Causality::Input);
        check(
            &format!("sensor_sd{floor}"),
            VarType::Real,
            Causality::Parameter,
        );
    }
    check("force", VarType::Real, Causality::Input);
    let out = check("control_force", VarType::Real, Causality::Output);
    assert!(
        out.depends_on.is_empty(),
        "the command is computed in fmi2DoStep: no direct feedthrough"
    );
    for i in 1..=6 {
        check(&format!("gain{i}"), VarType::Real, Causality::Parameter);
    }
    for name in [
        "state_scale",
        "m1",
        "m2",
        "m3",
        "c1",
        "c2",
        "c3",
        "k1",
        "k2",
        "k3",
        "highpass_hz",
        "process_sd",
        "sample_interval",
    ] {
        check(name, VarType::Real, Causality::Parameter);
    }
    assert_eq!(
        check("estimator", VarType::Integer, Causality::Parameter).start,
        Start::Integer(0)
    );
}

#[test]
fn the_observer_model_defaults_are_the_shear_fmus() {
    let info = LqrModel::info();
    let shear = fmu_shear::ShearModel::info();
    for name in ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"] {
        let ours = info.by_name(name).expect("in the table").start.clone();
        let theirs = shear
            .by_name(name)
            .expect("in the shear table")
            .start
            .clone();
        assert_eq!(ours, theirs, "{name}");
    }
}
