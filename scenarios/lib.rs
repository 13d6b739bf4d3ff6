//! Reference simulators for evalharness, one module per task.
//!
//! Each scenario owns its MuJoCo model, its seeded reset (a pure function of the
//! seed), its renderer, its exact scoring and its scripted behaviours (expert and
//! exploration) used to collect datasets. Only Push-T exists so far.

pub mod error;
pub mod pusht;

pub use error::ScenarioError;

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
