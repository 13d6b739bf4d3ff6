//! `evalharness`: rank robot-policy checkpoints offline in a DriftWorld world
//! model, checked against a MuJoCo reference simulator.
//!
//! `main` only wires logging and maps the outcome to an exit code:
//! 0 success, 1 an evaluation ran but a gate failed, 2 an error.

mod cli;
mod commands;
mod output;
mod plan;
mod policy_kinds;
mod progress;
mod rank;
mod scenario;

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    init_logging(args.verbose, args.quiet);
    scenarios::route_mujoco_logs();
    match commands::run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// Logs go to stderr (stdout carries results only); `RUST_LOG` overrides the level.
fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "warn",
        (false, 0) => "info",
        (false, 1) => "debug",
        (false, _) => "trace",
    };
    // MuJoCo's own info messages (model compile timings) are noise at the default level.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{level},mujoco=warn")));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .init();
}
