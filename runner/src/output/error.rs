//! What can stop a command from writing its output folder, each case naming the
//! folders involved and what to do instead.

use std::path::PathBuf;

/// An output folder that cannot be prepared, locked, staged or committed.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file-system operation failed; `doing` says which, naming the path.
    #[error("{doing}: {source}")]
    Io {
        /// What was being done (`creating OUT`, `moving OUT aside to OUT.replaced`, ...).
        doing: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A folder beside `--out` with the tool's name that the tool did not make.
    #[error(
        "{} exists and was not made by evalharness, which keeps {what} there; move or rename it (nothing was written)",
        dir.display()
    )]
    NotOurs {
        /// The folder.
        dir: PathBuf,
        /// What the tool keeps there.
        what: String,
    },
    /// A run's output exists and neither `--resume` nor `--force` was given.
    #[error("{} already exists (pass --resume to continue it or --force to replace it)", out.display())]
    RunExists {
        /// The output.
        out: PathBuf,
    },
    /// An output exists and `--force` was not given.
    #[error("output {} already exists (pass --force to replace it)", out.display())]
    Exists {
        /// The output.
        out: PathBuf,
    },
    /// An interrupted `--force` run left the run it was replacing aside.
    #[error(
        "{} holds the run an interrupted --force run was replacing; move it back to {} \
         (or delete it) before replacing {} again, or pass --resume to continue the new run",
        aside.display(),
        out.display(),
        out.display()
    )]
    ReplacedLeft {
        /// `OUT.replaced`.
        aside: PathBuf,
        /// The output.
        out: PathBuf,
    },
    /// Rows without the settings they were run with cannot be resumed.
    #[error(
        "--resume: {} has episodes but no config.json, so the settings its rows were run with \
         are unknown; start a new run (--force or another --out)",
        out.display()
    )]
    RowsWithoutConfig {
        /// The output.
        out: PathBuf,
    },
    /// Committing into an existing folder would overwrite some of its entries.
    #[error("{} already holds {}", target.display(), taken.join(", "))]
    Holds {
        /// The folder committed into.
        target: PathBuf,
        /// The names it already holds.
        taken: Vec<String>,
    },
    /// `--out` is, lies inside or contains an input.
    #[error("--out {} {how} the input {flag} {}; write the output somewhere else", out.display(), input.display())]
    Overlaps {
        /// The output.
        out: PathBuf,
        /// `is`, `lies inside` or `contains`.
        how: &'static str,
        /// The flag that named the input.
        flag: String,
        /// The input.
        input: PathBuf,
    },
    /// An input is where the tool keeps `OUT.partial`, `OUT.replaced` or `OUT.shards`.
    #[error(
        "the input {flag} {} is where this command keeps {suffix} files for --out {} \
         (it would be cleared or replaced); rename the input or write the output elsewhere",
        input.display(),
        out.display()
    )]
    InputKept {
        /// The flag that named the input.
        flag: String,
        /// The input.
        input: PathBuf,
        /// The kept folder's suffix.
        suffix: String,
        /// The output.
        out: PathBuf,
    },
    /// `--out` is a symbolic link to nothing.
    #[error(
        "--out {} is a symbolic link to {target}, which does not exist; create the target or give another --out",
        out.display()
    )]
    Dangling {
        /// The output.
        out: PathBuf,
        /// Where the link points.
        target: String,
    },
    /// Another process writes the output.
    #[error(
        "{} is being written by another evalharness process (its lock {} is held); \
         wait for it to finish, or write to another --out",
        out.display(),
        lock.display()
    )]
    Locked {
        /// The output.
        out: PathBuf,
        /// Its lock file.
        lock: PathBuf,
    },
    /// The lock file was replaced under the taker every time it locked it.
    #[error("could not lock {}: its lock file kept changing", out.display())]
    LockChanging {
        /// The output.
        out: PathBuf,
    },
    /// A dataset being staged could not be written.
    #[error("{}: {source}", dir.display())]
    Dataset {
        /// The staging folder.
        dir: PathBuf,
        /// The dataset writer's error.
        source: harness::replay::ReplayError,
    },
}

/// An [`OutputError::Io`] builder: `io("creating X")(e)`.
pub(crate) fn io(doing: impl Into<String>) -> impl FnOnce(std::io::Error) -> OutputError {
    let doing = doing.into();
    move |source| OutputError::Io { doing, source }
}
