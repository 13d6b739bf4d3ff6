//! `evalharness plan` arguments: GPC-RANK planning with a policy's proposals.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

/// How a decision picks the action chunk to execute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Planner {
    /// No planning: the policy's first proposal, as `rank` runs it.
    None,
    /// GPC-RANK: imagine every proposal in the world model, execute the best.
    WorldModel,
    /// The same ranking with MuJoCo imagining each proposal from the true state (the
    /// upper bound a perfect world model would reach with this cost).
    Simulator,
}

impl From<Planner> for engine::plan::Planner {
    fn from(p: Planner) -> Self {
        match p {
            Planner::None => Self::None,
            Planner::WorldModel => Self::WorldModel,
            Planner::Simulator => Self::Simulator,
        }
    }
}

/// `evalharness plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// The policy checkpoint that proposes action chunks (a diffusion policy, evalharness's or
    /// one imported with `import policy`: its sampling noise makes the proposals differ).
    #[arg(long, default_value = "checkpoints/pusht/policies/ft-epoch-0012")]
    pub policy: PathBuf,
    /// The world model that imagines the proposals (from `train world-model`).
    #[arg(long, default_value = "checkpoints/pusht/world_model")]
    pub world_model: PathBuf,
    /// Action-accentuation strength α, for a world model trained with
    /// `--accentuation` (default: its configured α).
    #[arg(long)]
    pub alpha: Option<f32>,
    /// Planners to run on the same seeds, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "none,world-model,simulator")]
    pub planners: Vec<Planner>,
    /// Proposals sampled per decision (GPC-RANK: 50; each costs one imagined rollout).
    #[arg(long, default_value_t = 8, value_parser = crate::cli::bounds::count(1, 4096))]
    pub proposals: usize,
    /// Actions of each proposal imagined before it is scored (default: all the
    /// policy predicts from the current step on, 15 for horizon 16 and 2 observations).
    #[arg(long)]
    pub imagine: Option<usize>,
    /// Actions of the chosen proposal executed before the next decision (default: the
    /// policy's own action horizon, so the `none` planner is the policy as `rank` runs it).
    #[arg(long)]
    pub execute: Option<usize>,
    /// Keep the policy's own (first) proposal unless the planner predicts another one ends
    /// at least this much closer to the goal (world units of the cost; 0 = GPC-RANK's
    /// plain argmin). A guard against picks that only an imagination error makes look good.
    #[arg(long, default_value_t = 0.0)]
    pub margin: f64,
    /// Spread of the proposals about their mean, `a ← mean + s·(a − mean)` (GPC-RANK: 1.01).
    #[arg(long, default_value_t = 1.01)]
    pub spread: f32,
    /// Scenario name or .toml file.
    #[arg(long, default_value = "pusht")]
    pub scenario: String,
    /// Episodes per planner.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// First episode seed (GPC-RANK's test seeds start at 100050).
    #[arg(long, default_value_t = 100_050)]
    pub seed_start: u64,
    /// Control steps per episode (an episode also ends at the chunk that succeeds).
    #[arg(long, default_value_t = 300)]
    pub max_steps: usize,
    /// Episodes advanced together (their proposals form one batched policy and
    /// world-model call). Part of the run's settings: float rounding depends on it.
    #[arg(long, default_value_t = 10, value_parser = crate::cli::bounds::count(1, 1000))]
    pub batch: usize,
    /// Master seed of the proposals' sampling noise, the world model's noise and the bootstrap.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Bootstrap replicates for the CIs.
    #[arg(long, default_value_t = 2000, value_parser = crate::cli::bootstrap_replicates)]
    pub bootstrap: usize,
    /// Threads for the simulator's rollouts (results do not depend on it).
    #[arg(long, default_value_t = 2, value_parser = crate::cli::bounds::workers())]
    pub jobs: usize,
    /// Episodes (the first seeds) whose decisions are drawn as filmstrips: the real frame,
    /// and what the world model and the simulator imagined of the picked proposal's outcome.
    #[arg(long, default_value_t = 2)]
    pub record: usize,
    /// A judge of frames (from `train judge` or `import judge`) whose score ranks the
    /// proposals, `cost = 1 − score` of the last imagined frame, as GPC-RANK ranks them by its
    /// reward predictors [default: the task's planning cost, Push-T's mean distance of the
    /// block's pixels from the goal]. `--margin` is then in units of that score.
    #[arg(long)]
    pub judge: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "results/plan")]
    pub out: PathBuf,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
    /// Continue a run in `--out` under the same settings, skipping finished batches; with a
    /// larger `--episodes`, extend a finished run (as `rank --resume`).
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
}
