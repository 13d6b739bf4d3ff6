//! `rank`'s arguments: a clap `Args` struct the binary flattens into its command line, and
//! the typed file a shard process of `--processes` reads its settings from (serde, so a
//! field added here reaches the shards without being named anywhere else).

use std::path::PathBuf;

use clap::Args;
use runner::bounds::{self, bootstrap_replicates, correlation};

/// `evalharness rank`.
#[derive(Debug, Clone, PartialEq, Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RankArgs {
    /// A policy checkpoint, or a folder of them [default: checkpoints/<task>/policies].
    #[arg(long)]
    pub policies: Option<PathBuf>,
    /// The world model (from `train world-model`) [default: checkpoints/<task>/world_model].
    #[arg(long)]
    pub world_model: Option<PathBuf>,
    /// A learned judge (from `train judge`) that scores the imagined frames in place
    /// of the task's own judge (whose scene checks are kept); its error on the
    /// simulator branch's real frames is reported as for any judge [default, for a task
    /// without a judge of its own (Lift, Can): checkpoints/<task>/judge].
    #[arg(long)]
    pub judge: Option<PathBuf>,
    /// The learned judge's persistence rule: success counts only once k judged frames
    /// in a row show it (the frames the policy sees, the last 2 of every chunk)
    /// [default: the judge's `persist_frames`].
    #[arg(long, value_name = "K")]
    pub judge_persist: Option<usize>,
    /// Judge every imagined frame, as the official DriftWorld evaluation does, not only the
    /// frames the policy sees (the last 2 of every chunk): every generated frame is decoded
    /// and scored, and the episode's score is the best of them.
    #[arg(long)]
    pub judge_every_frame: bool,
    /// Hand policies the world model's frames unrounded (values in [0, 1] before the bytes),
    /// as the official DriftWorld loop feeds them: imported policies read them; evalharness's
    /// own read the bytes either way. Needs a world model of whole frames (not goal-free).
    #[arg(long)]
    pub float_frames: bool,
    /// Action-accentuation strength α, for a world model trained with
    /// `--accentuation` (default: its configured α).
    #[arg(long)]
    pub alpha: Option<f32>,
    /// The scale of the world model's sampling noise, in [0, 1] (a one-pass model's
    /// temperature; 0: one fixed chunk per history and actions) [default: the model's
    /// `noise_scale`, else 1].
    #[arg(long, value_name = "T")]
    pub noise_scale: Option<f32>,
    /// Scenario name or .toml file.
    #[arg(long, default_value = "pusht")]
    pub scenario: String,
    /// Episodes per policy [default: checkpoints/<task>/rank.toml's, else 100].
    #[arg(long)]
    pub episodes: Option<usize>,
    /// First episode seed (training data uses seeds from 0).
    #[arg(long, default_value_t = 100_000)]
    pub seed_start: u64,
    /// Control steps per episode [default: checkpoints/<task>/rank.toml's, else the
    /// task's (Push-T 300, robomimic 400)].
    #[arg(long)]
    pub max_steps: Option<usize>,
    /// Episodes advanced together (one batched policy / world-model call). 50 splits
    /// the default run into 14 batches, so the workers finish together (with 100, one
    /// idled during the last world-model batch). Part of the run's settings: float
    /// rounding depends on it, so `--resume` must use the same value.
    #[arg(long, default_value_t = 50, value_parser = bounds::batch())]
    pub batch: usize,
    /// Output folder.
    #[arg(long, default_value = "results/rank")]
    pub out: PathBuf,
    /// Worker threads. Each takes the next task from one queue of every batch's two
    /// branches (world model, MuJoCo) and runs it with burn's kernels single-threaded,
    /// so results are identical (bit for bit) for any value; also the threads that
    /// replay the report's episodes.
    #[arg(long, default_value_t = 2, value_parser = bounds::workers())]
    pub jobs: usize,
    /// Master seed of the policies' sampling noise and of the bootstrap.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Bootstrap replicates for the CIs (1 to 1,000,000).
    #[arg(long, default_value_t = 2000, value_parser = bootstrap_replicates)]
    pub bootstrap: usize,
    /// Continue a run in `--out`, skipping finished episodes; with a larger
    /// `--episodes`, extend a finished run (only the new seeds run; the files equal a
    /// straight run's when the saved count is a whole number of batches).
    #[arg(long)]
    pub resume: bool,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
    /// Run only part i of n (0-based; whole batches), e.g. `--shard 0/4`.
    #[arg(long)]
    pub shard: Option<String>,
    /// With `--shard i/n`: run each batch this process claims first in DIR (a file per
    /// batch, naming its shard) instead of every n-th one, so shards that run at once
    /// share the batches out as they go. A shard resumed or restarted takes its own
    /// claims back. `--processes` gives its shards one folder (the claims are created with
    /// `O_EXCL`).
    #[arg(long, value_name = "DIR", requires = "shard")]
    pub claims: Option<PathBuf>,
    /// Split the run into this many `--shard i/N --jobs 1` processes running at once, join
    /// them with `merge` and finish as one run (report, table, gates). Byte-identical rows
    /// to one process. Faster on Lift and Can, whose GL renderer lets one thread of a
    /// process render at a time; `--jobs` then only sets the report's replay threads
    /// [default: the task's `rank.toml`, else 1; a `--shard` is one process].
    #[arg(long, value_name = "N", value_parser = bounds::count(1, bounds::MAX_PROCESSES))]
    pub processes: Option<usize>,
    /// Exit 1 if the Pearson correlation is below this (a number in [-1, 1]).
    #[arg(long, value_parser = correlation, allow_negative_numbers = true)]
    pub min_pearson: Option<f64>,
    /// Exit 1 if there are more rank inversions than this.
    #[arg(long)]
    pub max_inversions: Option<u64>,
    /// Skip the report (plots, filmstrips, table.tex, report.html); `evalharness report OUT` makes it later.
    #[arg(long)]
    pub no_report: bool,
}
