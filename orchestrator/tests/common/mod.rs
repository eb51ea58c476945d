//! Helpers shared by the orchestrator's integration tests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The workspace root (the bundled data is under `data/`).
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the orchestrator crate sits in the workspace")
        .to_owned()
}

/// Where `scripts/build-fmus.sh` put the FMUs (`<target>/fmu`); fails the test when they are
/// not there.
pub fn fmu_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target"));
    let dir = target.join("fmu");
    let fmu = dir.join("fmu_shear.fmu");
    assert!(
        fmu.is_file(),
        "{} is missing: run scripts/build-fmus.sh",
        fmu.display()
    );
    dir
}
