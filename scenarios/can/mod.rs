//! robomimic's **Can** (robosuite `PickPlaceCan`, 1.5.2 defaults): a Panda on a
//! Rethink mount picks a Coke can out of one bin and places it in its quadrant
//! of the other. Actions are robomimic's 7-D OSC_POSE deltas plus the gripper;
//! an episode succeeds when the can rests in its quadrant with the gripper away.

pub mod config;
pub mod expert;
pub mod rollout;
pub mod sim;

pub use config::CanConfig;
pub use rollout::CanBehaviour;
pub use sim::{Can, CanEpisode, CanEpisodeRecord, CanInit, CanSim, STATE_COLUMNS};

/// Can for the task table (`crate::load_task`): the shipped parameters, or a scenario file's.
pub(crate) fn registered(
    file: Option<&std::path::Path>,
) -> Result<Box<dyn harness::task::Task>, crate::ScenarioError> {
    let cfg = file.map_or_else(|| Ok(CanConfig::default()), CanConfig::from_file)?;
    Ok(crate::arm_task(CanSim::new(cfg)?))
}

/// The model a render worker builds for a Can episode's recipe.
pub(crate) fn render_model(
    key: &crate::robosuite::render_pool::ModelKey,
) -> Result<mujoco_rs::prelude::MjModel, crate::ScenarioError> {
    let cfg: CanConfig = serde_json::from_str(&key.config)
        .map_err(|e| crate::ScenarioError::Render { message: format!("can config: {e}") })?;
    if key.object_half.is_some() {
        return Err(crate::ScenarioError::Render {
            message: "a can model takes no object half-sizes".into(),
        });
    }
    sim::can_model(&cfg, &key.assets)
}

#[cfg(test)]
mod tests;
