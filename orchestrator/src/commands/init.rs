//! `twin init`: the default twin (the shear FMU, default parameters) as an SSP archive.

use std::path::PathBuf;

use anyhow::Result;

use crate::twin::Twin;

#[derive(clap::Args)]
pub struct InitArgs {
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: &InitArgs) -> Result<()> {
    Twin::default_twin()?.write(&args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
