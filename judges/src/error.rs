//! Why a judge folder, or a dataset a judge learns from or is read on, cannot be used.

use std::path::PathBuf;

/// A judge's failure, naming the folder, file or dataset; sources kept.
#[derive(Debug, thiserror::Error)]
pub enum JudgeError {
    /// A file or folder that cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// A `judge.json` that does not parse as one.
    #[error("{}: {source}", path.display())]
    File {
        /// The `judge.json`.
        path: PathBuf,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// A `judge.json` whose settings do not fit together or are unknown.
    #[error("{}: {what}", path.display())]
    Invalid {
        /// The `judge.json`.
        path: PathBuf,
        /// What does not fit.
        what: String,
    },
    /// Weights that are missing, truncated or do not fit the network, or cannot be written.
    #[error("{}: {source}", path.display())]
    Weights {
        /// The weights file.
        path: PathBuf,
        /// burn's error.
        #[source]
        source: burn::store::RecordError,
    },
    /// A dataset that cannot be read.
    #[error("dataset {}: {source}", path.display())]
    Replay {
        /// The dataset.
        path: PathBuf,
        /// The reader's error.
        #[source]
        source: harness::replay::ReplayError,
    },
    /// A dataset a judge cannot learn from: no label array, non-finite labels, too few
    /// episodes, or a loss that is no longer finite.
    #[error("dataset {}: {what}", path.display())]
    Dataset {
        /// The dataset.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// A small file (`judge.json`) that cannot be written.
    #[error(transparent)]
    Write(#[from] harness::runfile::RunFileError),
}
