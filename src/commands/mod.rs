//! One module per subcommand; [`run`] dispatches.

mod collect;
mod dataset;
mod episodes;
mod simulate;

use std::process::ExitCode;

use anyhow::Result;

pub use episodes::RendererKind;

use crate::cli::{Cli, Command, DatasetCommand};

/// Runs the parsed command; the exit code is 0 unless a gate failed (1).
pub fn run(cli: &Cli) -> Result<ExitCode> {
    match &cli.command {
        Command::Simulate(a) => simulate::run(a, cli.quiet),
        Command::Collect(a) => collect::run(a, cli.quiet),
        Command::Dataset(DatasetCommand::Info { path, json }) => dataset::info(path, *json),
    }
}
