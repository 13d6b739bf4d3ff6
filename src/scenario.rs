//! Resolving `--scenario` (a name or a .toml path) into a validated config.

use std::path::Path;

use anyhow::{Context, Result};
use scenarios::pusht::PushTConfig;
use scenarios::{SCENARIOS, ScenarioError};

/// Loads the Push-T config named by `--scenario`: `pusht` gives the shipped
/// parameters, a path loads that file (which must describe Push-T).
pub fn load_pusht(spec: &str) -> Result<PushTConfig> {
    if spec == "pusht" {
        return Ok(PushTConfig::default());
    }
    let path = Path::new(spec);
    if spec.ends_with(".toml") || path.exists() {
        return PushTConfig::from_file(path).with_context(|| format!("loading scenario file {spec}"));
    }
    Err(ScenarioError::UnknownScenario { name: spec.into(), available: SCENARIOS.join(", ") }.into())
}
