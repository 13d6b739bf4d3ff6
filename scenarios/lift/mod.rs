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
pub use rollout::LiftBehaviour;
pub use sim::{Lift, LiftEpisode, LiftEpisodeRecord, LiftInit, LiftSim, STATE_COLUMNS};

/// Lift for the task table (`crate::load_task`): the shipped parameters, or a scenario file's.
pub(crate) fn registered(
    file: Option<&std::path::Path>,
) -> Result<Box<dyn harness::task::Task>, crate::ScenarioError> {
    let cfg = file.map_or_else(|| Ok(LiftConfig::default()), LiftConfig::from_file)?;
    Ok(crate::arm_task(LiftSim::new(cfg)?))
}

/// The model a render worker builds for a Lift episode's recipe.
pub(crate) fn render_model(
    key: &crate::robosuite::render_pool::ModelKey,
) -> Result<mujoco_rs::prelude::MjModel, crate::ScenarioError> {
    let cfg: LiftConfig = serde_json::from_str(&key.config)
        .map_err(|e| crate::ScenarioError::Render { message: format!("lift config: {e}") })?;
    let half = key.object_half.ok_or_else(|| crate::ScenarioError::Render {
        message: "a lift model needs the cube's half-sizes".into(),
    })?;
    sim::lift_model(&cfg, &key.assets, half)
}

#[cfg(test)]
mod tests;
