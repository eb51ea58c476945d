//! `twin export-fmus`: the FMUs built into this `twin` written out as `.fmu` archives.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

#[derive(clap::Args)]
pub struct ExportFmusArgs {
    /// Directory to write `<modelIdentifier>.fmu` into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: &ExportFmusArgs) -> Result<()> {
    let paths = crate::twin::embedded::export(&a.out)
        .with_context(|| format!("writing the FMUs into {}", a.out.display()))?;
    if paths.is_empty() {
        bail!("this twin was built without FMUs (the packer writes linux64 FMUs only)");
    }
    for path in paths {
        println!("wrote {}", path.display());
    }
    Ok(())
}
