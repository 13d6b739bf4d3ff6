//! What robosuite's manipulation scenes share: the one simulator of every such task
//! ([`arm_sim`]: a task is an [`arm_sim::ArmScene`]), the asset folder, the scene composer
//! (Panda, mount, gripper, arenas), the OSC_POSE arm controller, the scripted-episode runner,
//! the exploration drift ([`wander`]), and the engine's [`Task`](harness::task::Task)
//! implementation ([`task`]).
//!
//! Lift and Can (`crate::lift`, `crate::can`) build on it. Everything follows
//! robosuite 1.5.2 at its default settings, so that a robomimic user recognises
//! the scenes, actions and success checks.

pub mod arm_sim;
pub mod assets;
pub mod datasets;
pub mod episode;
pub mod linalg;
pub mod osc;
pub mod render_pool;
pub mod renderer;
pub mod robot_state;
pub mod rollout;
pub mod runs;
pub mod scene;
pub mod task;
pub mod visual;
pub mod wander;

#[cfg(test)]
mod tests;

use std::path::Path;

use crate::error::ScenarioError;

/// Reads a robosuite scenario TOML that names itself `name = "<name>"` and
/// overrides any fields of `T` (the task's config, `deny_unknown_fields`).
///
/// # Errors
/// The file is unreadable, malformed, names another scenario, or has an unknown key.
pub fn read_named_toml<T: serde::de::DeserializeOwned>(path: &Path, name: &str) -> Result<T, ScenarioError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ScenarioError::Io { path: path.into(), source })?;
    let parse = |e: toml::de::Error| ScenarioError::Parse { path: path.into(), message: e.to_string() };
    let mut table: toml::Table = toml::from_str(&text).map_err(parse)?;
    match table.remove("name") {
        Some(toml::Value::String(n)) if n == name => {}
        other => {
            return Err(ScenarioError::InvalidField {
                path: path.into(),
                field: "name".into(),
                reason: format!("a {name} scenario file says name = \"{name}\", not {other:?}"),
            });
        }
    }
    table.try_into().map_err(parse)
}
