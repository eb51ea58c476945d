//! `twin`: the digital twin's command line. Thin: parse → run → exit code, printing the error chain.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    match orchestrator::commands::run(orchestrator::commands::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("twin: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
