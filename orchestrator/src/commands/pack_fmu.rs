//! `twin pack-fmu`: a built FMU library and its modelDescription.xml → a .fmu archive.

use std::path::PathBuf;

use anyhow::Result;

#[derive(clap::Args)]
pub struct PackArgs {
    #[arg(long)]
    pub model_description: PathBuf,
    #[arg(long)]
    pub library: PathBuf,
    #[arg(long)]
    pub documentation: Option<PathBuf>,
    #[arg(long)]
    pub resources: Option<PathBuf>,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: PackArgs) -> Result<()> {
    let contents = crate::cosim::pack::FmuContents {
        model_description: a.model_description,
        library: a.library,
        documentation: a.documentation,
        resources: a.resources,
    };
    let id = crate::cosim::pack::pack_fmu(&contents, &a.out)?;
    println!("wrote {} (modelIdentifier {id})", a.out.display());
    Ok(())
}
