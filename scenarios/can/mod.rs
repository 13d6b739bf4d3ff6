//! robomimic's **Can** (robosuite `PickPlaceCan`, 1.5.2 defaults): a Panda on a
//! Rethink mount picks a Coke can out of one bin and places it in its quadrant
//! of the other. Actions are robomimic's 7-D OSC_POSE deltas plus the gripper;
//! an episode succeeds when the can rests in its quadrant with the gripper away.

pub mod config;
pub mod expert;
pub mod rollout;
pub mod sim;

pub use config::CanConfig;
pub use rollout::{CanBehaviour, CanEpisodeRecord};
pub use sim::{CanEpisode, CanInit, CanSim, STATE_COLUMNS};

#[cfg(test)]
mod tests;
