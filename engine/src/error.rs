//! Why a batch of paired episodes stopped, naming the policy, seed or steps at fault.

use harness::policy::PolicyError;
use harness::task::TaskError;
use world_model::rollout::RolloutError;

/// What can stop a branch or a run of batches.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The policy could not act (non-finite output, unusable observations).
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// The task's simulator failed (a diverging step, an impossible reset).
    #[error(transparent)]
    Task(#[from] TaskError),
    /// A policy returned no actions for some episode.
    #[error("policy {policy} returned an empty action chunk or too few chunks")]
    EmptyChunk {
        /// The policy.
        policy: String,
    },
    /// The world model generated NaN or infinite latents, or cannot read the task's actions.
    #[error("policy {policy}, episode steps {first}..{end}")]
    WorldModel {
        /// The policy whose episodes were being imagined.
        policy: String,
        /// First control step of the chunk.
        first: usize,
        /// One past its last step.
        end: usize,
        /// What went wrong (which generated frames diverged).
        source: RolloutError,
    },
    /// A task without a judge of imagined frames, and none given.
    #[error(
        "task {task} has no hand-written judge of imagined frames: give a learned one (`train judge`, then `rank --judge DIR`)"
    )]
    NoJudge {
        /// The task.
        task: String,
    },
    /// A judge scored a frame with something other than a number in [0, 1] (non-finite
    /// weights, say): every episode would otherwise read as a success or a failure.
    #[error(
        "the judge scored a frame of policy {policy}'s episode {seed} as {value}, not a number in [0, 1]"
    )]
    Judge {
        /// The policy whose episode was being judged.
        policy: String,
        /// The episode seed.
        seed: u64,
        /// The score.
        value: f64,
    },
    /// A policy returned chunks shorter than a plan imagines or executes.
    #[error("policy {policy} returned fewer than {need} actions per proposal")]
    ShortChunk {
        /// The policy.
        policy: String,
        /// Actions needed per proposal.
        need: usize,
    },
    /// A task whose episodes have no planning cost or cannot be copied.
    #[error(
        "task {task} cannot be planned in: its episodes have no planning cost or cannot copy their simulator state"
    )]
    CannotPlan {
        /// The task.
        task: String,
    },
    /// The simulator diverged while trying a proposal on a copy of an episode.
    #[error("imagining a proposal of episode {seed}")]
    Imagining {
        /// The episode seed.
        seed: u64,
        /// The simulator's error.
        source: TaskError,
    },
    /// The world model generated non-finite latents for a plan's proposals.
    #[error("imagining proposals of policy {policy} at decision {decision}")]
    PlanWorldModel {
        /// The proposing policy.
        policy: String,
        /// The decision's index in its episodes.
        decision: u64,
        /// Which generated frames diverged.
        source: RolloutError,
    },
    /// A batch of a policy that had already failed.
    #[error("policy {policy}: skipped after an earlier failure")]
    Skipped {
        /// The policy.
        policy: String,
    },
    /// Worker threads could not start.
    #[error("starting worker threads: {0}")]
    Threads(String),
    /// A worker thread panicked.
    #[error("a rank worker panicked")]
    WorkerPanicked,
}

/// `score`, refused with [`EngineError::Judge`] when it is not a number in [0, 1].
///
/// # Errors
/// [`EngineError::Judge`] naming the policy and the seed.
pub(crate) fn judged(score: f64, policy: &str, seed: u64) -> Result<f64, EngineError> {
    if (0.0..=1.0).contains(&score) {
        Ok(score)
    } else {
        Err(EngineError::Judge { policy: policy.to_string(), seed, value: score })
    }
}
