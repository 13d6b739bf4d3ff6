//! Reference simulators for evalharness, one module per task.
//!
//! Each scenario owns its MuJoCo model, its seeded reset (a pure function of the
//! seed), its renderer, its exact scoring and its scripted behaviours (expert and
//! exploration) used to collect datasets, and implements the task interface
//! ([`harness::task::Task`]) the paired engine drives; [`load_task`] resolves
//! `--scenario`. Push-T implements the task interface; robomimic Lift so far has
//! its reference simulator, scripted behaviours and data commands.

pub mod can;
pub mod error;
pub mod lift;
pub mod pusht;
pub mod robosuite;

pub use error::ScenarioError;

use harness::task::Task;

/// The task `--scenario` names: a scenario name (`pusht`, `pusht-gpc`, `lift`, `can`: the
/// shipped parameters) or a scenario .toml file. The only place that maps a scenario to its
/// implementation: adding a task adds its line here.
///
/// # Errors
/// An unknown name, an unreadable or invalid file, or a scene MuJoCo refuses.
pub fn load_task(spec: &str) -> Result<Box<dyn Task>, ScenarioError> {
    use robosuite::task::RobosuiteTask;
    match scenario(spec)? {
        Scenario::PushT(cfg) => Ok(Box::new(pusht::PushTTask::new(*cfg)?)),
        Scenario::Lift(cfg) => Ok(Box::new(RobosuiteTask::new(lift::LiftSim::new(cfg)?))),
        Scenario::Can(cfg) => Ok(Box::new(RobosuiteTask::new(can::CanSim::new(cfg)?))),
    }
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
    if spec == "pusht-gpc" {
        return pusht::PushTConfig::gpc();
    }
    let path = std::path::Path::new(spec);
    let file = spec.ends_with(".toml") || path.exists();
    let named = if file { file_names(path)? } else { Some(spec.to_string()) };
    if let Some(name @ ("lift" | "can")) = named.as_deref() {
        return Err(ScenarioError::Unsupported {
            scenario: name.into(),
            what: "this command (it runs with `simulate` and `collect` and its scripted behaviours)".into(),
        });
    }
    if file {
        return pusht::PushTConfig::from_file(path);
    }
    Err(ScenarioError::UnknownScenario { name: spec.into(), available: SCENARIOS.join(", ") })
}

/// Names of the scenarios this build can simulate.
pub const SCENARIOS: &[&str] = &["pusht", "pusht-gpc", "lift", "can"];

/// A resolved `--scenario`: which simulator, with its parameters.
#[derive(Clone, Debug)]
pub enum Scenario {
    /// Push-T.
    PushT(Box<pusht::PushTConfig>),
    /// robomimic Lift.
    Lift(lift::LiftConfig),
    /// robomimic Can (robosuite's PickPlaceCan).
    Can(can::CanConfig),
}

/// Resolves `--scenario`: a name (`pusht`, `lift`: the shipped parameters) or a
/// scenario .toml file, whose `name` key says which simulator it describes.
///
/// # Errors
/// An unknown name, or an unreadable or invalid file.
pub fn scenario(spec: &str) -> Result<Scenario, ScenarioError> {
    match spec {
        "lift" => return Ok(Scenario::Lift(lift::LiftConfig::default())),
        "can" => return Ok(Scenario::Can(can::CanConfig::default())),
        _ => {}
    }
    let path = std::path::Path::new(spec);
    if !matches!(spec, "pusht" | "pusht-gpc") && (spec.ends_with(".toml") || path.exists()) {
        match file_names(path)?.as_deref() {
            Some("lift") => return Ok(Scenario::Lift(lift::LiftConfig::from_file(path)?)),
            Some("can") => return Ok(Scenario::Can(can::CanConfig::from_file(path)?)),
            _ => {}
        }
    }
    Ok(Scenario::PushT(Box::new(pusht_config(spec)?)))
}

/// The `name` a scenario file gives itself, if it parses and has one.
fn file_names(path: &std::path::Path) -> Result<Option<String>, ScenarioError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ScenarioError::Io { path: path.into(), source })?;
    Ok(toml::from_str::<toml::Table>(&text)
        .ok()
        .and_then(|t| t.get("name").and_then(|n| n.as_str().map(str::to_string))))
}

/// Prepares the process for MuJoCo; call it once at the start of `main`, before
/// any other thread exists.
///
/// - Routes MuJoCo's warnings and messages to the `log` crate (and so to the
///   program's `tracing` subscriber) instead of MuJoCo's default: printing to the
///   console and appending to `MUJOCO_LOG.TXT` in the working directory.
/// - Sets `LP_NUM_THREADS=0` unless the environment sets it: Mesa's software
///   renderer (llvmpipe, what MuJoCo's offscreen renderer runs on without a GPU)
///   then rasterises in the rendering thread instead of in helper threads of its
///   own. Mesa 22.3's llvmpipe crashed three times in 18 hours of rendering runs on
///   one of this project's machines, each a segmentation fault while it searched a
///   scene's list of referenced resources (`lp_scene_is_resource_referenced`; BENCHMARKS.md,
///   2026-11-27, "the Can headline"). Without helper threads it crashed once more, so
///   the race is (also) between two workers' GL contexts: the robosuite renderer now
///   lets one thread render at a time (`robosuite::episode`'s render lock), and this
///   setting stays as a second guard. The frames are the same bytes either way.
pub fn init_mujoco() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let set_lp_threads = std::env::var_os("LP_NUM_THREADS").is_none();
        // SAFETY: called from `main` before any other thread exists, so no thread
        // uses MuJoCo while its message handler is replaced (mujoco-rs's
        // requirement), and no thread reads the environment while it is changed
        // (`set_var`'s requirement); Mesa reads the variable later, when the first
        // renderer opens its EGL display.
        #[allow(unsafe_code)]
        unsafe {
            mujoco_rs::prelude::install_logging_hook();
            if set_lp_threads {
                std::env::set_var("LP_NUM_THREADS", "0");
            }
        };
    });
}

/// Builds the model a render worker is asked for: the same function, config and
/// assets as the episode that asked, so the same compiled model.
///
/// # Errors
/// An unknown task, a config that does not parse, or the build's own errors.
pub fn build_arm_model(
    key: &robosuite::render_pool::ModelKey,
) -> Result<mujoco_rs::prelude::MjModel, ScenarioError> {
    let bad = |e: serde_json::Error| ScenarioError::Render { message: format!("{} config: {e}", key.task) };
    match (key.task.as_str(), key.object_half) {
        ("lift", Some(half)) => {
            let cfg: lift::LiftConfig = serde_json::from_str(&key.config).map_err(bad)?;
            lift::sim::lift_model(&cfg, &key.assets, half)
        }
        ("can", None) => {
            let cfg: can::CanConfig = serde_json::from_str(&key.config).map_err(bad)?;
            can::sim::can_model(&cfg, &key.assets)
        }
        (task, _) => Err(ScenarioError::Render { message: format!("no arm model for task {task}") }),
    }
}

/// A render worker's loop on `input` and `output` (`evalharness render-worker`).
///
/// # Errors
/// A malformed request or a broken pipe.
pub fn serve_render_worker(input: impl std::io::Read, output: impl std::io::Write) -> std::io::Result<()> {
    robosuite::render_pool::serve(input, output, &build_arm_model)
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_task_says_without_a_reset_whether_its_episodes_judge_their_frames() {
        // `rank` asks `judges_own_frames` to pick a learned judge; the episodes' own
        // `judge` must agree with it (Push-T: its frame scorer; Lift and Can: none).
        for (name, own) in [("pusht", true), ("pusht-gpc", true), ("lift", false), ("can", false)] {
            let task = super::load_task(name).expect("robosuite assets (scripts/setup.sh)");
            assert_eq!(task.judges_own_frames(), own, "{name}");
            assert_eq!(task.reset(7).unwrap().judge().is_some(), own, "{name}");
        }
    }
}
