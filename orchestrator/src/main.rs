//! `twin`: the digital twin's command line. Thin: parse → run → exit code, printing the error chain.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "twin", version, about = "shear-twin: an operational digital twin on FMI 2.0")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Package a built FMU library and its modelDescription.xml into a .fmu archive.
    PackFmu {
        #[arg(long)]
        model_description: PathBuf,
        #[arg(long)]
        library: PathBuf,
        #[arg(long)]
        documentation: Option<PathBuf>,
        #[arg(long)]
        resources: Option<PathBuf>,
        #[arg(long)]
        out: PathBuf,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::PackFmu { model_description, library, documentation, resources, out } => {
            let contents = orchestrator::fmu_archive::FmuContents { model_description, library, documentation, resources };
            let id = orchestrator::fmu_archive::pack_fmu(&contents, &out)?;
            println!("wrote {} (modelIdentifier {id})", out.display());
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("twin: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
