//! What a batch of planned episodes carries: the context the planners share
//! ([`Ctx`]), each episode's live state ([`Live`]) and the rows a batch returns
//! ([`PlanRow`], [`BatchOut`]). The episode loop is in [`super::episodes`], the
//! imagining of proposals in [`super::imagine`]; both read these types.

use std::collections::VecDeque;
use std::sync::Arc;

use engine::Timing;
use harness::policy::Policy;
use harness::task::Seen;
use mujoco_rs::prelude::MjModel;
use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::plan_cost::GoalDistance;
use scenarios::pusht::{PushTConfig, PushTEnv};
use world_model::model::WorldModel;

/// What the planners share.
pub struct Ctx<'a> {
    pub cfg: &'a PushTConfig,
    pub model: &'a Arc<MjModel>,
    /// Returns chunks of at least `max(imagine, execute)` actions.
    pub policy: &'a dyn Policy,
    pub wm: Option<&'a WorldModel>,
    pub proposals: usize,
    pub imagine: usize,
    pub execute: usize,
    pub spread: f32,
    /// See `--margin`.
    pub margin: f64,
    pub master_seed: u64,
    pub max_steps: usize,
    pub pool: &'a rayon::ThreadPool,
    /// Episode seeds whose decisions are recorded for filmstrips.
    pub record: &'a [u64],
}

/// A finished batch.
pub struct BatchOut {
    pub rows: Vec<PlanRow>,
    pub timing: Timing,
    /// (seed, per decision: real frame, world model's and simulator's outcome of the pick).
    pub records: Vec<(u64, Vec<[Vec<u8>; 3]>)>,
}

/// One planned episode.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanRow {
    pub planner: String,
    pub seed: u64,
    /// max_t clip(coverage / success coverage, 0, 1).
    pub score: f64,
    pub max_coverage: f64,
    pub final_coverage: f64,
    pub success: bool,
    pub steps: usize,
    pub decisions: usize,
    /// Decisions that executed another proposal than the first.
    pub replaced: usize,
    /// World-model planner: decisions where the simulator would have picked the same proposal.
    pub agreed: Option<usize>,
    /// World-model planner: Σ over decisions of (the simulator's cost of the world
    /// model's pick − the lowest simulator cost), world units.
    pub regret: Option<f64>,
    /// World-model planner: the same sum for a pick uniformly at random (the mean over
    /// the proposals the simulator could score), the chance level of `regret`.
    pub regret_random: Option<f64>,
}

/// A `plan` row's (planner, seed, kind) for `whole_batches`: one row per seed.
pub fn plan_key(r: &PlanRow) -> (&str, u64, ()) {
    (r.planner.as_str(), r.seed, ())
}

/// One episode's live state.
pub(super) struct Live {
    pub(super) env: PushTEnv,
    /// Frames and agent positions the policy sees (with the goal), oldest first.
    pub(super) seen: VecDeque<Seen>,
    /// The world model's history frames (without the goal for a goal-free model).
    pub(super) wm_hist: VecDeque<Vec<u8>>,
    /// The first frame as the world model sees it (its anchor).
    pub(super) wm_first: Vec<u8>,
    /// Draws the goal onto a goal-free model's imagined frames.
    pub(super) scorer: FrameScorer,
    pub(super) cost: GoalDistance,
    pub(super) row: PlanRow,
    /// Per decision: the real frame, the world model's and the simulator's last frame of
    /// the picked proposal (empty where that planner did not imagine); only for recorded episodes.
    pub(super) record: Option<Vec<[Vec<u8>; 3]>>,
}
