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
    match commands::run(commands::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("twin: error: {err:#}");
            ExitCode::FAILURE
        }
    }
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
