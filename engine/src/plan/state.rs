//! What a batch of planned episodes carries: the context the planners share
//! ([`PlanCtx`]), each episode's live state ([`Live`]) and the rows a batch returns
//! ([`PlanRow`], [`PlanOut`]). The episode loop is in [`super::episodes`], the
//! imagining of proposals in [`super::imagine`]; both read these types.

use std::collections::VecDeque;

use harness::policy::Policy;
use harness::task::{Env, Imagination, PlanCost, Seen, Task};
use world_model::model::WorldModel;

use crate::start::Timing;

/// Which planner picks the executed proposal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Planner {
    /// The policy alone: proposal 0, nothing imagined.
    None,
    /// GPC-RANK: each proposal imagined in the world model.
    WorldModel,
    /// The same ranking with perfect imagination: each proposal tried on a copy of the simulator.
    Simulator,
}

impl Planner {
    /// The planner's name in rows, file names and `--planners`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::WorldModel => "world-model",
            Self::Simulator => "simulator",
        }
    }
}

/// What the planners share.
pub struct PlanCtx<'a> {
    /// The task; its episodes must have a [`PlanCost`] and copy themselves ([`Env::fork`]).
    pub task: &'a dyn Task,
    /// Returns chunks of at least `max(imagine, execute)` actions.
    pub policy: &'a dyn Policy,
    /// The world model (the world-model planner only).
    pub wm: Option<&'a WorldModel>,
    /// Proposals per decision.
    pub proposals: usize,
    /// Actions imagined per proposal.
    pub imagine: usize,
    /// Actions of the pick executed per decision.
    pub execute: usize,
    /// Factor by which the proposals are spread about their mean.
    pub spread: f32,
    /// See `plan --margin`.
    pub margin: f64,
    /// Master seed of the policy and world-model noise.
    pub master_seed: u64,
    /// Control steps per episode.
    pub max_steps: usize,
    /// Workers for the simulator's steps.
    pub pool: &'a rayon::ThreadPool,
    /// Episode seeds whose decisions are recorded for filmstrips.
    pub record: &'a [u64],
    /// A judge of frames whose score ranks the proposals (`plan --judge`; GPC-RANK ranks
    /// by its reward predictors), in place of the task's own planning cost.
    pub judge: Option<std::sync::Arc<dyn harness::judge::Judge>>,
}

/// A finished batch.
pub struct PlanOut {
    /// One row per episode seed.
    pub rows: Vec<PlanRow>,
    /// Its wall-clock split.
    pub timing: Timing,
    /// (seed, per decision: real frame, world model's and simulator's outcome of the pick).
    pub records: Vec<(u64, Vec<[Vec<u8>; 3]>)>,
}

/// One planned episode. The coverage fields hold the task's raw score (Push-T's
/// coverage of the goal T), under the names `plan` has always written.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanRow {
    /// The planner's name.
    pub planner: String,
    /// Episode seed.
    pub seed: u64,
    /// The best reward over the episode (Push-T: max_t clip(coverage / success coverage, 0, 1)).
    pub score: f64,
    /// The highest raw score.
    pub max_coverage: f64,
    /// The raw score at the end.
    pub final_coverage: f64,
    /// Whether the raw score passed the task's success threshold.
    pub success: bool,
    /// Control steps executed.
    pub steps: usize,
    /// Decisions taken.
    pub decisions: usize,
    /// Decisions that executed another proposal than the first.
    pub replaced: usize,
    /// World-model planner: decisions where the simulator would have picked the same proposal.
    pub agreed: Option<usize>,
    /// World-model planner: Σ over decisions of (the simulator's cost of the world
    /// model's pick − the lowest simulator cost), in the cost's units.
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
    pub(super) env: Box<dyn Env>,
    /// Frames and proprioception the policy sees, oldest first.
    pub(super) seen: VecDeque<Seen>,
    /// The world model's history frames (in its view).
    pub(super) wm_hist: VecDeque<Vec<u8>>,
    /// The first frame as the world model sees it (its anchor).
    pub(super) wm_first: Vec<u8>,
    /// Turns the world model's frames into the policy's view (draws back the goal).
    pub(super) imagination: Box<dyn Imagination>,
    pub(super) cost: Box<dyn PlanCost>,
    pub(super) row: PlanRow,
    /// Per decision: the real frame, the world model's and the simulator's last frame of
    /// the picked proposal (empty where that planner did not imagine); only for recorded episodes.
    pub(super) record: Option<Vec<[Vec<u8>; 3]>>,
}
