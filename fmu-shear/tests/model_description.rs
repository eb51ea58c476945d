//! The committed `modelDescription/fmu_shear.xml` is exactly what the variable table generates,
//! and its GUID is the one `fmi2Instantiate` checks. Regenerate on purpose with
//! `UPDATE_MODEL_DESCRIPTION=1 cargo test -p fmu-shear --test model_description`.

use std::path::PathBuf;

use fmi2::CoSimModel;
use fmu_shear::ShearModel;

fn committed_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../modelDescription/fmu_shear.xml")
}

#[test]
fn committed_model_description_matches_the_variable_table() {
    if let Err(problem) = ShearModel::info().check_committed_model_description(&committed_path()) {
        panic!("{problem}");
    }
}

#[test]
fn every_effect_is_off_by_default_and_parameters_have_the_paper_priors() {
    let info = ShearModel::info();
    for v in &info.variables {
        if v.name.ends_with("_enabled") {
            assert_eq!(v.start, fmi2::Start::Boolean(false), "{}", v.name);
        }
    }
    let start = |name: &str| match info.by_name(name).map(|v| v.start.clone()) {
        Some(fmi2::Start::Real(x)) => x,
        other => panic!("{name}: {other:?}"),
    };
    for i in 1..=3 {
        assert_eq!(start(&format!("m{i}")), 5.2);
        assert_eq!(start(&format!("c{i}")), (-4.605f64).exp());
        assert_eq!(start(&format!("k{i}")), 4021.0);
    }
    for name in [
        "force",
        "control_force",
        "acc1",
        "acc2",
        "acc3",
        "disp1",
        "vel3",
        "contact23_gap",
        "cubic2_stiffness",
        "friction1_force",
    ] {
        assert!(
            info.by_name(name).is_some(),
            "variable {name} is in the table"
        );
    }
}
