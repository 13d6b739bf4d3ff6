//! `evalharness merge` and `report` arguments: the join of a ranking run's shards, and its
//! report (`rank`'s own are [`ranking::args::RankArgs`]).

use std::path::PathBuf;

use clap::Args;

/// `evalharness merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The shards' output folders.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
    /// Skip the report.
    #[arg(long)]
    pub no_report: bool,
}

/// `evalharness report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// A `rank` output folder (with results.json and config.json).
    pub out: PathBuf,
}
