//! **Reach**: the smallest task, a marker on a line sent to a goal. It exists to show
//! that a task is its folder and one line of the task table (`crate::TASKS`): the
//! integration tests run it through `simulate`, `collect`, `train`, `rank` and `report`,
//! so a command that assumes Push-T's poses, coverage or frames fails there.
//!
//! - State: the marker's position x on a line from 0 to 10; the episode of seed s starts at
//!   a uniform draw from its seed.
//! - Actions: a 1-D absolute target; each control step the marker moves `gain` of the way
//!   to it.
//! - Score: success (1) while the marker is within `tolerance` of the goal, else 0
//!   ([`ScoreKind::Success`]); episodes end at the first success unless asked otherwise.
//! - Frames: `size`² RGB, dark grey, the goal a green band and the marker a white band
//!   ([`render`]); the task's own judge reads the marker's band back ([`ReachJudge`]).
//! - Imagination: the world model starts from the first frame; the policy's
//!   proprioception is the position its own commands move the marker to (the dynamics
//!   are exact, so dead reckoning is the truth).

mod datasets;
mod task;

use std::path::Path;

use serde::{Deserialize, Serialize};

pub use task::{ReachEnv, ReachJudge, ReachTask, render};

use crate::error::ScenarioError;

/// The shipped scene, as a scenario file.
const DEFAULT_TOML: &str = include_str!("../reach.toml");

/// Reach's parameters (`scenarios/reach.toml`; a scenario file may override any).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReachConfig {
    /// Always `reach`.
    pub name: String,
    /// The goal's position on the line, in [0, 10].
    pub goal: f64,
    /// Distance from the goal within which the episode succeeds.
    pub tolerance: f64,
    /// Fraction of the way to the commanded target the marker moves each step, in (0, 1].
    pub gain: f64,
    /// Control steps per episode unless asked otherwise.
    pub max_steps: usize,
    /// Side of the frames in pixels (the autoencoder and the policies read 96).
    pub image_size: usize,
}

impl ReachConfig {
    /// Parses and checks a Reach scenario; `origin` names the file in errors.
    ///
    /// # Errors
    /// Malformed TOML, an unknown key, another task's name, or a value out of range,
    /// naming the field.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Self, ScenarioError> {
        let cfg: Self = toml::from_str(text)
            .map_err(|e| ScenarioError::Parse { path: origin.to_path_buf(), message: e.to_string() })?;
        let bad = |field: &str, reason: &str| ScenarioError::InvalidField {
            path: origin.to_path_buf(),
            field: field.into(),
            reason: reason.into(),
        };
        if cfg.name != "reach" {
            return Err(bad("name", "a Reach scenario is named \"reach\""));
        }
        if !(0.0..=10.0).contains(&cfg.goal) {
            return Err(bad("goal", "must be in [0, 10]"));
        }
        if !(cfg.tolerance > 0.0 && cfg.tolerance < 10.0) {
            return Err(bad("tolerance", "must be in (0, 10)"));
        }
        if !(cfg.gain > 0.0 && cfg.gain <= 1.0) {
            return Err(bad("gain", "must be in (0, 1]"));
        }
        if !(1..=100_000).contains(&cfg.max_steps) {
            return Err(bad("max_steps", "must be in [1, 100000]"));
        }
        if !(8..=1024).contains(&cfg.image_size) {
            return Err(bad("image_size", "must be in [8, 1024]"));
        }
        Ok(cfg)
    }
}

impl Default for ReachConfig {
    fn default() -> Self {
        // The shipped file is parsed by a unit test, so this cannot fail at run time.
        Self::from_toml_str(DEFAULT_TOML, Path::new("scenarios/reach.toml"))
            .unwrap_or_else(|e| unreachable!("shipped reach.toml is invalid: {e}"))
    }
}

/// Reach for the task table (`crate::load_task`): the shipped scene, or a scenario file's.
pub(crate) fn registered(file: Option<&Path>) -> Result<Box<dyn harness::task::Task>, ScenarioError> {
    let cfg = match file {
        None => ReachConfig::default(),
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|source| ScenarioError::Io { path: path.to_path_buf(), source })?;
            ReachConfig::from_toml_str(&text, path)?
        }
    };
    Ok(Box::new(ReachTask::new(cfg)))
}

#[cfg(test)]
mod tests;
