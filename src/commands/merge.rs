//! `evalharness merge SHARD... --out OUT`: joins `rank --shard i/n` outputs into
//! what one unsharded run writes ([`runner::merge`]).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;

/// `evalharness merge`: joins shard folders into `out` and says so on stdout.
///
/// # Errors
/// As [`runner::merge::join`].
pub fn run(shards: &[PathBuf], out: &Path, force: bool, no_report: bool) -> Result<ExitCode> {
    let (rows, _) = runner::merge::join(shards, out, force, no_report, true)?;
    outln!("merged {} shards: {rows} rows -> {}", shards.len(), out.display());
    Ok(ExitCode::SUCCESS)
}
