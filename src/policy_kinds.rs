//! Loading a checkpoint of any policy kind.
//!
//! The learned kinds live in `policies` (burn) and the `scripted` kind in
//! `scenarios` (it plans with MuJoCo); the crates do not know each other, so the
//! binary, which sees both, dispatches on `policy.json`'s `kind`.

use std::path::Path;
use std::sync::Arc;

use burn::tensor::Device;
use harness::policy::Policy;
use mujoco_rs::prelude::MjModel;
use policies::dir::{Expectations, PolicyLoadError, load_policy};
use scenarios::pusht::PushTConfig;
use scenarios::pusht::scripted::ScriptedPolicy;

/// Loads the checkpoint folder `dir` for the Push-T scene `cfg` (compiled `model`).
///
/// # Errors
/// [`PolicyLoadError`] naming the folder (see [`load_policy`]; for `scripted`, an
/// unreadable `policy.json` or a bad config).
pub fn load_any(
    dir: &Path,
    expect: Expectations,
    device: &Device,
    cfg: &PushTConfig,
    model: &Arc<MjModel>,
) -> Result<Box<dyn Policy>, PolicyLoadError> {
    let json = dir.join("policy.json");
    let kind = std::fs::read_to_string(&json)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["kind"].as_str().map(str::to_owned));
    if kind.as_deref() == Some("scripted") {
        let policy = ScriptedPolicy::load(dir, cfg, model.clone(), expect.image_size)
            .map_err(|m| PolicyLoadError::new(dir, m))?;
        return Ok(Box::new(policy));
    }
    load_policy(dir, expect, device)
}
