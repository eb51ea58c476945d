//! `twin fleet`: the twin's work for many structures as tasks on Dask. The fleet runner is
//! Python (`shear_twin.fleet`, on dask.distributed, calling this library through the
//! `shear_twin` extension); this subcommand runs it in the project's Python environment.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::Command;

use anyhow::{bail, Context, Result};

#[derive(clap::Args)]
pub struct FleetArgs {
    /// The fleet's manifest (JSON: structures with their twin and record; see shear_twin.fleet),
    /// or `synth` followed by `--out DIR --structures N` to make a synthetic fleet.
    #[arg(allow_hyphen_values = true, trailing_var_arg = true, num_args = 1..)]
    pub args: Vec<OsString>,
}

/// The Python that has `shear_twin`: `$TWIN_PYTHON`, else the repository's `.venv` beside a
/// cargo-built `twin` (`target/<profile>/twin` → `.venv/bin/python`), else `python3`.
fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("TWIN_PYTHON") {
        return PathBuf::from(p);
    }
    if let Ok(exe) = std::env::current_exe() {
        if let Some(root) = exe
            .parent()
            .and_then(|d| d.parent())
            .and_then(|d| d.parent())
        {
            let venv = root.join(".venv/bin/python");
            if venv.is_file() {
                return venv;
            }
        }
    }
    PathBuf::from("python3")
}

pub fn run(args: &FleetArgs) -> Result<()> {
    let python = python();
    let mut command = Command::new(&python);
    command.arg("-m").arg("shear_twin.fleet").args(&args.args);
    // The runner's twins find their FMUs as this binary does: `TWIN_FMU_DIR` when set (it is
    // inherited), else the ones built into the package.
    let status = command.status().with_context(|| {
        format!(
            "cannot run {} -m shear_twin.fleet (install the package: scripts/test.sh, or \
             pip install ./python; or set TWIN_PYTHON)",
            python.display()
        )
    })?;
    if !status.success() {
        bail!("the fleet runner failed ({status})");
    }
    Ok(())
}
