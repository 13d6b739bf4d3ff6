//! robomimic's **Lift** (robosuite `Lift`, 1.5.2 defaults): a Panda on a Rethink
//! mount picks a small red cube off a table. Actions are robomimic's 7-D OSC_POSE
//! deltas plus the gripper; an episode succeeds when the cube's centre rises more
//! than 0.04 m above the table top.

pub mod config;
pub mod expert;
pub mod rollout;
pub mod sim;

pub use config::LiftConfig;
pub use expert::{LiftExpert, LiftFlaws};
pub use rollout::{LiftBehaviour, LiftEpisodeRecord};
pub use sim::{LiftEpisode, LiftInit, LiftSim, STATE_COLUMNS};

#[cfg(test)]
mod tests;
