//! Resolving `--scenario` (a name or a .toml path) into a task or a Push-T config.

use anyhow::{Context, Result};
use harness::task::Task;
use scenarios::pusht::PushTConfig;

/// Loads the Push-T config named by `--scenario` (for the Push-T-only commands):
/// `pusht` gives the shipped parameters, a path loads that file (which must describe Push-T).
pub fn load_pusht(spec: &str) -> Result<PushTConfig> {
    scenarios::pusht_config(spec).with_context(|| format!("loading scenario {spec}"))
}

/// Loads the task named by `--scenario`.
pub fn load_task(spec: &str) -> Result<Box<dyn Task>> {
    scenarios::load_task(spec).with_context(|| format!("loading scenario {spec}"))
}
