//! Loading a checkpoint of any policy kind.
//!
//! The learned kinds live here (burn) and the `scripted` kind belongs to the task (its
//! expert plans with the task's simulator, `Task::scripted_policy`); this crate does not
//! know the tasks, so it dispatches on `policy.json`'s `kind` and hands a `scripted` folder
//! to the task it is given.

use std::path::Path;

use crate::dir::{Expectations, PolicyLoadError, load_policy};
use burn::tensor::Device;
use harness::policy::Policy;
use harness::task::Task;

/// Loads the checkpoint folder `dir` for `task`.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder (see [`load_policy`]; for `scripted`, an
/// unreadable `policy.json`, a bad config, or a task without scripted policies).
pub fn load_any(
    dir: &Path,
    expect: &Expectations,
    device: &Device,
    task: &dyn Task,
) -> Result<Box<dyn Policy>, PolicyLoadError> {
    if crate::dir::policy_kind(dir).as_deref() == Some("scripted") {
        return task.scripted_policy(dir).map_err(|e| PolicyLoadError::new(dir, e.to_string()));
    }
    load_policy(dir, expect, device)
}

/// What a learned checkpoint must match to run on `task`: its frame size, its
/// proprioception and its actions' width and bounds.
pub fn expectations(task: &dyn Task) -> Expectations {
    let (obs, act) = (task.observation_spec(), task.action_spec());
    Expectations {
        image_size: obs.image_size,
        proprio_dim: obs.proprio.len(),
        action_low: act.low,
        action_high: act.high,
        task: Some(task.name().to_string()),
        robot: obs.robot,
    }
}
