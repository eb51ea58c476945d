//! The committed `modelDescription/fmu_gp_corrector.xml` is exactly what the variable table
//! generates, and its GUID is the one `fmi2Instantiate` checks. Regenerate on purpose with
//! `UPDATE_MODEL_DESCRIPTION=1 cargo test -p fmu-gp-corrector --test model_description`.

use std::path::PathBuf;

use fmi2::{Causality, CoSimModel, Start, VarType};
use fmu_gp_corrector::variables::FEEDTHROUGH;
use fmu_gp_corrector::GpCorrector;

fn committed_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../modelDescription/fmu_gp_corrector.xml")
}

#[test]
fn committed_model_description_matches_the_variable_table() {
    if let Err(problem) = GpCorrector::info().check_committed_model_description(&committed_path()) {
        panic!("{problem}");
    }
}

#[test]
fn the_table_has_the_interface_the_twin_connects_to() {
    let info = GpCorrector::info();
    let check = |name: &str, var_type: VarType, causality: Causality| {
        let v = info
            .by_name(name)
            .unwrap_or_else(|| panic!("variable {name} is in the table"));
        assert_eq!((v.var_type, v.causality), (var_type, causality), "{name}");
        v.clone()
    };
    for floor in 1..=3 {
        check(
            &format!("physics_acc{floor}"),
            VarType::Real,
            Causality::Input,
        );
        check(
            &format!("measured_acc{floor}"),
            VarType::Real,
            Causality::Input,
        );
        for output in ["acc", "latent_var", "sd"] {
            let v = check(
                &format!("{output}{floor}"),
                VarType::Real,
                Causality::Output,
            );
            // Outputs are computed from the current physics accelerations and force.
            assert_eq!(v.depends_on, FEEDTHROUGH.to_vec(), "{}", v.name);
        }
    }
    check("force", VarType::Real, Causality::Input);
    check("learn", VarType::Boolean, Causality::Input);
    check("training_points", VarType::Integer, Causality::Output);
    check("training_path", VarType::String, Causality::Parameter);
    let start = |name: &str| check(name, VarType::Integer, Causality::Parameter).start;
    assert_eq!(start("lags"), Start::Integer(9));
    assert_eq!(start("target"), Start::Integer(0));
    assert_eq!(
        start("refit_every"),
        Start::Integer(fmu_gp_corrector::DEFAULT_REFIT_EVERY as i32)
    );
    assert!(
        !info.can_interpolate_inputs,
        "the corrector samples its inputs at communication points"
    );
}
