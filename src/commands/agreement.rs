//! `evalharness agreement --csv FILE`: agreement metrics for any predictor
//! (`runner::agreement`), printed as JSON.

use std::process::ExitCode;

use anyhow::Result;

use crate::cli::AgreementArgs;

/// Runs the command.
pub fn run(a: &AgreementArgs) -> Result<ExitCode> {
    let out = runner::agreement::agreement_json(&a.csv, a.bootstrap, a.seed)?;
    outln!("{}", serde_json::to_string_pretty(&out)?);
    Ok(ExitCode::SUCCESS)
}
