//! The paired rollout engine: a policy's episodes run twice from the same initial
//! states, once in the task's reference simulator and once in the world model.
//!
//! It is generic over the task ([`harness::task::Task`]): Push-T, Lift and Can run
//! through the same code, with the task's judge scoring the imagined frames.
//!
//! - [`start`]: what a batch starts from ([`Start`]: the episodes reset to their
//!   seeds, their judges and first observations, the per-episode noise streams) and
//!   what a branch returns;
//! - [`sim`]: the simulator branch (real frames, exact scores);
//! - [`imagined`]: the world-model branch (imagined frames, judged scores);
//! - [`replay`]: one episode's recorded actions stepped in the simulator;
//! - [`schedule`]: all policies' batches on worker threads, load-balanced, handed
//!   on in batch order, with the same rows for any worker count;
//! - [`plan`]: GPC-RANK, a policy's proposals imagined and the best executed, in
//!   lockstep batches of its own (`evalharness plan`).
//!
//! Both branches draw the policy's sampling noise from clones of the same
//! per-episode stream, so they are matched pairs. All episodes of a batch advance
//! in lockstep (one batched policy call, one batched world-model call). An episode
//! leaves the batch at the end of the action chunk in which it succeeded (as
//! gym-pusht terminates at success), in each branch by that branch's score.

mod decide;
mod error;
pub mod imagined;
pub mod plan;
pub mod replay;
pub mod schedule;
pub mod sim;
pub mod start;
#[cfg(test)]
mod tests;

pub use error::EngineError;
pub use imagined::wm_branch;
pub use replay::{Replay, replay_in_sim};
pub use sim::sim_branch;
pub use start::{BranchOut, Observe, Setup, Start, Timing, Trajectory, obs_of, push};
