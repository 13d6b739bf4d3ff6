//! What can stop `rank`: a flag or input refused before anything is written, the libraries it
//! drives (each error kept whole, with its source), a shard process that failed, and the
//! context a step adds ("loading scenario S", "starting shard i/n") around one of them.

use std::path::PathBuf;

/// A failed `rank`.
#[derive(Debug, thiserror::Error)]
pub enum RankError {
    /// A flag, or the combination of flags and inputs, refused; the message names them.
    #[error("{0}")]
    Refused(String),
    /// What the command was doing when `source` failed.
    #[error("{what}")]
    In {
        /// The step, naming its flag, file, shard or policy.
        what: String,
        /// What failed.
        #[source]
        source: Box<RankError>,
    },
    /// A shard process of `--processes` that ended without finishing its batches.
    #[error("--processes: shard {index}/{count} {why}; {log}")]
    Shard {
        /// The shard's index.
        index: usize,
        /// The number of shards.
        count: usize,
        /// How it ended ("ended with signal: 9", "ended with exit status: 2").
        why: String,
        /// Where its folder and log are, and the log's last lines.
        log: String,
    },
    /// A file or folder of the run's own (a shard's log or arguments, the shards' folder).
    #[error("{}: {source}", path.display())]
    File {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A shard's arguments' file that cannot be written.
    #[error(transparent)]
    RunFile(#[from] harness::runfile::RunFileError),
    /// A small JSON file that cannot be read or written.
    #[error(transparent)]
    Json(#[from] runner::command::JsonFileError),
    /// A value that cannot be written or read as JSON.
    #[error("encoding JSON: {0}")]
    Encode(#[from] serde_json::Error),
    /// Another I/O failure (starting a process, waiting for one).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The output folder (or an input placed inside it).
    #[error(transparent)]
    Output(#[from] runner::output::OutputError),
    /// The run layer: the run's configuration, resume and merge rules, batches, media,
    /// models and judges, the task's defaults.
    #[error(transparent)]
    Run(#[from] runner::RunError),
    /// The device the environment names.
    #[error(transparent)]
    Device(#[from] nn::device::DeviceError),
    /// A seed range.
    #[error(transparent)]
    Seeds(#[from] harness::seed::SeedRangeError),
    /// A run's `episodes.jsonl`.
    #[error(transparent)]
    Rows(#[from] harness::rows::RowsError),
    /// A task, its scenario file or its render workers.
    #[error(transparent)]
    Scenario(#[from] scenarios::ScenarioError),
    /// A policy checkpoint folder.
    #[error(transparent)]
    Policy(#[from] policies::dir::PolicyLoadError),
    /// The episode tables (`episodes.csv`, `episodes.parquet`).
    #[error(transparent)]
    Table(#[from] reports::episodes::TableError),
    /// The worker threads.
    #[error("starting worker threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
}

runner::context_for!(RankError);
