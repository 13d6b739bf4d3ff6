//! What can be wrong with a run folder's configuration, one variant per rule, each
//! naming the file and what to do instead.

use std::path::PathBuf;

/// A run configuration that cannot be read or written, or a resume or merge its
/// rules refuse.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A file-system operation failed; `doing` says which, naming the path.
    #[error("{doing}: {source}")]
    File {
        /// What was being done.
        doing: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a configuration of this kind: damaged, or written by a
    /// version of evalharness whose settings differ.
    #[error(
        "{}: not a {what} run's config.json that this version reads ({field}: {source}); \
         start a new run (--force or another --out)",
        path.display()
    )]
    Parse {
        /// The file.
        path: PathBuf,
        /// `rank` or `plan`.
        what: &'static str,
        /// The setting where parsing stopped (`.` for the whole file).
        field: String,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// `--resume` under settings other than the saved run's.
    #[error(
        "--resume: {} was written with other settings: {}; pass the same options, or --force to start over",
        path.display(),
        differs.join("; ")
    )]
    Differs {
        /// The saved configuration.
        path: PathBuf,
        /// Each differing setting, `name (saved: …, now: …)`.
        differs: Vec<String>,
    },
    /// A task's `rank.toml` that is not one (an unknown key, a wrong type).
    #[error("{}: invalid rank defaults: {source}", path.display())]
    Defaults {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// A model folder's content changed since the saved run.
    #[error(
        "--resume: the content of {} changed since {} was written (its rows came from the \
         old files); restore them, or start a new run (--force or another --out)",
        names.join(", "),
        path.display()
    )]
    Changed {
        /// The saved configuration.
        path: PathBuf,
        /// The inputs whose fingerprint differs.
        names: Vec<String>,
    },
    /// `--episodes` lower than the saved run's.
    #[error(
        "--resume: {} holds a run of {was} episodes per policy, and --episodes {now} would drop \
         some; pass --episodes {was} (or more, to extend it)",
        path.display()
    )]
    Shrinks {
        /// The saved configuration.
        path: PathBuf,
        /// Episodes per policy saved.
        was: usize,
        /// Episodes per policy asked for.
        now: usize,
    },
    /// A saved run ending in a part batch cannot grow bit for bit.
    #[error(
        "--resume --episodes {now}: the saved run's {was} episodes end in a part batch of \
         --batch {batch}, which a straight run of {now} would fill with other seeds (and \
         round differently), so this run cannot be extended bit for bit; start a new one \
         (--force or another --out), or run the extra seeds with --seed-start {next}"
    )]
    PartBatch {
        /// Episodes per policy saved.
        was: usize,
        /// Episodes per policy asked for.
        now: usize,
        /// The batch size.
        batch: usize,
        /// The first seed after the saved run's.
        next: u64,
    },
    /// A shard's share of the batches changes with their number.
    #[error(
        "--resume --episodes {now}: {} is one shard of a run, and a shard's share of the \
         batches changes with their number; extend the merged run instead",
        path.display()
    )]
    ShardGrows {
        /// The saved configuration.
        path: PathBuf,
        /// Episodes per policy asked for.
        now: usize,
    },
    /// A filmstrip index that is not a list of filmstrips.
    #[error("{}: not a filmstrip index ({field}: {source})", path.display())]
    Index {
        /// The file.
        path: PathBuf,
        /// The entry and field where parsing stopped.
        field: String,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// A `results.json` number no run can produce (a hand-edited or damaged file).
    #[error("results.json: {first}{}", if *more > 0 { format!(" (and {more} more)") } else { String::new() })]
    OutOfRange {
        /// The first value out of range, with its path in the file.
        first: String,
        /// How many more there are.
        more: usize,
    },
    /// A kept-frames file that is not one, or frames that cannot be kept.
    #[error("{}: not a kept-frames file ({why})", path.display())]
    Kept {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// Replaying a picked episode's batch for its filmstrip failed.
    #[error("filmstrips: replaying policy {policy}'s batch of seed {seed}: {source}")]
    Replay {
        /// The policy.
        policy: String,
        /// The picked seed.
        seed: u64,
        /// The engine's error.
        source: Box<engine::EngineError>,
    },
    /// A filmstrip's PNG or GIF could not be written.
    #[error("{0}")]
    Media(String),
    /// A run's `results.json` that cannot be read.
    #[error(transparent)]
    Results(#[from] harness::results::ResultsError),
    /// A run's `episodes.jsonl` that cannot be read.
    #[error(transparent)]
    Rows(#[from] harness::rows::RowsError),
    /// A plot that cannot be drawn or written.
    #[error(transparent)]
    Plot(#[from] reports::plots::PlotError),
    /// An output folder that cannot be prepared or committed.
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    /// An episode table that cannot be written.
    #[error(transparent)]
    Table(#[from] reports::episodes::TableError),
    /// The world model failed while imagining a batch: it would fail every policy alike,
    /// so the run stops, naming it.
    #[error(
        "world model {}, imagining policy {policy}'s seeds {seeds:?} (the rows of the batches before this one are kept)",
        model.display()
    )]
    WorldModel {
        /// The world model's folder.
        model: PathBuf,
        /// The policy whose batch it was.
        policy: String,
        /// The batch's seeds.
        seeds: Vec<u64>,
        /// The rollout's error.
        source: Box<world_model::rollout::RolloutError>,
    },
    /// A judge scored an imagined frame with something other than a score: every
    /// policy's imagined rows would be wrong, so the run stops, naming it.
    #[error("{judge} (the rows of the batches before this one are kept)")]
    Judge {
        /// `judge DIR`, or the task's own judge.
        judge: String,
        /// The engine's error.
        source: Box<engine::EngineError>,
    },
    /// The engine stopped a run of batches (its worker threads could not start).
    #[error(transparent)]
    Engine(Box<engine::EngineError>),
    /// A world model that cannot be loaded.
    #[error("loading world model {}", dir.display())]
    LoadWorldModel {
        /// Its folder.
        dir: PathBuf,
        /// The loader's error.
        source: Box<world_model::WorldModelError>,
    },
    /// An inference option a world model cannot take (`--alpha`, `--noise-scale`).
    #[error("{flag}: {error} ({})", dir.display())]
    ModelOption {
        /// The flag.
        flag: &'static str,
        /// The world model's folder.
        dir: PathBuf,
        /// What it cannot take (shown in the message, so not a chained source).
        error: world_model::SettingError,
    },
    /// A judge folder that cannot be loaded.
    #[error("--judge {0}")]
    JudgeFolder(#[source] judges::JudgeError),
    /// A judge that reads other frames or scores another thing than the task.
    #[error("--judge {}: {what}", dir.display())]
    JudgeMismatch {
        /// The judge's folder.
        dir: PathBuf,
        /// What differs.
        what: String,
    },
    /// An input that cannot be fingerprinted.
    #[error(transparent)]
    Fingerprint(#[from] harness::fingerprint::FingerprintError),
    /// Shard folders that are not one complete split of one run.
    #[error("{0}")]
    Shards(String),
}

impl RunError {
    /// A [`RunError::File`] builder for `map_err`: `doing` says what was being done,
    /// naming the path (`creating DIR`, `writing FILE`).
    pub(crate) fn file(doing: String) -> impl FnOnce(std::io::Error) -> Self {
        move |source| Self::File { doing, source }
    }
}

impl From<engine::EngineError> for RunError {
    fn from(e: engine::EngineError) -> Self {
        Self::Engine(Box::new(e))
    }
}
