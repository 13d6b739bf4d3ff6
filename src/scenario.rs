//! Resolving `--scenario` (a name or a .toml path) into a task.

use anyhow::{Context, Result};
use harness::task::Task;

/// Loads the task named by `--scenario`.
pub fn load_task(spec: &str) -> Result<Box<dyn Task>> {
    scenarios::load_task(spec).with_context(|| format!("loading scenario {spec}"))
}
