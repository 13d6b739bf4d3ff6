//! Reference simulators for evalharness, one module per task.
//!
//! Each scenario owns its MuJoCo model, its seeded reset (a pure function of the
//! seed), its renderer, its exact scoring and its scripted behaviours (expert and
//! exploration) used to collect datasets, and implements the task interface
//! ([`harness::task::Task`]) the paired engine drives; [`load_task`] resolves
//! `--scenario`. Only Push-T exists so far.

pub mod error;
pub mod pusht;

pub use error::ScenarioError;

use harness::task::Task;

/// The task `--scenario` names: a scenario name (`pusht`, its shipped parameters) or
/// a scenario .toml file (today a Push-T one). The only place that maps a scenario
/// to its implementation: adding a task adds its line here.
///
/// # Errors
/// An unknown name, an unreadable or invalid file, or a scene MuJoCo refuses.
pub fn load_task(spec: &str) -> Result<Box<dyn Task>, ScenarioError> {
    Ok(Box::new(pusht::PushTTask::new(pusht_config(spec)?)?))
}

/// The Push-T config `--scenario` names: `pusht` gives the shipped parameters, a
/// path loads that file (which must describe Push-T).
///
/// # Errors
/// An unknown name, or an unreadable or invalid file.
pub fn pusht_config(spec: &str) -> Result<pusht::PushTConfig, ScenarioError> {
    if spec == "pusht" {
        return Ok(pusht::PushTConfig::default());
    }
    let path = std::path::Path::new(spec);
    if spec.ends_with(".toml") || path.exists() {
        return pusht::PushTConfig::from_file(path);
    }
    Err(ScenarioError::UnknownScenario { name: spec.into(), available: SCENARIOS.join(", ") })
}

/// Names of the scenarios this build can simulate.
pub const SCENARIOS: &[&str] = &["pusht"];

/// Routes MuJoCo's warnings and messages to the `log` crate (and so to the
/// program's `tracing` subscriber) instead of MuJoCo's default: printing to the
/// console and appending to `MUJOCO_LOG.TXT` in the working directory.
///
/// Call once at the start of `main`, before any thread uses MuJoCo.
pub fn route_mujoco_logs() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: called from `main` before any other thread exists, so no thread
        // uses MuJoCo while the handler is replaced (mujoco-rs's requirement).
        #[allow(unsafe_code)]
        unsafe {
            mujoco_rs::prelude::install_logging_hook()
        };
    });
}
