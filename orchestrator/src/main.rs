//! `twin`: the digital twin's command line. Thin: parse → run → exit code, printing the error chain.

use std::process::ExitCode;

use clap::Parser;

mod commands;

// The library's modules at the binary's root: the commands name them `crate::…`.
use orchestrator::{
    choice, cosim, evaluation, fsutil, record, report, serve, synth, twin, workflows,
};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    restore_sigpipe();
    print_notices();
    match commands::run(commands::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("twin: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

/// The library's notices on stderr: every live page failure; the FMUs' log messages only when
/// `TWIN_FMU_LOG` is set.
fn print_notices() {
    let fmu_log = std::env::var_os("TWIN_FMU_LOG").is_some();
    orchestrator::notice::set_sink(move |n| {
        if n.topic != orchestrator::notice::Topic::FmuLog || fmu_log {
            eprintln!("{}", n.text);
        }
    });
}

/// A command whose output is piped into `head` (or any reader that stops early) ends quietly, as
/// Unix tools do, killed by SIGPIPE: Rust's runtime ignores the signal, and every `println!`
/// after the reader has gone would panic on the broken pipe.
#[cfg(unix)]
#[allow(unsafe_code)]
fn restore_sigpipe() {
    // SAFETY: setting a signal's disposition to its default, first thing in `main`, before any
    // thread exists; no handler of ours is involved.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_sigpipe() {}
