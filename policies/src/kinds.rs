//! Loading a checkpoint of any policy kind.
//!
//! The learned kinds live in `policies` (burn) and the `scripted` kind belongs to
//! the task (its expert plans with the task's simulator); the crates do not know
//! each other, so the binary, which sees both, dispatches on `policy.json`'s `kind`.

use std::path::Path;

use burn::tensor::Device;
use harness::policy::Policy;
use harness::task::Task;
use policies::dir::{Expectations, PolicyLoadError, load_policy};

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
    if policies::dir::policy_kind(dir).as_deref() == Some("scripted") {
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
