//! Arguments of `evalharness read-judge`: reading recorded episodes with a learned
//! judge as `rank` reads imagined ones, to choose its persistence rule on data.

use std::path::PathBuf;

use clap::Args;

/// `evalharness read-judge`.
#[derive(Debug, Args)]
pub struct ReadJudgeArgs {
    /// A judge folder (from `train judge`, or an earlier `read-judge --out`).
    #[arg(long, required_unless_present = "rule", conflicts_with = "rule")]
    pub judge: Option<PathBuf>,
    /// A hand-written rule instead of a judge folder; `--out` writes its folder.
    #[arg(long, value_enum)]
    pub rule: Option<JudgeRule>,
    /// Dataset of simulator frames with the judge's label array (zarr replay buffer),
    /// e.g. from `collect --no-early-stop`, so that success lasts as it does in an
    /// imagined rollout.
    #[arg(long)]
    pub data: PathBuf,
    /// Persistence values to read with: judged frames in a row that must show success.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,6,8")]
    pub persist: Vec<usize>,
    /// Actions executed per policy decision; `rank` judges the first frame and the
    /// last `--seen` of every chunk.
    #[arg(long, default_value_t = judges::metrics::RANK_CHUNK)]
    pub chunk: usize,
    /// Frames the policy sees at the end of each chunk (its observation horizon).
    #[arg(long, default_value_t = judges::metrics::RANK_SEEN)]
    pub seen: usize,
    /// Read at most this many episodes (the first ones).
    #[arg(long)]
    pub episodes: Option<usize>,
    /// Write a copy of the judge here whose `persist_frames` is the value that reads
    /// most episodes right (the smallest on a tie), with this reading in its provenance.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace an existing `--out` once the new judge is complete.
    #[arg(long)]
    pub force: bool,
    /// Print JSON instead of a Markdown table.
    #[arg(long)]
    pub json: bool,
}

/// Hand-written judges of frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum JudgeRule {
    /// Lift: the red cube's median row at or above row 40 of the 96 × 96 agentview
    /// (`judges::rule::ColourHeight::lift_red`).
    LiftRed,
}
